#pragma once

#include <string>
#include <vector>

namespace pisco_cli {

struct BenchOptions {
  std::vector<double> rho_max_deg{5.0, 10.0};
  std::string backend = "auto";
  std::string device = "auto";
  unsigned threads = 0;
};

// The paper's Table 1 workload: a table of evaluations/s and the ratio to the paper's GTX 1080.
int run_bench(const BenchOptions& options);

}  // namespace pisco_cli
