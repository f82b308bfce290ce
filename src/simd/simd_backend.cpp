// The simd backend (docs/simd.md): the GPU kernels' float32 contract on the CPU's vector units.
// This file is the driver: it packs the sky and the weights into the kernel's layout once, and per
// sample computes the antenna frame in float64 with the reference's own code (core/frame.hpp) and the
// disc's ranges (simd::disc_ranges: the reference's, core/disc.hpp), then hands them to the kernel
// (simd_kernel.cpp, compiled per instruction set by Highway). Samples are spread over a thread pool
// as in the float64 reference.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <initializer_list>
#include <limits>
#include <memory>
#include <thread>
#include <utility>

#include "core/poles.hpp"
#include "core/backend.hpp"
#include "core/disc.hpp"
#include "core/frame.hpp"
#include "core/plate.hpp"
#include "cpu/ring_slices.hpp"
#include "cpu/thread_pool.hpp"
#include "simd/simd_kernel.hpp"

namespace pisco::detail {
namespace {

using simd::KernelDetector;
using simd::KernelSky;

unsigned hardware_threads() { return std::max(1u, std::thread::hardware_concurrency()); }

// The instruction set: `device` when it names one, else PISCO_SIMD_TARGET (how the test suite runs
// on another instruction set), else the best the processor supports.
std::string requested_target(const std::string& device) {
  if (!device.empty() && device != "auto") return device;
  const char* t = std::getenv("PISCO_SIMD_TARGET");
  return t ? std::string(t) : std::string();
}

// Records of columns `cols` of a table of 4 values a node (w_I, w_Q, w_U, w_V): record k holds their
// values at node k, then at node k + 1 (zero past the last node), the two ends of an interpolation
// along r or x in one load (simd_kernel.hpp, KernelDetector).
template <class T>
std::vector<T> node_records(const std::vector<T>& table, std::initializer_list<std::size_t> cols) {
  const std::size_t nodes = table.size() / 4, m = cols.size();
  std::vector<T> out(2 * m * nodes, T(0));
  for (std::size_t k = 0; k < nodes; ++k) {
    std::size_t h = 0;
    for (const std::size_t c : cols) {
      out[2 * m * k + h] = table[4 * k + c];
      if (k + 1 < nodes) out[2 * m * k + m + h] = table[4 * (k + 1) + c];
      ++h;
    }
  }
  return out;
}

// One detector's weights in the kernel's layout: float32 columns (float32_weights, the GPU
// backends' rule) and the reference's float64 tables.
struct DetectorTables {
  std::vector<float> records[2];
  std::vector<double> pairs64[5];  // the float64 path only
  KernelDetector view{};
};

DetectorTables detector_tables(const PreparedDetector& det, std::size_t index, bool float64_path) {
  const std::size_t nodes = det.weights.size() / 4;
  if (det.grid_n < 2 || nodes == 0)
    throw Error("simd: detector " + std::to_string(index) + " has a weight grid of " + std::to_string(det.grid_n) +
                " nodes a side; the kernel needs at least 2");
  // The kernel addresses a record by its offset in floats, 4 (node + n) at most, in 32-bit lanes.
  if (4 * (nodes + std::size_t(det.grid_n) + 2) > std::size_t(std::numeric_limits<std::int32_t>::max()))
    throw Error("simd: detector " + std::to_string(index) + "'s weight grid has " + std::to_string(nodes) +
                " nodes, more than the kernel's 32-bit record offsets reach (at most about 5.4e8)");
  const std::vector<float> w32 = float32_weights(det);
  DetectorTables t;
  bool polarized_uv = false;
  for (std::size_t k = 0; k < nodes; ++k) polarized_uv = polarized_uv || w32[4 * k + 2] != 0.0f || w32[4 * k + 3] != 0.0f;
  const int columns = polarized_uv ? 4 : 2;
  t.records[0] = node_records(w32, {0, 1});
  if (columns == 4) t.records[1] = node_records(w32, {2, 3});
  if (float64_path) {
    for (std::size_t c = 0; c < 4; ++c) t.pairs64[c] = node_records(det.weights, {c});
    if (!det.norm_weights.empty()) t.pairs64[4] = node_records(det.norm_weights, {0});
  }
  KernelDetector& v = t.view;
  for (int c = 0; c < 2; ++c) v.records[c] = t.records[c].empty() ? nullptr : t.records[c].data();
  for (int c = 0; c < 5; ++c) v.pairs64[c] = t.pairs64[c].empty() ? nullptr : t.pairs64[c].data();
  v.columns = columns;
  v.radial = det.radial;
  v.grid_n = det.grid_n;
  v.grid_a = float(det.grid_a);
  v.grid_inv_step = float(det.grid_inv_step);
  v.weights = det.weights.data();
  v.norm_weights = det.norm_weights.empty() ? nullptr : det.norm_weights.data();
  v.grid_a_d = det.grid_a;
  v.grid_inv_step_d = det.grid_inv_step;
  return t;
}

class SimdBackend final : public Backend {
 public:
  SimdBackend(std::shared_ptr<const EngineInputs> inputs, const SkyView& sky, const EngineOptions& options)
      : in_(std::move(inputs)),
        pool_(options.threads ? options.threads : hardware_threads()),
        kernel_(simd::choose_kernel(requested_target(options.device))),
        ring_columns_(in_->sky.rings) {
    monopole_ = float32_monopole(sky);
    boundary_ = cap_boundary(sky.nside(), in_->quadrature);
    per_sample_ = in_->normalization == Normalization::per_sample;
    exact_ = monopole_ != 0.0 || per_sample_;
    pack_sky(sky);
    tables_.reserve(in_->detectors.size());
    for (std::size_t d = 0; d < in_->detectors.size(); ++d) tables_.push_back(detector_tables(in_->detectors[d], d, exact_));
  }

