// Beam kinds (docs/library.md, "How to add a beam format"): each [beams.NAME] type a kind with one
// entry, which reads its keys of the table and makes its beamsor; the pipeline finds a kind by its
// name or BeamKind through one registry, beam_kinds().
#pragma once

#include <span>
#include <string>

#include "io/toml_table.hpp"
#include "pisco/beam_files.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/simulation_config.hpp"

namespace pisco::detail {

struct BeamKindEntry {
  BeamKind kind;
  const char* name;
  void (*read)(Table& t, BeamConfig& b);  // its keys of the [beams.NAME] table (type is read already)
  // Its beamsor; `file` carries rho_max, the grid step, the detector's zeta (for the kinds that turn
  // with the detector) and the split. Null for the kinds made of other tables' beams.
  Beamsor (*make)(const BeamConfig& b, const FileBeamOptions& file);
  bool turns_with_detector;  // its co-polar axis turns with each detector's zeta (beams from files of other codes)
  bool combines_beams;       // made of other [beams] tables' beams (sequence, plate)
};

// Every kind, in the order of BeamKind; the kind of a name or of a BeamKind.
std::span<const BeamKindEntry* const> beam_kinds();
const BeamKindEntry& beam_kind(BeamKind kind);
const BeamKindEntry* beam_kind_named(const std::string& name);

// The keys the kinds share (beam_keys.cpp): the disc and grid step (rho_max_deg, grid_step_arcmin);
// a Gaussian's FWHM within them; a beam file's name, with the error `needs` when it is missing; a
// split into main part and sidelobes (sidelobe_split_deg, sidelobe_taper_deg, sidelobe_nside); an
// analytic beam's cross-polar part, far sidelobe and Mueller matrix.
void read_beam_grid(Table& t, BeamConfig& b);
double read_width(Table& t, const BeamConfig& b, const std::string& key);
void read_beam_file(Table& t, BeamConfig& b, const std::string& needs);
void read_sidelobe_split(Table& t, BeamConfig& b);
void read_analytic_beam(Table& t, BeamConfig& b);

// The kinds (src/beams/kinds/), each one entry.
extern const BeamKindEntry gaussian_beam_kind, elliptical_beam_kind, beamsor_file_beam_kind, grasp_beam_kind,
    blm_beam_kind, sequence_beam_kind, plate_beam_kind;

}  // namespace pisco::detail
