// What the CUDA kernel computes for one sample, written as host/device functions so that the host can
// run the very same float32 arithmetic (tests/test_cuda_host.cpp checks the precision contract of
// docs/validation.md, "B", without a GPU). The kernel (convolve.cu) adds only the warp plumbing: shared memory for the
// range batch, __syncwarp and the shuffle reduction.
//
// One warp per sample. The warp walks the disc's rings together, one ring a lane (the cooperative disc
// walk below, for_each_disc_range's float64 arithmetic, as the reference's), and the ranges are
// gathered in ring order into batches of up to batch_ranges, cut where walk_disc, the serial walk the
// host emulation keeps, cuts them; the batch's pixels,
// numbered 0 ... total-1 across its ranges, are dealt to the lanes round-robin, so a lane stays busy
// however short the rings are. The assignment depends only on the disc, never on the chunk or launch
// size: results are deterministic.
//
// Precision: the sky is stored in float32 with its monopole I0 removed (a 2.725 K monopole would leave
// float32 only ~0.3 uK of resolution). The monopole's own contribution, I0 sum_k w_I(k), and the
// per-sample normalization sum_k wn(k) are summed in float64 from double pixel vectors and double
// weights: the same arithmetic as the reference. On that path the float32 evaluation also takes its
// beam coordinates (x, y) from the float64 ones, which cuts its error about five-fold for free (the
// rounding of the float32 pixel vectors is the largest float32 error, amplified by the beam's slope);
// otherwise the whole evaluation is the arithmetic of src/kernel/pixel.glsl in float (kernel/contribution.hpp).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "kernel/cap_boundary.hpp"
#include "kernel/contribution.hpp"
#include "kernel/disc.hpp"
#include "kernel/frame.hpp"
#include "kernel/plate.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail::cuda {

constexpr int warp_lanes = 32;
constexpr int batch_ranges = 32;

// One sky pixel as the kernel reads it: two 16-byte loads.
struct alignas(16) PixelRecord {
  float kx, ky, kz;  // unit vector
  float i;           // I - I0
  float q, u, v, pad;
};

struct KernelSky {
  const PixelRecord* pixels;
  const double* vectors;  // 4 doubles per pixel (kx, ky, kz, 0); only for the float64 sums
  const RingEntry* rings;
  std::int64_t nside;
  double monopole;        // I0, removed from PixelRecord::i (times boundary.at(p))
  CapBoundary boundary;   // the rings where the polar caps meet the belt: the monopole's weight there
};

struct KernelDetector {
  // w per node, 4 floats (reference layout, converted); with columns == 2, (w_I, w_Q) of node k and of
  // node k + 1 (IQPairGrid), for detectors without w_U and w_V (device_data.hpp, kernel_columns)
  const float* weights;
  int columns;
  const double* weights64;      // (w_I, wn, 0, 0) per node in double; only on the float64 path
  const double* plate_weights;  // aperture plates: (w_Q, w_U, w_V, 0) per node in double, for the float64 sums
  int grid_n;
  float grid_a, grid_inv_step;
  double grid_a_d, grid_inv_step_d;
  double rho_max, cos_rho_max;
  double cos_zeta, sin_zeta;
  DetectorOffset offset;  // from the boresight
  double plate_mueller[16];  // aperture plates: M0, row-major
};

// One sample's plate (aperture plates): M(theta) by columns in float32 for the pixels' effective
// weights, and its column 0 in float64 for the monopole's weight sum_a w_a M_a0.
struct PlateSample {
  Vec4<float> columns[4];  // M(theta) by columns, the form effective_weights takes
  Vec4<double> col0;
};

PISCO_HD PlateSample plate_sample(const KernelDetector& det, double theta) {
  const double* m0 = det.plate_mueller;
  Vec4<double> m[4];
  plate_rows(Vec4<double>{m0[0], m0[1], m0[2], m0[3]}, Vec4<double>{m0[4], m0[5], m0[6], m0[7]},
             Vec4<double>{m0[8], m0[9], m0[10], m0[11]}, Vec4<double>{m0[12], m0[13], m0[14], m0[15]},
             cos(2.0 * theta), sin(2.0 * theta), m[0], m[1], m[2], m[3]);
  PlateSample p;
  p.columns[0] = {float(m[0].x), float(m[1].x), float(m[2].x), float(m[3].x)};
  p.columns[1] = {float(m[0].y), float(m[1].y), float(m[2].y), float(m[3].y)};
  p.columns[2] = {float(m[0].z), float(m[1].z), float(m[2].z), float(m[3].z)};
  p.columns[3] = {float(m[0].w), float(m[1].w), float(m[2].w), float(m[3].w)};
  p.col0 = {m[0].x, m[1].x, m[2].x, m[3].x};
  return p;
}

