#pragma once

#include <filesystem>

#include "config.hpp"

namespace pisco_cli {

struct RunOptions {
  bool quiet = false;
  bool plots = true;
  std::filesystem::path plot_script;  // tools/pisco_plot.py, found by the caller
};

// Runs a whole simulation: sky -> TOD -> maps -> spectra (-> plots). Returns the exit status.
int run_simulation(const SimulationConfig& config, const RunOptions& options);

}  // namespace pisco_cli
