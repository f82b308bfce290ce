// The float64 reference backend: one sample per task, the disc walked ring by ring, every pixel
// through the per-pixel arithmetic of shaders/pixel.glsl (core/contribution.hpp). Straightforward by
// design: it is the ground truth of every test.
#include <atomic>
#include <cmath>
#include <memory>
#include <thread>
#include <utility>

#include "core/backend.hpp"
#include "core/contribution.hpp"
#include "core/disc.hpp"
#include "core/frame.hpp"
#include "cpu/thread_pool.hpp"
#include "core/plate.hpp"

namespace pisco::detail {
namespace {

// The sample loop is compiled twice on x86-64, for the baseline and for x86-64-v3 (AVX2, FMA), and
// the loader picks the clone the processor supports: about 1.4x faster where v3 is present.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define PISCO_CPU_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define PISCO_CPU_CLONES
#endif

// One sample. With a plate (Plate), `plate` is M(theta) row-major and each pixel's weights are the
// effective w M(theta) (docs/physics.md, "Half-wave plates").
template <bool PerSample, bool Radial, bool Plate>
inline __attribute__((always_inline)) double sample(const PreparedSky& sky, const double* pixels,
                                                    const PreparedDetector& det,
                                                    const SampleFrame<double>& f, double theta, double phi,
                                                    const double* plate, std::uint64_t& count) {
  const ArrayGrid<double> grid{det.weights.data(), det.grid_n, det.grid_a, det.grid_inv_step};
  const ArrayGrid<double> norm_grid{det.norm_weights.data(), det.grid_n, det.grid_a, det.grid_inv_step};
  Vec4<double> m[4];  // the plate's M(theta) by columns
  if constexpr (Plate)
    for (int c = 0; c < 4; ++c) m[c] = {plate[c], plate[4 + c], plate[8 + c], plate[12 + c]};
  double sum = 0.0, norm = 0.0;
  for_each_disc_range(sky.rings.data(), sky.nside, theta, phi, det.rho_max, det.cos_rho_max,
                      [&](std::uint32_t begin, std::uint32_t end) {
                        count += end - begin;
                        for (std::uint32_t p = begin; p < end; ++p) {
                          const double* px = &pixels[std::size_t(p) * 8];
                          const Vec3<double> k{px[0], px[1], px[2]};
                          const Vec4<double> S{px[4], px[5], px[6], px[7]};
                          const PixelGeometry<double> g = pixel_geometry(f, k);
                          Vec4<double> w = Radial ? interpolate_radial(grid, g.r2) : interpolate_weights(grid, g.x, g.y);
                          if constexpr (Plate) w = effective_weights(w, m[0], m[1], m[2], m[3]);
                          sum += stokes_response(w, g.cos2chi, g.sin2chi, S);
                          if constexpr (PerSample)
                            norm += (Radial ? interpolate_radial(norm_grid, g.r2) : interpolate_weights(norm_grid, g.x, g.y)).x;
                        }
                      });
  if constexpr (PerSample) return norm > 0 ? sum / norm : 0.0;
  return sum;
}

// M(theta) = R(-theta) M0 R(theta), row-major (core/plate.hpp).
inline void plate_matrix(const PreparedDetector& det, double theta, double* m) {
  plate_at(&det.plate_mueller[0][0], std::cos(2 * theta), std::sin(2 * theta), m);
}

template <bool Radial, bool Plate>
inline double sample_of(const PreparedSky& sky, const double* pixels, const PreparedDetector& det, bool per_sample,
                        const SampleFrame<double>& f, double theta, double phi, const double* plate,
                        std::uint64_t& count) {
  return per_sample ? sample<true, Radial, Plate>(sky, pixels, det, f, theta, phi, plate, count)
                    : sample<false, Radial, Plate>(sky, pixels, det, f, theta, phi, plate, count);
}

// Samples [begin, end) of one chunk; returns the number of pixels evaluated. The detector's basis
// and line of sight come from frame.hpp, for either pointing form (offset applied there).
PISCO_CPU_CLONES std::uint64_t convolve_samples(const PreparedSky& sky, const double* pixels,
                                                const PreparedDetector& det, bool per_sample, const PointingInput& in,
                                                double* tod, bool accumulate, std::size_t begin, std::size_t end) {
  std::uint64_t count = 0;
  const bool plate = det.plate == PreparedDetector::Plate::aperture;
  double m[16];
  for (std::size_t i = begin; i < end; ++i) {
    double theta = 0.0, phi = 0.0;
    const SampleFrame<double> f = detector_frame(in, i, det, theta, phi);
    double d;
    if (plate) {
      plate_matrix(det, in.plate_angle[i], m);
      d = det.radial ? sample_of<true, true>(sky, pixels, det, per_sample, f, theta, phi, m, count)
                     : sample_of<false, true>(sky, pixels, det, per_sample, f, theta, phi, m, count);
    } else {
      d = det.radial ? sample_of<true, false>(sky, pixels, det, per_sample, f, theta, phi, nullptr, count)
                     : sample_of<false, false>(sky, pixels, det, per_sample, f, theta, phi, nullptr, count);
    }
    tod[i] = accumulate ? tod[i] + d : d;
  }
  return count;
}

class CpuBackend final : public Backend {
 public:
  CpuBackend(std::shared_ptr<const EngineInputs> inputs, const SkyView& sky, unsigned threads)
      : in_(std::move(inputs)),
        pool_(threads ? threads : std::max(1u, std::thread::hardware_concurrency())),
        pixels_(reference_pixels(sky, unsigned(pool_.size()))) {}

  std::string name() const override { return "cpu"; }
  std::string device() const override {
    return "float64 reference, " + std::to_string(pool_.size()) + " threads";
  }

  // The reference computes at submit(): its results are ready when the call returns.
  void submit(std::size_t detector, const PointingInput& pointing, std::span<double> tod, bool accumulate,
              std::uint64_t) override {
    const PreparedDetector& det = in_->detectors.at(detector);
    std::atomic<std::uint64_t> pixels{0};
    const bool per_sample = in_->normalization == Normalization::per_sample;
    pool_.parallel_for(pointing.size(), 64, [&](std::size_t begin, std::size_t end) {
      pixels += convolve_samples(in_->sky, pixels_.data(), det, per_sample, pointing, tod.data(), accumulate, begin, end);
    });
    evaluated_ += pixels;
  }

  std::uint64_t wait(std::uint64_t) override { return std::exchange(evaluated_, 0); }

 private:
  std::shared_ptr<const EngineInputs> in_;
  ThreadPool pool_;
  std::vector<double> pixels_;  // reference_pixels(): 8 doubles a pixel
  std::uint64_t evaluated_ = 0;
};

}  // namespace

BackendEntry cpu_backend_entry() {
  // Last for "auto": simd and vulkan on lavapipe are faster on the same cores (BENCHMARKS.md).
  return {"cpu", -2,
          [] {
            BackendInfo info{"cpu", true,
                             "float64 reference on " +
                                 std::to_string(std::max(1u, std::thread::hardware_concurrency())) +
                                 " hardware threads",
                             {}, {}};
            info.capabilities.float64 = true;
            info.capabilities.worker_threads = true;
            return info;
          },
          [](std::shared_ptr<const EngineInputs> in, const SkyView& sky, const EngineOptions& o) -> std::unique_ptr<Backend> {
            return std::make_unique<CpuBackend>(std::move(in), sky, o.threads);
          }};
}

}  // namespace pisco::detail