// Per-lane partial sums.
struct LaneSums {
  float sum = 0.0f, carry = 0.0f;  // Kahan-compensated sum of the float32 contributions
  double monopole = 0.0;            // sum of w_I, float64
  double norm = 0.0;                // sum of the normalization weight, float64
};

// The detector's basis and line of sight for one sample of a chunk: `pointing` holds 4 doubles a
// sample, (theta, phi, psi, 0) or a boresight quaternion (x, y, z, w) (frame.hpp).
PISCO_HD SampleFrame<double> sample_frame(const double* pointing, bool quaternions, const KernelDetector& det,
                                          double& theta, double& phi) {
  if (quaternions)
    return quat_sample({pointing[0], pointing[1], pointing[2], pointing[3]}, det.offset, det.cos_zeta, det.sin_zeta,
                       theta, phi);
  return angle_sample(pointing[0], pointing[1], pointing[2], det.offset, det.cos_zeta, det.sin_zeta, theta, phi);
}

// The same in steps whose transcendental functions the warp spreads over its lanes (convolve.cu's
// warp_sample_frame; the same bits, tests/test_cuda_host.cpp):
// 1. angle pointing: lane k < 6 takes angle_trig(pointing, k), the cosine and sine of theta, phi and psi;
// 2. every lane builds the basis from the six (detector_basis); where the line of sight's angles are
//    not the pointing's own (quaternions, an offset),
// 3. lanes 0 and 1 take its theta and phi (frame.glsl's pisco_direction_angle);
// 4. the disc's three cosines on lanes 0 to 2 (disc_cos of kernel/disc.hpp).
constexpr int angle_trig_lanes = 6;
PISCO_HD double angle_trig(const double* pointing, int k) {
  const int angle = k >> 1;
  const double x = angle == 0 ? pointing[0] : angle == 1 ? wrap_phi(pointing[1]) : pointing[2];
  return (k & 1) != 0 ? pisco_sin(x) : pisco_cos(x);
}

// The detector's basis (theta', phi', p') of a sample from its pointing and, for angles, the six values
// of angle_trig; returns whether theta and phi (set from angle pointing) are the line of sight's,
// false when they are still to be taken from p (pisco_direction_angle).
PISCO_HD bool detector_basis(const double* pointing, bool quaternions, const KernelDetector& det,
                             const double trig[angle_trig_lanes], Vec3<double>& theta_p, Vec3<double>& phi_p,
                             Vec3<double>& p, double& theta, double& phi) {
  if (quaternions) {
    const Q4 b{pointing[0], pointing[1], pointing[2], pointing[3]};
    pisco_rotation(pisco_quat_mul(b, det.offset.quat), theta_p, phi_p, p);
    return false;
  }
  theta = pointing[0];
  phi = wrap_phi(pointing[1]);
  pisco_angle_basis(trig[0], trig[1], trig[2], trig[3], trig[4], trig[5], theta_p, phi_p, p);
  if (!det.offset.active) return true;
  pisco_offset_basis(det.offset.quat, theta_p, phi_p, p);
  return false;
}

PISCO_HD SampleFrame<float> to_float(const SampleFrame<double>& f) {
  auto v = [](const Vec3<double>& a) { return Vec3<float>{float(a.x), float(a.y), float(a.z)}; };
  return {v(f.theta_p), v(f.phi_p), v(f.p), v(f.e_c)};
}

PISCO_HD void kahan_add(LaneSums& s, float value) { pisco::detail::kahan_add(s.sum, s.carry, value); }

// A lane's compensated float32 total, the value that enters the warp reduction.
PISCO_HD float lane_total(const LaneSums& s) { return s.sum - s.carry; }

// Pixel number j of a batch: position j of the concatenated ranges [first[r], first[r] + offset[r+1] -
// offset[r]); r is the range of the lane's previous pixel (positions only grow) and is advanced.
PISCO_HD std::uint32_t batch_pixel(const std::uint32_t* first, const std::uint32_t* offset, std::uint32_t j, int& r) {
  while (j >= offset[r + 1]) ++r;
  return first[r] + (j - offset[r]);
}

