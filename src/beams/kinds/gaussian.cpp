// [beams.NAME] type = "gaussian": a round Gaussian (docs/beams.md, docs/config.md).
#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {

const BeamKindEntry gaussian_beam_kind{
    BeamKind::gaussian, "gaussian",
    [](Table& t, BeamConfig& b) {
      read_beam_grid(t, b);
      b.fwhm = read_width(t, b, "fwhm_deg");
      read_sidelobe_split(t, b);
      read_analytic_beam(t, b);
    },
    [](const BeamConfig& b, const FileBeamOptions&) { return Beamsor::gaussian(b.fwhm, b.options); }, false, false};

}  // namespace pisco::detail