  std::string name() const override { return "simd"; }
  std::string device() const override {
    return "Highway " + kernel_.description + ", " + std::to_string(pool_.size()) + " threads" +
           (exact_ ? ", float64 path (monopole or per-sample normalization)" : "");
  }

  // Computed at submit(), as the reference: the results are ready when the call returns.
  void submit(std::size_t detector, const PointingInput& pointing, std::span<double> tod, bool accumulate,
              std::uint64_t) override {
    const PreparedDetector& det = in_->detectors.at(detector);
    const KernelDetector& kd = tables_.at(detector).view;
    std::atomic<std::uint64_t> pixels{0};
    pool_.parallel_for(pointing.size(), 64, [&](std::size_t begin, std::size_t end) {
      pixels += convolve_samples(det, kd, pointing, tod.data(), accumulate, begin, end);
    });
    evaluated_ += pixels;
  }

  std::uint64_t wait(std::uint64_t) override { return std::exchange(evaluated_, 0); }

  // The adjoint, a block of samples at a time: their frames, discs (and the per-sample
  // normalization's norms) on all threads, then the scatter by slices of rings (cpu/ring_slices.hpp),
  // cut for each block so that each holds about the same share of its pixels: deterministic.
  std::uint64_t adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                        bool squares) override {
    const PreparedDetector& det = in_->detectors.at(detector);
    const KernelDetector& kd = tables_.at(detector).view;
    const PreparedSky& sky = in_->sky;
    if (adjoint_[0].empty())
      for (auto& m : adjoint_) m.assign(simd::map_size(sky.npix, sky.rings.size()), 0.0);
    if (work_.size() != sky.rings.size()) {
      work_.assign(sky.rings.size(), 0.0);
      work_steps_.assign(sky.rings.size() + 1, 0.0);
    }
    const bool plate = det.plate == PreparedDetector::Plate::aperture;
    struct Sample {
      SampleFrame<double> f;
      double theta, value;
      std::size_t first, count;  // its ranges in `ranges` of its task
      std::uint32_t ring0, ring1;  // the first and last rings its disc touches
      std::uint32_t pixels;
      unsigned task;
    };
    // Blocks of 32768 samples: a block of a scan covers a band of rings, which the slices share out,
    // and with many threads a narrow band leaves slices of one or two rings, every disc cut into as
    // many parts (16 threads: 15 to 20% faster than blocks of 8192; BENCHMARKS.md, 2026-11-27).
    constexpr std::size_t block = 32768, task_samples = 256;
    std::vector<Sample> samples(std::min(block, pointing.size()));
    std::vector<std::array<double, 16>> plates(plate ? samples.size() : 0);  // each sample's M(theta)
    // Each task's samples' ranges, split where they cross from one ring to the next (a polar cap is
    // one range of the disc), with each one's map_offset.
    std::vector<std::vector<std::uint32_t>> ranges((block + task_samples - 1) / task_samples);
    std::vector<std::vector<std::uint32_t>> offsets(ranges.size());
    std::atomic<std::uint64_t> pixels{0};
    for (std::size_t b0 = 0; b0 < pointing.size(); b0 += block) {
      const std::size_t n = std::min(block, pointing.size() - b0);
      pool_.parallel_for((n + task_samples - 1) / task_samples, 1, [&](std::size_t t0, std::size_t t1) {
        std::vector<std::uint32_t> disc;
        for (std::size_t t = t0; t < t1; ++t) {
          std::vector<std::uint32_t>& r = ranges[t];
          std::vector<std::uint32_t>& o = offsets[t];
          r.clear();
          o.clear();
          for (std::size_t k = t * task_samples; k < std::min(n, (t + 1) * task_samples); ++k) {
            const std::size_t i = b0 + k;
            Sample& s = samples[k];
            double phi = 0.0;
            s.f = detector_frame(pointing, i, det, s.theta, phi);
            s.value = tod[i];
            s.task = unsigned(t);
            s.first = r.size();
            s.count = 0;
            if (s.value == 0.0) continue;
            if (plate)
              plate_at(&det.plate_mueller[0][0], std::cos(2 * pointing.plate_angle[i]),
                       std::sin(2 * pointing.plate_angle[i]), plates[k].data());
            const std::size_t c = simd::disc_ranges(kernel_, sky.rings.data(), ring_columns_, sky.nside, s.theta, phi,
                                                    det.rho_max, det.cos_rho_max, disc);
            if (c > 0) {
              // The disc's ranges come ring by ring, northmost first: each is split where it crosses
              // from one ring to the next (only a polar cap does) and given its ring's map_offset.
              s.ring0 = ring_of(sky, disc[0]);
              s.ring1 = ring_of(sky, disc[c - 1] - 1);
              s.pixels = 0;
              const std::size_t at = r.size(), most = c / 2 + (s.ring1 - s.ring0 + 1);
              r.resize(at + 2 * most);
              o.resize(at / 2 + most);
              std::uint32_t* rw = r.data() + at;
              std::uint32_t* ow = o.data() + at / 2;
              const RingEntry* ring = sky.rings.data() + s.ring0;
              for (std::size_t q = 0; q < c; q += 2) {
                std::uint32_t b = disc[q];
                const std::uint32_t e = disc[q + 1];
                s.pixels += e - b;
                while (b >= ring->first + ring->count) ++ring;
                for (;;) {
                  const std::uint32_t stop = std::min(e, ring->first + ring->count);
                  *rw++ = b;
                  *rw++ = stop;
                  *ow++ = std::uint32_t(simd::map_offset(std::size_t(ring - sky.rings.data())));
                  if (stop == e) break;
                  b = stop;
                  ++ring;
                }
              }
              r.resize(std::size_t(rw - r.data()));
              o.resize(std::size_t(ow - o.data()));
            }
            s.count = r.size() - s.first;
            if (per_sample_) {  // the norm as the forward computes it (its float64 path)
              const simd::SampleInput in{&s.f, disc.data(), c / 2, plate ? plates[k].data() : nullptr, false, true};
              simd::SampleSums sums;
              simd::convolve_sample(kernel_, sky_, kd, in, sums);
              s.value = sums.norm > 0 ? s.value / sums.norm : 0.0;
            }
          }
        }
      });
      // Each sample's pixels spread evenly over its rings: the estimate of the work that cuts the slices,
      // as steps (its share starts at ring0 and stops after ring1) summed once over the rings.
      std::size_t ring_first = work_.size(), ring_last = 0;
      for (std::size_t j = 0; j < n; ++j) {
        const Sample& s = samples[j];
        if (s.count == 0 || s.value == 0.0) continue;
        const double share = double(s.pixels) / double(s.ring1 - s.ring0 + 1);
        work_steps_[s.ring0] += share;
        work_steps_[s.ring1 + 1] -= share;
        ring_first = std::min<std::size_t>(ring_first, s.ring0);
        ring_last = std::max<std::size_t>(ring_last, s.ring1);
      }
      double running = 0.0;
      for (std::size_t k = ring_first; k <= ring_last; ++k) {
        running += work_steps_[k];
        work_[k] = std::max(running, 0.0);  // rounding may leave -1e-16 where no disc reaches
        work_steps_[k] = 0.0;
      }
      if (ring_first <= ring_last) work_steps_[ring_last + 1] = 0.0;
      work_slices(sky, work_, std::size_t(pool_.size()), slices_);
      for (std::size_t k = ring_first; k <= ring_last; ++k) work_[k] = 0.0;
      pool_.parallel_for(slices_.size(), 1, [&](std::size_t begin, std::size_t end) {
        std::uint64_t count = 0;
        for (std::size_t k = begin; k < end; ++k) {
          const RingSlice& slice = slices_[k];
          for (std::size_t j = 0; j < n; ++j) {
            const Sample& s = samples[j];
            if (s.count == 0 || s.value == 0.0 || s.ring1 < slice.ring_lo || s.ring0 > slice.ring_hi) continue;
            const std::uint32_t* r = ranges[s.task].data() + s.first;
            const std::uint32_t* o = offsets[s.task].data() + s.first / 2;
            std::size_t entries = s.count;  // its ranges in this slice: all of them, or those of its rings
            if (s.ring0 >= slice.ring_lo && s.ring1 <= slice.ring_hi) {
              count += s.pixels;
            } else {
              // Each range lies on one ring and they come in order: the slice's are consecutive.
              std::size_t q0 = 0;
              while (q0 < s.count && r[q0] < slice.lo) q0 += 2;
              std::size_t q1 = q0;
              while (q1 < s.count && r[q1] < slice.hi) {
                count += r[q1 + 1] - r[q1];
                q1 += 2;
              }
              if (q1 == q0) continue;
              r += q0;
              o += q0 / 2;
              entries = q1 - q0;
            }
            // The slice's map entries end where its last ring's gap does.
            const std::size_t limit = slice.hi + simd::map_offset(slice.ring_hi + 1);
            const simd::ScatterInput in{&s.f,    r,       o,      entries / 2, plate ? plates[j].data() : nullptr,
                                        s.value, squares, limit,
                                        {adjoint_[0].data(), adjoint_[1].data(), adjoint_[2].data(), adjoint_[3].data()}};
            simd::scatter_sample(kernel_, sky_, kd, in);
          }
        }
        pixels += count;
      });
    }
    return pixels;
  }