// Pixel p's float32 geometry g and weights w, w M(theta) behind an aperture plate (kernel/plate.hpp).
// On the float64 path (Float64), the beam coordinates come from the float64 pixel vectors, which float32 pixel vectors
// would carry only to ~1e-7 (the largest float32 error otherwise, on steep beams); they are returned
// in x, y for the float64 sums.
template <bool Radial, bool Float64, bool Plate, class Grid>
PISCO_HD Vec4<float> pixel_weights(const KernelSky& sky, const Grid& grid, const SampleFrame<float>& f,
                                   const SampleFrame<double>& fd, std::uint32_t p, const PixelRecord& px,
                                   const PlateSample* plate, PixelGeometry<float>& g, double& x, double& y) {
  const Vec3<float> k{px.kx, px.ky, px.kz};
  g = pixel_geometry(f, k);
  if constexpr (Float64) {
    const double* kv = sky.vectors + 4 * std::size_t(p);
    const Vec3<double> kd{kv[0], kv[1], kv[2]};
    beam_coordinates(kd, fd.theta_p, fd.phi_p, x, y);
    g.x = float(x);
    g.y = float(y);
  }
  Vec4<float> w = Radial ? interpolate_radial(grid, g.r2) : interpolate_weights(grid, g.x, g.y);
  if constexpr (Plate) w = effective_weights(w, plate->columns[0], plate->columns[1], plate->columns[2], plate->columns[3]);
  return w;
}

// The float32 beam grid of a kernel variant: 4 columns a node (ArrayGrid), or with Columns == 2 the
// (w_I, w_Q) pairs of IQPairGrid, one 16-byte load a node pair, whose U and V weights are zeros.
template <int Columns>
using FloatGrid = std::conditional_t<Columns == 2, IQPairGrid<float>, ArrayGrid<float>>;

template <int Columns>
PISCO_HD FloatGrid<Columns> float_grid(const KernelDetector& det) {
  return {det.weights, det.grid_n, det.grid_a, det.grid_inv_step};
}

// The pixels of one batch that fall to `lane`: positions lane, lane + 32, ... of the batch. The
// float64 path (Float64) is taken for the monopole's weight and for the per-sample normalization.
// With Columns == 2 (no w_U, w_V; never behind a plate) the response leaves out the zero U and V
// terms (stokes_response_iq): the same values.
template <bool Radial, bool Monopole, bool PerSample, bool Plate = false, int Columns = 4>
PISCO_HD void process_batch(const KernelSky& sky, const KernelDetector& det, const SampleFrame<float>& f,
                            const SampleFrame<double>& fd, const std::uint32_t* first,
                            const std::uint32_t* offset, int count, int lane, LaneSums& acc,
                            const PlateSample* plate = nullptr) {
  constexpr bool Float64 = Monopole || PerSample;
  static_assert(Columns == 4 || (Columns == 2 && !Plate), "a plate mixes all four columns");
  const std::uint32_t total = offset[count];
  const FloatGrid<Columns> grid = float_grid<Columns>(det);
  const ArrayGrid<double> weights64{det.weights64, det.grid_n, det.grid_a_d, det.grid_inv_step_d};
  const ArrayGrid<double> plate64{det.plate_weights, det.grid_n, det.grid_a_d, det.grid_inv_step_d};
  int r = 0;
  for (std::uint32_t j = std::uint32_t(lane); j < total; j += warp_lanes) {
    const std::uint32_t p = batch_pixel(first, offset, j, r);
    const PixelRecord px = sky.pixels[p];
    const Vec4<float> S{px.i, px.q, px.u, px.v};
    PixelGeometry<float> g;
    double x = 0.0, y = 0.0;
    const Vec4<float> w = pixel_weights<Radial, Float64, Plate>(sky, grid, f, fd, p, px, plate, g, x, y);
    kahan_add(acc, Columns == 2 ? stokes_response_iq(w, g.cos2chi, g.sin2chi, S)
                                : stokes_response(w, g.cos2chi, g.sin2chi, S));
    if constexpr (Float64) {
      const Vec4<double> we =
          Radial ? interpolate_radial(weights64, x * x + y * y) : interpolate_weights(weights64, x, y);
      if constexpr (Monopole) {
        const double ring = sky.boundary.at(p);
        if constexpr (Plate) {
          // (w_Q, w_U, w_V, 0)
          const Vec4<double> wp =
              Radial ? interpolate_radial(plate64, x * x + y * y) : interpolate_weights(plate64, x, y);
          acc.monopole += ring * plate_monopole_weight(Vec4<double>{we.x, wp.x, wp.y, wp.z}, plate->col0);
        } else {
          acc.monopole += ring * we.x;
        }
      }
      if constexpr (PerSample) acc.norm += we.y;
    }
  }
}

