// The float64 reference backend: one sample per task, the disc walked ring by ring, every pixel
// through the per-pixel arithmetic of src/kernel/pixel.glsl (kernel/contribution.hpp). Straightforward by
// design: it is the ground truth of every test.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <thread>
#include <utility>

#include "core/backend.hpp"
#include "kernel/contribution.hpp"
#include "kernel/disc.hpp"
#include "kernel/frame.hpp"
#include "core/ring_slices.hpp"
#include "core/thread_pool.hpp"
#include "kernel/plate.hpp"

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
    plate_columns(plate, m);
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

// M(theta) = R(-theta) M0 R(theta), row-major (kernel/plate.hpp).
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

// The adjoint of one sample (docs/physics.md, "The adjoint"): d times each pixel's weights, the
// transpose of stokes_response, added onto the pixels of its disc that lie in [lo, hi) (acc: 4
// doubles a pixel). With the per-sample normalization, d is divided by the sample's own norm first.
template <bool Radial, bool Plate, bool Squares>
inline void scatter_sample(const PreparedSky& sky, const double* pixels, const PreparedDetector& det,
                           const SampleFrame<double>& f, double theta, double phi, const double* plate, double d,
                           std::uint32_t lo, std::uint32_t hi, double* acc, std::uint64_t& count) {
  const ArrayGrid<double> grid{det.weights.data(), det.grid_n, det.grid_a, det.grid_inv_step};
  Vec4<double> m[4];
  if constexpr (Plate)
    plate_columns(plate, m);
  for_each_disc_range(sky.rings.data(), sky.nside, theta, phi, det.rho_max, det.cos_rho_max,
                      [&](std::uint32_t begin, std::uint32_t end) {
                        begin = std::max(begin, lo);
                        end = std::min(end, hi);
                        if (begin >= end) return;
                        count += end - begin;
                        for (std::uint32_t p = begin; p < end; ++p) {
                          const double* px = &pixels[std::size_t(p) * 8];
                          const PixelGeometry<double> g = pixel_geometry(f, Vec3<double>{px[0], px[1], px[2]});
                          Vec4<double> w = Radial ? interpolate_radial(grid, g.r2) : interpolate_weights(grid, g.x, g.y);
                          if constexpr (Plate) w = effective_weights(w, m[0], m[1], m[2], m[3]);
                          const Vec4<double> a = stokes_adjoint(w, g.cos2chi, g.sin2chi);
                          double* out = &acc[std::size_t(p) * 4];
                          const double v[4] = {d * a.x, d * a.y, d * a.z, d * a.w};
                          for (int c = 0; c < 4; ++c) out[c] += Squares ? v[c] * v[c] : v[c];
                        }
                      });
}

// The per-sample normalization's divisor of each sample (sample() with a unit-free sky of zeros).
template <bool Radial>
double sample_norm(const PreparedSky& sky, const double* pixels, const PreparedDetector& det,
                   const SampleFrame<double>& f, double theta, double phi) {
  const ArrayGrid<double> norm_grid{det.norm_weights.data(), det.grid_n, det.grid_a, det.grid_inv_step};
  double norm = 0.0;
  for_each_disc_range(sky.rings.data(), sky.nside, theta, phi, det.rho_max, det.cos_rho_max,
                      [&](std::uint32_t begin, std::uint32_t end) {
                        for (std::uint32_t p = begin; p < end; ++p) {
                          const double* px = &pixels[std::size_t(p) * 8];
                          const PixelGeometry<double> g = pixel_geometry(f, Vec3<double>{px[0], px[1], px[2]});
                          norm += (Radial ? interpolate_radial(norm_grid, g.r2) : interpolate_weights(norm_grid, g.x, g.y)).x;
                        }
                      });
  return norm;
}