  // The maps without their rings' gaps (simd::map_offset).
  void take_adjoint(const std::array<std::span<double>, 4>& maps) override {
    const PreparedSky& sky = in_->sky;
    for (std::size_t c = 0; c < 4; ++c) {
      if (!maps[c].empty() && !adjoint_[c].empty())
        for (std::size_t k = 0; k < sky.rings.size(); ++k) {
          const RingEntry& r = sky.rings[k];
          const double* from = adjoint_[c].data() + r.first + simd::map_offset(k);
          for (std::uint32_t q = 0; q < r.count; ++q) maps[c][r.first + q] += from[q];
        }
      adjoint_[c] = {};
    }
  }

 private:
  // The sky in the kernel's layout, a piece of pixels at a time (their unit vectors on all cores).
  void pack_sky(const SkyView& sky) {
    const std::size_t npix = sky.npix();
    for (auto* c : {&kx_, &ky_, &kz_, &i_, &q_, &u_, &v_}) c->assign(npix + simd::pad_floats, 0.0f);
    if (exact_)
      for (auto* c : {&vx_, &vy_, &vz_}) c->assign(npix + simd::pad_floats, 0.0);
    const PixelVectors vectors(sky.nside());
    constexpr std::size_t piece = std::size_t(1) << 16;
    std::vector<double> xyz(3 * std::min(piece, npix));
    for (std::size_t first = 0; first < npix; first += piece) {
      const std::size_t n = std::min(piece, npix - first);
      vectors.get(first, n, xyz.data(), unsigned(pool_.size()));
      for (std::size_t j = 0; j < n; ++j) {
        const std::size_t p = first + j;
        kx_[p] = float(xyz[3 * j]);
        ky_[p] = float(xyz[3 * j + 1]);
        kz_[p] = float(xyz[3 * j + 2]);
        i_[p] = float(sky.I()[p] - monopole_ * boundary_.at(p));
        q_[p] = float(sky.Q()[p]);
        u_[p] = float(sky.U()[p]);
        v_[p] = float(sky.V()[p]);
      }
      if (exact_)
        for (std::size_t j = 0; j < n; ++j) {
          vx_[first + j] = xyz[3 * j];
          vy_[first + j] = xyz[3 * j + 1];
          vz_[first + j] = xyz[3 * j + 2];
        }
    }
    sky_ = {kx_.data(), ky_.data(), kz_.data(), i_.data(), q_.data(), u_.data(), v_.data(),
            exact_ ? vx_.data() : nullptr, exact_ ? vy_.data() : nullptr, exact_ ? vz_.data() : nullptr, monopole_,
            boundary_};
  }