// The adjoint (docs/cuda.md, "The adjoint"): the pixels of one batch that fall to `lane`, each adding
// round(v g_c) for its Stokes components c, g = stokes_adjoint(w, chi) (g_c^2 with Squares, the diagonal
// of A^T A; kernel/fixed_point.glsl's fixed_share), through add(4 p + c, q): an integer atomic on the
// device, so that the sums are the same bits whatever the order of the warps. The geometry and weights
// are the forward's (Float64 as the forward's). With Columns == 2, the V weight is zero and the U
// weight's terms of w_U are signed zeros (stokes_adjoint_iq): the same integers.
template <bool Radial, bool Float64, bool Plate, bool Squares, int Columns = 4, class Add>
PISCO_HD void scatter_batch(const KernelSky& sky, const KernelDetector& det, const SampleFrame<float>& f,
                            const SampleFrame<double>& fd, const std::uint32_t* first, const std::uint32_t* offset,
                            int count, int lane, double value, const PlateSample* plate, Add&& add) {
  static_assert(Columns == 4 || (Columns == 2 && !Plate), "a plate mixes all four columns");
  const std::uint32_t total = offset[count];
  const FloatGrid<Columns> grid = float_grid<Columns>(det);
  int r = 0;
  for (std::uint32_t j = std::uint32_t(lane); j < total; j += warp_lanes) {
    const std::uint32_t p = batch_pixel(first, offset, j, r);
    PixelGeometry<float> g;
    double x = 0.0, y = 0.0;
    const Vec4<float> w = pixel_weights<Radial, Float64, Plate>(sky, grid, f, fd, p, sky.pixels[p], plate, g, x, y);
    Vec4<float> a;
    if constexpr (Columns == 2) {
      const Vec3<float> iqu = stokes_adjoint_iq(w, g.cos2chi, g.sin2chi);
      a = {iqu.x, iqu.y, iqu.z, 0.0f};
    } else {
      a = stokes_adjoint(w, g.cos2chi, g.sin2chi);
    }
    const float gs[4] = {a.x, a.y, a.z, a.w};
    for (int c = 0; c < (Columns == 2 ? 3 : 4); ++c)  // with two columns V's weight is zero
      if (const std::int64_t q = fixed_share(value, gs[c], Squares)) add(4 * std::size_t(p) + std::size_t(c), q);
  }
}

// Walks the disc of (theta, phi), gathering ranges into first[]/offset[] (written only where
// `writer`) and calling flush(count) whenever batch_ranges ranges are gathered and once at the end.
// Returns the disc's pixel count. The serial walk: the host emulation's, and the batches the
// kernel's cooperative walk must give (tests/test_cuda_host.cpp).
template <class Flush>
PISCO_HD std::uint32_t walk_disc(const KernelSky& sky, const KernelDetector& det, double theta, double phi,
                                 std::uint32_t* first, std::uint32_t* offset, bool writer, Flush&& flush) {
  std::uint32_t pixels = 0, batched = 0;
  int count = 0;
  if (writer) offset[0] = 0;
  for_each_disc_range(sky.rings, sky.nside, theta, phi, det.rho_max, det.cos_rho_max,
                      [&](std::uint32_t begin, std::uint32_t end) {
                        if (end <= begin) return;
                        batched += end - begin;
                        if (writer) {
                          first[count] = begin;
                          offset[count + 1] = batched;
                        }
                        if (++count == batch_ranges) {
                          flush(count);
                          pixels += batched;
                          batched = 0;
                          count = 0;
                        }
                      });
  if (count > 0) flush(count);
  return pixels + batched;
}

// The cooperative disc walk (docs/cuda.md, "Kernel"): the warp walks the disc's rings 32 at a time, one
// ring a lane, instead of every lane walking every ring. Each lane finds its ring's ranges with the
// float64 arithmetic of for_each_disc_range (at most two, non-empty ones only), and the warp stages
// them in ring order in shared memory: the north cap's range first, each pass's lanes in order, the
// south cap's last, the very order walk_disc emits. The batches of batch_ranges ranges are then cut
// from the staging exactly as walk_disc cuts them, so every lane gets the same pixels and the TOD the
// same bits. The kernel (convolve.cu, walk_disc_warp) supplies the warp's ballots and scans;
// tests/test_cuda_host.cpp runs these steps lane by lane and requires walk_disc's batches.

