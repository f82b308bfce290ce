// [beams.NAME] type = "grasp": a TICRA GRASP .grd or .cut file (docs/beams.md, "GRASP files").
#include <algorithm>
#include <cmath>
#include <string>

#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {

const BeamKindEntry grasp_beam_kind{
    BeamKind::grasp, "grasp",
    [](Table& t, BeamConfig& b) {
      read_beam_grid(t, b);
      read_beam_file(t, b, "a beam of type \"grasp\" needs file = \"beam.grd\" (or a .cut file)");
      const double set = t.number("set", 0.0);
      if (!(set >= 0 && set <= 1e6 && set == std::floor(set)))
        t.fail("set", "expected the number of one of the file's beams (1, 2, ...)");
      b.set = static_cast<int>(set);
      read_sidelobe_split(t, b);
    },
    [](const BeamConfig& b, const FileBeamOptions& file) {
      const auto all = GraspBeam::read(b.file);
      if (b.set == 0 && all.size() > 1)
        throw Error(b.file.string() + " holds " + std::to_string(all.size()) +
                    " beams (field sets or frequencies): choose one with set = 1.." + std::to_string(all.size()));
      if (b.set > static_cast<int>(all.size()))
        throw Error("set = " + std::to_string(b.set) + ", but " + b.file.string() + " holds " +
                    std::to_string(all.size()) + " beam" + (all.size() > 1 ? "s" : ""));
      return Beamsor::from_grasp(all[static_cast<std::size_t>(std::max(b.set, 1) - 1)], file);
    },
    true, false};

}  // namespace pisco::detail