  // Samples [begin, end) of one chunk; returns the number of pixels evaluated. The frame and the
  // disc are the reference's (cpu_backend.cpp), in float64.
  std::uint64_t convolve_samples(const PreparedDetector& det, const KernelDetector& kd, const PointingInput& in,
                                 double* tod, bool accumulate, std::size_t begin, std::size_t end) const {
    std::uint64_t count = 0;
    const bool plate = det.plate == PreparedDetector::Plate::aperture;
    const PreparedSky& sky = in_->sky;
    std::vector<std::uint32_t> ranges;  // disc_ranges' buffer
    double m[16];
    for (std::size_t i = begin; i < end; ++i) {
      double theta = 0.0, phi = 0.0;
      const SampleFrame<double> f = detector_frame(in, i, det, theta, phi);
      if (plate) plate_at(&det.plate_mueller[0][0], std::cos(2 * in.plate_angle[i]), std::sin(2 * in.plate_angle[i]), m);
      const std::size_t n = simd::disc_ranges(kernel_, sky.rings.data(), ring_columns_, sky.nside, theta, phi,
                                              det.rho_max, det.cos_rho_max, ranges);
      for (std::size_t r = 0; r < n; r += 2) count += ranges[r + 1] - ranges[r];
      const simd::SampleInput sample{&f, ranges.data(), n / 2, plate ? m : nullptr, monopole_ != 0.0, per_sample_};
      simd::SampleSums sums;
      simd::convolve_sample(kernel_, sky_, kd, sample, sums);
      // As the reference and the GPU kernels: float32 sum plus I0 sum w_I, over the normalization.
      double d = sums.sum + monopole_ * sums.monopole_weight;
      if (per_sample_) d = sums.norm > 0 ? d / sums.norm : 0.0;
      tod[i] = accumulate ? tod[i] + d : d;
    }
    return count;
  }

