// [beams.NAME] type = "elliptical": an elliptical Gaussian (docs/beams.md, docs/config.md).
#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {

const BeamKindEntry elliptical_beam_kind{
    BeamKind::elliptical, "elliptical",
    [](Table& t, BeamConfig& b) {
      read_beam_grid(t, b);
      b.fwhm_x = read_width(t, b, "fwhm_x_deg");
      b.fwhm_y = read_width(t, b, "fwhm_y_deg");
      b.angle = t.number("angle_deg", 0.0) * deg;
      read_sidelobe_split(t, b);
      read_analytic_beam(t, b);
    },
    [](const BeamConfig& b, const FileBeamOptions&) {
      return Beamsor::elliptical_gaussian(b.fwhm_x, b.fwhm_y, b.angle, b.options);
    },
    false, false};

}  // namespace pisco::detail
