// The simd backend (docs/simd.md): the GPU kernels' float32 contract on the CPU's vector units.
// This file is the driver: it packs the sky and the weights into the kernel's layout once, and per
// sample computes the antenna frame in float64 with the reference's own code (kernel/frame.hpp) and the
// disc's ranges (simd::disc_ranges: the reference's, kernel/disc.hpp), then hands them to the kernel
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
#include "kernel/disc.hpp"
#include "kernel/frame.hpp"
#include "kernel/plate.hpp"
#include "core/ring_slices.hpp"  // ring_of
#include "core/thread_pool.hpp"
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

// A 2D grid's float32 records (simd_kernel.cpp, RecordGrid): for each node k = j n + i, its record
// (w(k), w(k + 1)), then (ex(k), ex(k + n)) and (ey(k), ey(k + 1)) of the cell it is the lower corner
// of, from the table's nodes and edge terms (src/kernel/grid_curvature.hpp: ex(i, j) at n^2 + i n + j,
// ey at 2 n^2 + k); a pair's member beyond the grid is 0 (no cell reads it).
std::vector<float> grid_records(const std::vector<float>& table, std::initializer_list<std::size_t> cols, int n) {
  const std::size_t nn = std::size_t(n) * std::size_t(n), m = cols.size();
  std::vector<float> out(3 * 2 * m * nn, 0.0f);
  auto put = [&](std::size_t record, std::size_t a, bool a_in, std::size_t b, bool b_in) {
    std::size_t h = 0;
    for (const std::size_t c : cols) {
      if (a_in) out[2 * m * record + h] = table[4 * a + c];
      if (b_in) out[2 * m * record + m + h] = table[4 * b + c];
      ++h;
    }
  };
  for (std::size_t k = 0; k < nn; ++k) {
    const std::size_t i = k % std::size_t(n), j = k / std::size_t(n);
    put(3 * k, k, true, k + 1, k + 1 < nn);
    put(3 * k + 1, nn + i * n + j, true, nn + i * n + j + 1, j + 1 < std::size_t(n));
    put(3 * k + 2, 2 * nn + k, true, 2 * nn + k + 1, k + 1 < nn);
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
  if (det.radial) {
    t.records[0] = node_records(w32, {0, 1});
    if (columns == 4) t.records[1] = node_records(w32, {2, 3});
  } else {
    t.records[0] = grid_records(w32, {0, 1}, det.grid_n);
    if (columns == 4) t.records[1] = grid_records(w32, {2, 3}, det.grid_n);
  }
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

// One adjoint task's samples and the window they are scattered into (SimdBackend::adjoint).
struct Window {
  struct Sample {
    SampleFrame<double> f;
    double value = 0.0;
    std::uint32_t first = 0, count = 0;  // its ranges: entries [first, first + count) of `ranges`
    std::uint32_t pixels = 0;            // its disc's
    bool summed = false;  // the normal pass: value already is its forward value (below, plan_task)
  };
  struct Row {
    std::uint32_t lo = 0, hi = 0;  // the ring's pixels [lo, hi) in the window
    std::size_t at = 0;            // where they start in `maps`
  };
  std::vector<Sample> samples;
  std::vector<std::array<double, 16>> plates;  // each sample's M(theta) behind an aperture plate
  std::vector<std::uint32_t> disc;
  // The samples' ranges (begin, end pairs, each within one ring) and each range's ring; buffers,
  // grown and never shrunk: `ranges_used` entries of `ranges` are the task's.
  std::vector<std::uint32_t> ranges, rings;
  std::size_t ranges_used = 0;
  // By ring (entry k for ring k): the pixels [lo, hi) the task's ranges reach on it while it is
  // planned (lo = 2^32 - 1, hi = 0 where none, and again once laid out), and where its row starts, as
  // the offset that takes a pixel of the ring to its place in the window (p + offset modulo 2^32).
  std::vector<std::uint32_t> ring_lo, ring_hi, ring_offset;
  std::uint32_t ring0 = 0;  // the first row's ring
  std::vector<Row> rows;
  std::size_t size = 0;                     // pixels of all rows
  std::array<std::vector<double>, 4> maps;  // I, Q, U, V
  std::size_t bytes(int outputs) const { return samples.empty() ? 0 : size * sizeof(double) * std::size_t(outputs); }
};

class SimdBackend final : public Backend {
 public:
  SimdBackend(std::shared_ptr<const EngineInputs> inputs, const SkyView& sky, const EngineOptions& options)
      : in_(std::move(inputs)),
        pool_(options.number("threads") ? unsigned(options.number("threads")) : hardware_threads()),
        kernel_(simd::choose_kernel(requested_target(options.text("device")))),
        ring_columns_(in_->sky.rings) {
    monopole_ = float32_monopole(sky);
    boundary_ = cap_boundary(sky.nside(), in_->quadrature);
    per_sample_ = in_->normalization == Normalization::per_sample;
    float64_ = monopole_ != 0.0 || per_sample_;
    pack_sky(sky.nside(), 0, {sky.I(), sky.Q(), sky.U(), sky.V()}, sky_);
    tables_.reserve(in_->detectors.size());
    for (std::size_t d = 0; d < in_->detectors.size(); ++d) tables_.push_back(detector_tables(in_->detectors[d], d, float64_));
  }

  std::string name() const override { return "simd"; }
  std::string device() const override {
    return "Highway " + kernel_.description + ", " + std::to_string(pool_.size()) + " threads" +
           (float64_ ? ", float64 path (monopole or per-sample normalization)" : "");
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

  void set_polar_sky(const SkyBand& band) override {
    pack_sky(band.nside, band.first, {band.maps[0], band.maps[1], band.maps[2], band.maps[3]}, polar_);
  }

  // A task's plan (its samples' frames, ranges and their rings): about 12 bytes a range of the sample's
  // disc, which crosses at most 3 rho NSIDE + 1 rings (their spacing in colatitude is 2 / (3 NSIDE)
  // or more), one range each (two where it wraps round phi = 0, rarely).
  static std::size_t plan_bytes_per_sample(double rho, std::int64_t nside) {
    return sizeof(Window::Sample) + 3 * sizeof(std::uint32_t) * std::size_t(3.0 * rho * double(nside) + 4.0);
  }
  // Samples a task: 1024, or fewer (64 at least) where that keeps a task's plan near 2 MiB (wide discs
  // at high NSIDE: 30 deg at NSIDE 1024 makes tasks of 107). A function of the disc alone, not of the
  // threads, so that the maps are the same bits on any number of them.
  static std::size_t adjoint_task_samples(double rho, std::int64_t nside) {
    constexpr std::size_t plan_task_bytes = std::size_t(2) << 20;
    return std::clamp<std::size_t>(plan_task_bytes / plan_bytes_per_sample(rho, nside), 64, 1024);
  }
  static constexpr std::size_t plan_budget = std::size_t(128) << 20;  // bytes of the plans of a wave

  // The adjoint (docs/physics.md, "The adjoint"): tasks of consecutive samples (adjoint_task_samples),
  // each scattered whole by one thread into a window of its own (on each ring its discs touch, the
  // pixels from the first to the last any of them reaches), then the windows added into the maps
  // ring by ring, in the tasks' order, on all threads. Each pixel receives each task's sum of its
  // samples (in their order), task after task: the same bits whatever the number of threads. Tasks
  // come in waves of four a thread (fewer, one a thread at least, where their plans would pass
  // plan_budget: wide discs), and a wave's windows are filled and added in runs of tasks that fit in
  // window_budget together (one task at least). (Smaller tasks make larger windows in all: at 256
  // samples the windows' zeroing and adding cost 10% of the adjoint, at 1024 3%.)
  std::uint64_t adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                        bool squares) override {
    return scatter(detector, pointing, tod, squares ? Pass::squares : Pass::adjoint);
  }

  // The normal pass: the adjoint's tasks and windows, each selected sample's value its own forward
  // value, summed by the scatter kernel from the weights it scatters (ScatterInput::normal). Not on
  // the float64 path (a monopole or the per-sample normalization): that one sums the forward in
  // other arithmetic, and the engine convolves and scatters in two passes instead.
  bool has_normal() const override { return !float64_; }
  std::uint64_t normal(std::size_t detector, const PointingInput& pointing, std::span<const double> select) override {
    return scatter(detector, pointing, select, Pass::normal);
  }

  void take_adjoint(const std::array<std::span<double>, 4>& maps) override { hand_over_adjoint(adjoint_, maps); }

 private:
  enum class Pass { adjoint, squares, normal };

  std::uint64_t scatter(std::size_t detector, const PointingInput& pointing, std::span<const double> tod, Pass pass) {
    const bool squares = pass == Pass::squares, normal = pass == Pass::normal;
    const PreparedDetector& det = in_->detectors.at(detector);
    const KernelDetector& kd = tables_.at(detector).view;
    const PreparedSky& sky = in_->sky;
    if (adjoint_[0].empty())
      for (auto& m : adjoint_) m.assign(sky.npix, 0.0);
    const bool plate = det.plate == PreparedDetector::Plate::aperture;
    // Without U, V weights (two columns, no plate) the kernel leaves V alone (stokes_adjoint_iq).
    const int outputs = kd.columns == 2 && !plate ? 3 : 4;
    constexpr std::size_t window_budget = std::size_t(256) << 20;  // bytes of windows held at once
    const std::size_t task_samples = adjoint_task_samples(det.rho_max, sky.nside);
    const std::size_t tasks = (pointing.size() + task_samples - 1) / task_samples;
    const std::size_t threads = pool_.size();
    const std::size_t plans = plan_budget / (task_samples * plan_bytes_per_sample(det.rho_max, sky.nside));
    const std::size_t wave = std::max(threads, std::min(std::max<std::size_t>(8, 4 * threads), plans));
    if (windows_.size() < wave) windows_.resize(wave);
    std::atomic<std::uint64_t> pixels{0};
    for (std::size_t w0 = 0; w0 < tasks; w0 += wave) {
      const std::size_t count = std::min(wave, tasks - w0);
      pool_.parallel_for(count, 1, [&](std::size_t t0, std::size_t t1) {
        for (std::size_t t = t0; t < t1; ++t) {
          const std::size_t first = (w0 + t) * task_samples;
          pixels += plan_task(det, kd, pointing, tod, first, std::min(pointing.size(), first + task_samples), plate,
                              normal, windows_[t]);
        }
      });
      for (std::size_t g0 = 0; g0 < count;) {
        std::size_t g1 = g0, bytes = 0;
        while (g1 < count && (g1 == g0 || bytes + windows_[g1].bytes(outputs) <= window_budget))
          bytes += windows_[g1++].bytes(outputs);
        pool_.parallel_for(g1 - g0, 1, [&](std::size_t t0, std::size_t t1) {
          for (std::size_t t = g0 + t0; t < g0 + t1; ++t) fill_task(kd, plate, outputs, squares, normal, windows_[t]);
        });
        add_windows(g0, g1, outputs);
        // A window far above its share of the budget gives its memory back.
        for (std::size_t t = g0; t < g1; ++t)
          if (windows_[t].maps[0].capacity() * sizeof(double) * std::size_t(outputs) > window_budget / wave)
            for (auto& m : windows_[t].maps) std::vector<double>().swap(m);
        g0 = g1;
      }
    }
    return pixels;
  }

  // Windows [t0, t1) added into the maps, ring by ring on all threads, each ring's in the tasks' order.
  void add_windows(std::size_t t0, std::size_t t1, int outputs) {
    std::uint32_t ring_lo = std::numeric_limits<std::uint32_t>::max(), ring_hi = 0;
    for (std::size_t t = t0; t < t1; ++t)
      if (!windows_[t].rows.empty()) {
        ring_lo = std::min(ring_lo, windows_[t].ring0);
        ring_hi = std::max(ring_hi, windows_[t].ring0 + std::uint32_t(windows_[t].rows.size()) - 1);
      }
    if (ring_lo > ring_hi) return;
    pool_.parallel_for(ring_hi - ring_lo + 1, 4, [&](std::size_t k0, std::size_t k1) {
      for (std::size_t k = ring_lo + k0; k < ring_lo + k1; ++k)
        for (std::size_t t = t0; t < t1; ++t) {
          const Window& w = windows_[t];
          if (k < w.ring0 || k >= w.ring0 + w.rows.size()) continue;
          const Window::Row& row = w.rows[k - w.ring0];
          if (row.hi <= row.lo) continue;
          for (int c = 0; c < outputs; ++c) {
            double* to = adjoint_[c].data() + row.lo;
            const double* from = w.maps[c].data() + row.at;
            for (std::uint32_t j = 0; j < row.hi - row.lo; ++j) to[j] += from[j];
          }
        }
    });
  }

  // The sky in the kernel's layout, a piece of pixels at a time (their unit vectors on all cores):
  // pixels [first, first + count) of `maps` (count values each), read through the sky's pixel numbers.
  struct PackedSky {
    std::vector<float> kx, ky, kz, i, q, u, v;
    std::vector<double> vx, vy, vz;  // float64 path only
    KernelSky view{};
  };
  void pack_sky(int nside, std::size_t first_pixel, const std::array<std::span<const double>, 4>& maps,
                PackedSky& out) const {
    const std::size_t count = maps[0].size();
    for (auto* c : {&out.kx, &out.ky, &out.kz, &out.i, &out.q, &out.u, &out.v}) c->assign(count + simd::pad_floats, 0.0f);
    if (float64_)
      for (auto* c : {&out.vx, &out.vy, &out.vz}) c->assign(count + simd::pad_floats, 0.0);
    const PixelVectors vectors(nside);
    constexpr std::size_t piece = std::size_t(1) << 16;
    std::vector<double> xyz(3 * std::min(piece, count));
    for (std::size_t first = 0; first < count; first += piece) {
      const std::size_t n = std::min(piece, count - first);
      vectors.get(first_pixel + first, n, xyz.data(), unsigned(pool_.size()));
      for (std::size_t j = 0; j < n; ++j) {
        const std::size_t p = first + j;
        out.kx[p] = float(xyz[3 * j]);
        out.ky[p] = float(xyz[3 * j + 1]);
        out.kz[p] = float(xyz[3 * j + 2]);
        out.i[p] = float(maps[0][p] - monopole_ * boundary_.at(first_pixel + p));
        out.q[p] = float(maps[1][p]);
        out.u[p] = float(maps[2][p]);
        out.v[p] = float(maps[3][p]);
      }
      if (float64_)
        for (std::size_t j = 0; j < n; ++j) {
          out.vx[first + j] = xyz[3 * j];
          out.vy[first + j] = xyz[3 * j + 1];
          out.vz[first + j] = xyz[3 * j + 2];
        }
    }
    const auto at = [&](const auto& c) { return c.empty() ? nullptr : band_indexed(c.data(), first_pixel); };
    out.view = {at(out.kx), at(out.ky), at(out.kz), at(out.i), at(out.q), at(out.u), at(out.v),
                at(out.vx), at(out.vy), at(out.vz), monopole_, boundary_};
  }

  // One adjoint task's plan: samples [begin, end)'s frames, values and ranges, and the window's rows
  // sized to their discs. Returns the pixels they will scatter.
  std::uint64_t plan_task(const PreparedDetector& det, const KernelDetector& kd, const PointingInput& pointing,
                          std::span<const double> tod, std::size_t begin, std::size_t end, bool plate,
                          bool normal, Window& w) const {
    const PreparedSky& sky = in_->sky;
    const RingEntry* const rings = sky.rings.data();
    w.samples.clear();
    w.plates.clear();
    w.rows.clear();
    w.ranges_used = 0;
    w.size = 0;
    if (w.ring_lo.size() != sky.rings.size() + 1) {
      w.ring_lo.assign(sky.rings.size() + 1, std::numeric_limits<std::uint32_t>::max());
      w.ring_hi.assign(sky.rings.size() + 1, 0);
      w.ring_offset.assign(sky.rings.size() + 1, 0);
    }
    std::uint32_t* const lo = w.ring_lo.data();
    std::uint32_t* const hi = w.ring_hi.data();
    std::uint64_t count = 0;
    std::uint32_t ring0 = std::numeric_limits<std::uint32_t>::max(), ring1 = 0;
    // Each sample's frame, value and ranges, split where they cross from one ring to the next (only
    // a polar cap does), each range's ring, and each ring's reach.
    for (std::size_t i = begin; i < end; ++i) {
      if (tod[i] == 0.0) continue;
      Window::Sample s;
      double theta = 0.0, phi = 0.0;
      s.f = detector_frame(pointing, i, det, theta, phi);
      s.value = tod[i];
      double m[16];
      if (plate)
        plate_at(&det.plate_mueller[0][0], std::cos(2 * pointing.plate_angle[i]), std::sin(2 * pointing.plate_angle[i]),
                 m);
      const std::size_t c = simd::disc_ranges(kernel_, rings, ring_columns_, sky.nside, theta, phi, det.rho_max,
                                              det.cos_rho_max, w.disc);
      if (c == 0) continue;
      if (per_sample_) {  // the norm as the forward computes it (its float64 path)
        const simd::SampleInput in{&s.f, w.disc.data(), c / 2, plate ? m : nullptr, false, true};
        simd::SampleSums sums;
        simd::convolve_sample(kernel_, sky_.view, kd, in, sums);
        if (!(sums.norm > 0)) continue;
        s.value /= sums.norm;
      }
      // The ranges are in increasing pixel order, so their rings are too: at most one a range and
      // one a ring they span.
      const std::uint32_t first_ring = ring_of(sky, w.disc[0]), last_ring = ring_of(sky, w.disc[c - 1] - 1);
      const std::size_t most = c + 2 * std::size_t(last_ring - first_ring + 1);
      if (w.ranges.size() < w.ranges_used + most) {
        w.ranges.resize(std::max(w.ranges_used + most, 2 * w.ranges.size()));
        w.rings.resize(w.ranges.size() / 2);
      }
      std::uint32_t* out = w.ranges.data() + w.ranges_used;
      std::uint32_t* out_ring = w.rings.data() + w.ranges_used / 2;
      std::uint32_t ring = first_ring, ring_end = rings[ring].first + rings[ring].count;
      const std::uint64_t before = count;
      for (std::size_t q = 0; q < c; q += 2) {
        std::uint32_t b = w.disc[q];
        const std::uint32_t e = w.disc[q + 1];
        count += e - b;
        while (b >= ring_end) {
          ++ring;
          ring_end = rings[ring].first + rings[ring].count;
        }
        for (;;) {
          const std::uint32_t stop = std::min(e, ring_end);
          out[0] = b;
          out[1] = stop;
          out += 2;
          *out_ring++ = ring;
          lo[ring] = std::min(lo[ring], b);
          hi[ring] = std::max(hi[ring], stop);
          if (stop == e) break;
          b = stop;
          ++ring;
          ring_end = rings[ring].first + rings[ring].count;
        }
      }
      ring0 = std::min(ring0, first_ring);
      ring1 = std::max(ring1, last_ring);
      s.first = std::uint32_t(w.ranges_used);
      w.ranges_used = std::size_t(out - w.ranges.data());
      s.count = std::uint32_t(w.ranges_used - s.first);
      s.pixels = std::uint32_t(count - before);
      // The normal pass sums the forward's response over the ranges it scatters; a polar cap, one range
      // of the forward's disc, is split here by ring, which would group its pixels into other vectors
      // and so round the sum otherwise: such a sample (its disc holds a pole) is summed by the forward
      // kernel over the disc's own ranges, as convolve sums it, and scattered with that value.
      if (normal && s.count != c) {
        const simd::SampleInput in{&s.f, w.disc.data(), c / 2, plate ? m : nullptr, false, false};
        simd::SampleSums sums;
        simd::convolve_sample(kernel_, sky_.view, kd, in, sums);
        s.value = sums.sum + monopole_ * sums.monopole_weight;
        s.summed = true;
      }
      w.samples.push_back(s);
      if (plate) std::copy_n(m, 16, w.plates.emplace_back().data());
    }
    if (w.samples.empty()) return count;
    // The window: for each ring from ring0 to ring1, the pixels from the lowest to the highest any
    // range reaches, one row after the other, with a gap of a cache line after each
    // (simd::window_gap): rows of whole rings of NSIDE 128 and more would otherwise lie a multiple of
    // 4 KiB apart. Pixel p of ring k lands at p + offset = p - lo + at (modulo 2^32, as the kernel adds).
    w.ring0 = ring0;
    w.rows.resize(ring1 - ring0 + 1);
    std::size_t size = 0;
    for (std::uint32_t k = ring0; k <= ring1; ++k) {
      Window::Row& row = w.rows[k - ring0];
      row = hi[k] > lo[k] ? Window::Row{lo[k], hi[k], size} : Window::Row{0, 0, size};
      w.ring_offset[k] = std::uint32_t(row.at) - row.lo;
      size += row.hi - row.lo + simd::window_gap;
      lo[k] = std::numeric_limits<std::uint32_t>::max();
      hi[k] = 0;
    }
    w.size = size;
    return count;
  }

  // One adjoint task's scatter into its window, zeroed first (with `normal`, the normal pass's).
  void fill_task(const KernelDetector& kd, bool plate, int outputs, bool squares, bool normal, Window& w) const {
    if (w.samples.empty()) return;
    // The whole window is this thread's: a range's last vector may add zeros into the next row.
    for (int c = 0; c < outputs; ++c) w.maps[c].assign(w.size, 0.0);
    // The normal pass's weights of one disc (simd::normal_scratch_floats), a buffer a thread, sized
    // to the largest disc of the task: 32 bytes a pixel (0.8 MB for 10 deg discs at NSIDE 512).
    thread_local std::vector<float> scratch;
    if (normal) {
      std::size_t pixels = 0, ranges = 0;
      for (const Window::Sample& s : w.samples) {
        pixels = std::max<std::size_t>(pixels, s.pixels);
        ranges = std::max<std::size_t>(ranges, s.count / 2);
      }
      if (scratch.size() < simd::normal_scratch_floats(pixels, ranges))
        scratch.resize(simd::normal_scratch_floats(pixels, ranges));
    }
    for (std::size_t k = 0; k < w.samples.size(); ++k) {
      const Window::Sample& s = w.samples[k];
      simd::ScatterInput in{&s.f,    w.ranges.data() + s.first, w.rings.data() + s.first / 2, w.ring_offset.data(),
                            s.count / 2, plate ? w.plates[k].data() : nullptr, s.value, squares, w.size,
                            {w.maps[0].data(), w.maps[1].data(), w.maps[2].data(), w.maps[3].data()}};
      if (normal && !s.summed) {
        in.normal = true;
        in.pixels = s.pixels;
        in.scratch = scratch.data();
      }
      simd::scatter_sample(kernel_, sky_.view, kd, in);
    }
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
      simd::convolve_sample(kernel_, in.sky ? polar_.view : sky_.view, kd, sample, sums);
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
  bool per_sample_ = false, float64_ = false;  // float64_: the float64 path (monopole or per-sample normalization)
  PackedSky sky_, polar_;  // the sky, and its polar copy's band (set_polar_sky)
  std::vector<DetectorTables> tables_;
  std::uint64_t evaluated_ = 0;
  std::array<std::vector<double>, 4> adjoint_;  // I, Q, U, V
  std::vector<Window> windows_;                  // the adjoint's, one a task of the wave at hand
};

}  // namespace

void attach_simd_backend(BackendEntry& e) {
  e.probe = [] {
    try {
      const simd::Kernel k = simd::choose_kernel(requested_target(""));
      BackendInfo info{"simd", true,
                       "Highway " + k.description + " on " + std::to_string(hardware_threads()) + " hardware threads",
                       {}, {}};
      info.capabilities.worker_threads = true;
      info.capabilities.adjoint = true;
      info.capabilities.normal = true;
      return info;
    } catch (const Error& e) {
      return BackendInfo{"simd", false, e.what(), {}, {}};
    }
  };
  e.create = [](std::shared_ptr<const EngineInputs> in, const SkyView& sky,
                const EngineOptions& o) -> std::unique_ptr<Backend> {
    return std::make_unique<SimdBackend>(std::move(in), sky, o);
  };
}

}  // namespace pisco::detail