// Ring iz's non-empty ranges in the disc d, in for_each_disc_range's order: [begin0, end0) when count >= 1,
// [begin1, end1) when 2. Named fields, not arrays: an array indexed by a lane's own count would live
// in local memory (47 of the 53 local loads in the sm_90 code of the common variants when it was one).
struct RingRanges {
  int count = 0;
  std::uint32_t begin0 = 0, end0 = 0, begin1 = 0, end1 = 0;
};

PISCO_HD RingRanges ring_ranges(const KernelSky& sky, const DiscRings& d, double phi0, double cos_rho,
                                std::int64_t iz) {
  RingRanges out;
  const RingEntry& r = sky.rings[iz - 1];
  double x, ysq;
  ring_edge(r, d, cos_rho, x, ysq);
  if (ysq <= 0) return out;  // the ring does not cross the disc boundary
  emit_ring_crossing(r, phi0, x, ysq, [&](std::uint32_t begin, std::uint32_t end) {
    if (end <= begin) return;
    if (out.count == 0) {
      out.begin0 = begin;
      out.end0 = end;
    } else {
      out.begin1 = begin;
      out.end1 = end;
    }
    ++out.count;
  });
  return out;
}

// The staging's capacity: fewer than batch_ranges left over, and a pass's 32 lanes with two ranges each.
constexpr int staging_ranges = 3 * batch_ranges;
static_assert(batch_ranges == warp_lanes, "a batch's offsets are one warp scan");

PISCO_HD int popcount32(std::uint32_t v) {
#if defined(__CUDA_ARCH__)
  return __popc(v);
#else
  return __builtin_popcount(v);
#endif
}

// The lanes below `lane`, as a mask.
PISCO_HD std::uint32_t lanes_below(int lane) { return lane == 0 ? 0u : 0xffffffffu >> (warp_lanes - lane); }

// Lane `lane`'s ranges into the staging, after the `pending` ranges already there and those of the
// lanes below it: `one` and `two` are the warp's masks of the lanes with at least one and with two.
PISCO_HD void stage_ranges(std::uint32_t* begin, std::uint32_t* end, int pending, std::uint32_t one, std::uint32_t two,
                           int lane, const RingRanges& rr) {
  const std::uint32_t below = lanes_below(lane);
  const int at = pending + popcount32(one & below) + popcount32(two & below);
  if (rr.count >= 1) {
    begin[at] = rr.begin0;
    end[at] = rr.end0;
  }
  if (rr.count == 2) {
    begin[at + 1] = rr.begin1;
    end[at + 1] = rr.end1;
  }
}

// After a whole batch: lane `lane`'s share of moving the staging's ranges [batch_ranges, pending) to its
// front. Each lane reads slots batch_ranges + lane and 2 batch_ranges + lane and writes lane and
// batch_ranges + lane, so no lane reads what another writes.
PISCO_HD void unstage_batch(std::uint32_t* begin, std::uint32_t* end, int pending, int lane) {
  const int a = batch_ranges + lane, b = 2 * batch_ranges + lane;
  const bool has_a = a < pending, has_b = b < pending;
  const std::uint32_t begin_a = has_a ? begin[a] : 0u, end_a = has_a ? end[a] : 0u;
  const std::uint32_t begin_b = has_b ? begin[b] : 0u, end_b = has_b ? end[b] : 0u;
  if (has_a) {
    begin[lane] = begin_a;
    end[lane] = end_a;
  }
  if (has_b) {
    begin[a] = begin_b;
    end[a] = end_b;
  }
}

// A polar cap's range (disc.hpp's emit_north_cap and emit_south_cap, as walk_disc takes them) staged
// after the `pending` ranges by `writer`; every lane counts it.
template <class EmitCap>
PISCO_HD void stage_cap(std::uint32_t* begin, std::uint32_t* end, int& pending, bool writer, EmitCap&& emit_cap) {
  emit_cap([&](std::uint32_t b, std::uint32_t e) {
    if (writer) {
      begin[pending] = b;
      end[pending] = e;
    }
    ++pending;
  });
}

// The sample from the reduced sums, as every backend (src/kernel/pixel.glsl): float32 sum plus I0 sum w_I,
// over the normalization when per-sample.
PISCO_HD double finish_sample(float sum, double monopole_weight, double norm, double monopole, bool per_sample) {
  return pisco::detail::finish_sample(double(sum), monopole, monopole_weight, norm, per_sample);
}

}  // namespace pisco::detail::cuda
