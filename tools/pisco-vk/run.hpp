#pragma once

#include <filesystem>

#include "pisco/pisco.hpp"
#include "pisco/simulation.hpp"

namespace pisco_cli {

struct RunOptions {
  bool quiet = false;
  bool plots = true;
  std::filesystem::path data_dir;     // holds assets/ and tools/pisco_plot.py
};

// The exit status of a run whose maps solve no pixel (docs/config.md): its files are written, the maps
// all UNSEEN, with a warning on stderr.
inline constexpr int exit_nothing_solved = 4;
// The run finished, with warnings (pisco::SimulationResult::warnings): every file is written.
inline constexpr int exit_warnings = 5;

// Runs a whole simulation: sky -> TOD -> maps -> spectra (pisco::Simulation), then the plots. Returns the
// exit status.
int run_simulation(const pisco::SimulationConfig& config, const RunOptions& options);

}  // namespace pisco_cli