  std::shared_ptr<const EngineInputs> in_;
  mutable ThreadPool pool_;
  simd::Kernel kernel_;
  simd::RingColumns ring_columns_;
  double monopole_ = 0.0;
  CapBoundary boundary_;
  bool per_sample_ = false, exact_ = false;
  std::vector<float> kx_, ky_, kz_, i_, q_, u_, v_;
  std::vector<double> vx_, vy_, vz_;  // float64 path only
  KernelSky sky_{};
  std::vector<DetectorTables> tables_;
  std::uint64_t evaluated_ = 0;
  std::array<std::vector<double>, 4> adjoint_;  // I, Q, U, V
  std::vector<RingSlice> slices_;                // the adjoint's, for the block at hand (cpu/ring_slices.hpp)
  std::vector<double> work_;                     // the block's pixels on each ring (an estimate)
  std::vector<double> work_steps_;               // its changes from ring to ring, one past the last ring
};

}  // namespace

BackendEntry simd_backend_entry() {
  // Above the float64 reference and vulkan on a CPU device (lavapipe), below a GPU: BENCHMARKS.md.
  return {"simd", 5,
          [] {
            try {
              const simd::Kernel k = simd::choose_kernel(requested_target(""));
              BackendInfo info{"simd", true,
                               "Highway " + k.description + " on " + std::to_string(hardware_threads()) +
                                   " hardware threads",
                               {}, {}};
              info.capabilities.worker_threads = true;
              info.capabilities.adjoint = true;
              return info;
            } catch (const Error& e) {
              return BackendInfo{"simd", false, e.what(), {}, {}};
            }
          },
          [](std::shared_ptr<const EngineInputs> in, const SkyView& sky, const EngineOptions& o) -> std::unique_ptr<Backend> {
            return std::make_unique<SimdBackend>(std::move(in), sky, o);
          }};
}

}  // namespace pisco::detail
