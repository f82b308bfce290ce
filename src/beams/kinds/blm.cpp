// [beams.NAME] type = "blm": a beam's b_lm in a healpy alm FITS file (docs/beams.md, "b_lm files").
#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {

const BeamKindEntry blm_beam_kind{
    BeamKind::blm, "blm",
    [](Table& t, BeamConfig& b) {
      read_beam_grid(t, b);
      read_beam_file(t, b, "a beam of type \"blm\" needs file = \"beam_alm.fits\" (healpy.write_alm)");
      b.temperature_only = t.boolean("temperature_only", false);
      read_sidelobe_split(t, b);
    },
    [](const BeamConfig& b, const FileBeamOptions& file) {
      return Beamsor::from_harmonic(HarmonicBeam::read_fits(b.file), file);
    },
    true, false};

}  // namespace pisco::detail