// Samples [0, n) scattered onto the pixels of one slice of rings (core/ring_slices.hpp).
PISCO_CPU_CLONES std::uint64_t scatter_samples(const PreparedSky& sky, const double* pixels, const PreparedDetector& det,
                                               const PointingInput& in, const double* tod, const double* norms,
                                               const RingSlice& slice, bool squares, double* acc) {
  const std::uint32_t lo = slice.lo, hi = slice.hi;
  std::uint64_t count = 0;
  const bool plate = det.plate == PreparedDetector::Plate::aperture;
  double m[16];
  for (std::size_t i = 0; i < in.size(); ++i) {
    double d = tod[i];
    if (norms) d = norms[i] > 0 ? d / norms[i] : 0.0;
    if (d == 0.0) continue;
    double theta = 0.0, phi = 0.0;
    const SampleFrame<double> f = detector_frame(in, i, det, theta, phi);
    if (slice.missed_by(theta, det.rho_max)) continue;
    if (plate) plate_matrix(det, in.plate_angle[i], m);
    const double* pm = plate ? m : nullptr;
#define PISCO_SCATTER(R, P, S) scatter_sample<R, P, S>(sky, pixels, det, f, theta, phi, pm, d, lo, hi, acc, count)
    if (squares) {
      if (plate) det.radial ? PISCO_SCATTER(true, true, true) : PISCO_SCATTER(false, true, true);
      else det.radial ? PISCO_SCATTER(true, false, true) : PISCO_SCATTER(false, false, true);
    } else {
      if (plate) det.radial ? PISCO_SCATTER(true, true, false) : PISCO_SCATTER(false, true, false);
      else det.radial ? PISCO_SCATTER(true, false, false) : PISCO_SCATTER(false, false, false);
    }
#undef PISCO_SCATTER
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
    const double* table = pointing.sky ? band_indexed(polar_.data(), 8 * polar_first_) : pixels_.data();
    pool_.parallel_for(pointing.size(), 64, [&](std::size_t begin, std::size_t end) {
      pixels += convolve_samples(in_->sky, table, det, per_sample, pointing, tod.data(), accumulate, begin, end);
    });
    evaluated_ += pixels;
  }

  void set_polar_sky(const SkyBand& band) override {
    polar_ = reference_pixels(band.nside, band.first, {band.maps[0], band.maps[1], band.maps[2], band.maps[3]},
                              unsigned(pool_.size()));
    polar_first_ = band.first;
  }

  std::uint64_t wait(std::uint64_t) override { return std::exchange(evaluated_, 0); }

  // Spread over threads by slices of rings (core/ring_slices.hpp): deterministic.
  std::uint64_t adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                        bool squares) override {
    const PreparedDetector& det = in_->detectors.at(detector);
    const PreparedSky& sky = in_->sky;
    if (adjoint_.empty()) adjoint_.assign(sky.npix * 4, 0.0);
    std::vector<double> norms;
    if (in_->normalization == Normalization::per_sample) {
      norms.resize(tod.size());
      pool_.parallel_for(tod.size(), 64, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
          double theta = 0.0, phi = 0.0;
          const SampleFrame<double> f = detector_frame(pointing, i, det, theta, phi);
          norms[i] = det.radial ? sample_norm<true>(sky, pixels_.data(), det, f, theta, phi)
                                : sample_norm<false>(sky, pixels_.data(), det, f, theta, phi);
        }
      });
    }
    if (slices_.empty()) slices_ = ring_slices(sky, std::size_t(pool_.size()) * 8);
    std::atomic<std::uint64_t> pixels{0};
    pool_.parallel_for(slices_.size(), 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t k = begin; k < end; ++k) {
        const RingSlice& s = slices_[k];
        pixels += scatter_samples(sky, pixels_.data(), det, pointing, tod.data(), norms.empty() ? nullptr : norms.data(),
                                  s, squares, adjoint_.data());
      }
    });
    return pixels;
  }

  void take_adjoint(const std::array<std::span<double>, 4>& maps) override {
    if (adjoint_.empty()) return;
    for (int c = 0; c < 4; ++c)
      if (!maps[c].empty())
        for (std::size_t p = 0; p < in_->sky.npix; ++p) maps[c][p] += adjoint_[4 * p + std::size_t(c)];
    adjoint_.clear();
    adjoint_.shrink_to_fit();
  }

 private:
  std::vector<double> adjoint_;  // 4 doubles a pixel: I, Q, U, V
  std::vector<RingSlice> slices_;  // the adjoint's (core/ring_slices.hpp)
  std::shared_ptr<const EngineInputs> in_;
  ThreadPool pool_;
  std::vector<double> pixels_;  // reference_pixels(): 8 doubles a pixel
  std::vector<double> polar_;   // the polar copy's band, likewise, from pixel polar_first_
  std::size_t polar_first_ = 0;
  std::uint64_t evaluated_ = 0;
};

}  // namespace

BackendEntry cpu_backend_entry() {
  // Last for "auto": simd and vulkan on lavapipe are faster on the same cores (BENCHMARKS.md).
  return {.name = "cpu",
          .priority = -2,
          .settings = {threads_setting()},
          .probe =
              [] {
                BackendInfo info{"cpu", true,
                                 "float64 reference on " +
                                     std::to_string(std::max(1u, std::thread::hardware_concurrency())) +
                                     " hardware threads",
                                 {}, {}};
                info.capabilities.float64 = true;
                info.capabilities.worker_threads = true;
                info.capabilities.adjoint = true;
                return info;
              },
          .create = [](std::shared_ptr<const EngineInputs> in, const SkyView& sky,
                       const EngineOptions& o) -> std::unique_ptr<Backend> {
            return std::make_unique<CpuBackend>(std::move(in), sky, unsigned(o.number("threads")));
          }};
}

}  // namespace pisco::detail
