// [beams.NAME] type = "plate": a beam that turns with the half-wave plate (docs/changing.md), made of
// other tables' beams.
#include <string>

#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {
namespace {

// type = "plate": a beam that turns with the half-wave plate (docs/changing.md): other beams at plate
// angles; their names are checked once every table is read (check_combined_beams).
void read(Table& t, BeamConfig& b) {
  b.nodes = t.strings("beams", {});
  if (b.nodes.size() < 2)
    t.fail("beams", "a beam that turns with the plate needs two or more beams (names of [beams] tables, at plate "
                    "angles k period / N)");
  b.plate_period = t.number_in("period_deg", 180.0, 1e-6, 720.0, "a period in (0, 720] deg (180 for a half-wave plate)") * deg;
  if (t.has("normalize_by")) {
    b.plate_normalize_by = t.string("normalize_by").value_or("");
    if (b.plate_normalize_by.empty())
      t.fail("normalize_by", "expected the name of a [beams] table (the beam without the plate), or no key");
  }
}

}  // namespace

const BeamKindEntry plate_beam_kind{BeamKind::plate, "plate", read, nullptr, false, true};

}  // namespace pisco::detail
