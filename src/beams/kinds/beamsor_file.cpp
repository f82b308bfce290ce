// [beams.NAME] type = "file": a HEALPix beamsor file (docs/formats.md, "Beamsor files").
#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {

const BeamKindEntry beamsor_file_beam_kind{
    BeamKind::file, "file",
    [](Table& t, BeamConfig& b) {
      read_beam_grid(t, b);
      read_beam_file(t, b, "a beam of type \"file\" needs file = \"beamsor.fits\"");
      read_sidelobe_split(t, b);  // refused: a beamsor file cannot be split
    },
    [](const BeamConfig& b, const FileBeamOptions&) {
      return Beamsor::read_healpix_fits(b.file, b.options.rho_max, b.options.grid_step);
    },
    false, false};

}  // namespace pisco::detail
