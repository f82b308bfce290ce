#pragma once

#include <string>
#include <vector>

namespace pisco_cli {

struct BenchOptions {
  std::vector<double> rho_max_deg{5.0, 10.0};
  std::string backend = "auto";
  std::string device = "auto";
  unsigned threads = 0;
  std::string arithmetic = "auto";  // vulkan: auto, float64 or float-float
  // A half-wave plate in front of both detectors: "none", "ideal" or "generic" (all 16 Mueller
  // entries non-zero), at the aperture or, with hwp_placement = "detector", behind the optics.
  std::string hwp = "none";
  std::string hwp_placement = "aperture";
  // "gaussian" (Table 1's round beam, a radial profile) or "elliptical" (class_like.toml's first beam,
  // 1.52 x 1.46 deg FWHM at 10 deg, on the 2D grid that every beam that is not round uses).
  std::string beam = "gaussian";
  // A monopole added to the sky's I, in uK (2.725e6 for the CMB's): the float32 backends then sum
  // the monopole's weight in float64 (docs/vulkan.md, "Precision"), which this measures.
  double monopole_uk = 0.0;
  // Also time the adjoint (Engine::adjoint and take_adjoint) of the same TOD, and its ratio to the
  // forward path's time.
  bool adjoint = false;
  // Times each path this many times, alternately, and reports the best (this shared machine's
  // speed varies from run to run; the best of several is the code's own cost).
  unsigned repeat = 1;
  // Instead of Table 1: the streamed run's host work per detector-sample, without the convolution
  // (a CLASS-like constant-elevation scan, 36 pairs): the boresight, each detector's pointing and the
  // binned map-maker, on one thread and on `threads` (0: all).
  bool stream = false;
};

// The streamed pipeline's host work (BenchOptions::stream): a table of ns per detector-sample.
int run_stream_bench(const BenchOptions& options);

// The paper's Table 1 workload: a table of evaluations/s and the ratio to the paper's GTX 1080.
int run_bench(const BenchOptions& options);

}  // namespace pisco_cli
