// The simd backend's kernel (src/simd/simd_kernel.cpp) on every instruction set this machine runs,
// not only the best one that the parity tests (simd.BackendParity) use: each compiled copy of the
// kernel, with its own vector width, its own weight lookups (16-byte records transposed in blocks of
// four lanes) and its own staging of short rings, against the float64 reference at the bars of
// docs/validation.md, "B": radial profiles and 2D grids, two and four weight columns, a generic plate
// at the aperture and at the detector, and the float64 path (a sky with a monopole, per-sample
// normalization).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "backend_fixtures.hpp"
#include "support.hpp"
#include "pisco/engine.hpp"
#include "pisco/hwp.hpp"
#include "pisco/units.hpp"
#include "simd_targets.hpp"

namespace {

using pisco_test::compare;
using pisco_test::Stats;

// The instruction sets this machine runs (Highway's names), best first.
std::vector<std::string> instruction_sets() {
  std::vector<std::string> out;
  for (const auto& named : pisco_test::simd_kernels()) out.push_back(named.first);
  return out;
}

pisco::EngineOptions on(const std::string& backend, const std::string& target, pisco::Normalization n) {
  pisco::EngineOptions o;
  o.backend = backend;
  pisco_test::set_taken(o, "device", target);
  pisco_test::set_taken(o, "threads", 2LL);
  o.normalization = n;
  return o;
}

// Every detector of the scene, without a plate and with a generic one at the aperture (even
// detectors) or the detector (odd ones), on a sky with and without a monopole, and with per-sample
// normalization.
TEST(SimdKernel, EveryInstructionSetMatchesTheReference) {
  // As the parity tests: PISCO_SIMD_TARGET naming an instruction set the machine lacks leaves the
  // backend unavailable.
  if (const std::string why = pisco_test::backend_unavailable("simd"); !why.empty())
    GTEST_SKIP() << "simd backend unavailable: " << why;
  const std::vector<std::string> targets = instruction_sets();
  ASSERT_FALSE(targets.empty()) << "the simd backend names no instruction set here";
  const pisco::Pointing p = pisco_test::random_pointing(600, 23);
  std::vector<double> h(p.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = 0.217 * double(i);
  struct Case {
    double monopole;
    pisco::Normalization normalization;
  };
  for (const Case c : {Case{0.0, pisco::Normalization::integral}, Case{2.725, pisco::Normalization::integral},
                       Case{0.0, pisco::Normalization::per_sample}}) {
    const double monopole = c.monopole;
    const bool per_sample = c.normalization == pisco::Normalization::per_sample;
    const pisco_test::Scene s = pisco_test::backend_scene(64, monopole);
    std::vector<pisco::Detector> plated = s.focal_plane.detectors();
    for (std::size_t i = 0; i < plated.size(); ++i)
      plated[i].hwp = pisco::HalfWavePlate{pisco_test::generic_plate(),
                                           i % 2 ? pisco::HwpPlacement::detector : pisco::HwpPlacement::aperture,
                                           0.3 * double(i)};
    // The anisotropies' scale: the bars are relative to the TOD without the monopole.
    const pisco_test::Scene aniso = pisco_test::backend_scene(64, 0.0);
    for (const bool plate : {false, true}) {
      const pisco::FocalPlane fp = plate ? pisco::FocalPlane(plated) : s.focal_plane;
      const std::vector<double> angles = plate ? h : std::vector<double>{};
      pisco::Engine cpu(s.sky, s.beams, fp, on("cpu", "auto", c.normalization));
      pisco::Engine cpu_aniso(aniso.sky, aniso.beams, fp, on("cpu", "auto", c.normalization));
      for (const std::string& target : targets) {
        pisco::Engine dev(s.sky, s.beams, fp, on("simd", target, c.normalization));
        EXPECT_TRUE(pisco_test::contains(dev.device_name(), target)) << dev.device_name();
        for (std::size_t d = 0; d < fp.size(); ++d) {
          std::vector<double> ref(p.size()), got(p.size(), std::numeric_limits<double>::quiet_NaN()), a(p.size());
          cpu.convolve(d, p, ref, false, angles);
          dev.convolve(d, p, got, false, angles);
          cpu_aniso.convolve(d, p, a, false, angles);
          const Stats st = compare(ref, got);
          const double scale = compare(a, a).rms_ref;
          const std::string what = target + ", " + fp[d].name + (plate ? ", plate" : "") +
                                   (monopole != 0.0 ? ", monopole sky" : "") + (per_sample ? ", per sample" : "");
          std::cout << what << ": relative rms error " << st.rms_err / scale << ", max error / rms "
                    << st.max_err / scale << "\n";
          EXPECT_EQ(st.non_finite, 0u) << what;
          EXPECT_LE(st.rms_err, 1e-5 * scale) << what;
          EXPECT_LE(st.max_err, 1e-4 * scale) << what;
        }
      }
    }
  }
}

}  // namespace
