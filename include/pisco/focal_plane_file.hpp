// Focal-plane files (docs/config.md, "[focal_plane]"): the reader of the tables a simulation file's
// [focal_plane] names, and the plate keys a row may carry. The simulation-file reader
// (simulation_config.hpp) uses it; so may any program.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/focal_plane.hpp"

namespace pisco {

// A detector's own plate settings from its focal-plane row (keys hwp, hwp_gamma_deg, hwp_mueller).
struct DetectorHwp {
  std::optional<bool> enabled;
  std::optional<double> gamma;           // radians
  bool gamma_key = false;                // set by the row's hwp_gamma_deg (not a TOAST table's gamma)
  std::optional<Mueller> mueller;
};

// Reads a focal plane table (docs/config.md, "[focal_plane]"): CSV with a header (name, zeta_deg,
// epsilon, gain, beam, xi_deg, eta_deg, gamma_deg, hwp, hwp_gamma_deg), a TOAST HDF5 table (one beam,
// its gamma column as the plates' gamma) or TOML ([[detectors]] / [[pairs]] as in the simulation
// file). Each detector's beam is its index in `beam_names` (the [beams] tables); `hwp`, when given,
// receives each detector's plate keys. Throws pisco::Error naming the file, line and column.
std::vector<Detector> read_focal_plane_file(const std::filesystem::path& file,
                                            const std::vector<std::string>& beam_names,
                                            std::vector<DetectorHwp>* hwp = nullptr);

}  // namespace pisco
