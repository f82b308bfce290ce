// The simd backend's kernel (docs/simd.md): one sample's disc, a vector of float32 lanes at a time.
// Highway compiles this file once per instruction set (foreach_target.h re-includes it with each
// target's HWY_NAMESPACE) and HWY_DYNAMIC_DISPATCH picks the best the processor supports at run time:
// AVX-512 (Highway's AVX3), AVX2, SSE4 or the portable EMU128 on x86-64; NEON on Arm.
//
// The per-pixel formulas are kernel/contribution-inl.hpp, included into each target's namespace with
// T = F, a float32 vector with +, -, *, /: the reference's own arithmetic, lane by lane. Only what
// cannot be written as a formula of T is vector code here: loads, the beam weights' record lookups,
// the interpolation's index arithmetic and masks, and the compensated sum.
//
// The pixels of a range are consecutive in RING order, so the sky is stored as structure of arrays
// and a vector of pixels is one contiguous load per quantity; a range's last vector is loaded whole
// (the arrays are padded) and its lanes past the range are masked out of the sum. Each range starts
// at lane 0: which lane evaluates a pixel depends only on the disc, so results are deterministic and
// independent of the chunk size and of the thread that runs the sample.

#include "simd/targets.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "simd/simd_kernel.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>
#include <hwy/contrib/math/math-inl.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <type_traits>
#include <vector>

#include "simd/simd_kernel.hpp"
#include "pisco/error.hpp"

HWY_BEFORE_NAMESPACE();
namespace pisco::detail::simd {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;
using MF = hn::Mask<DF>;

// A vector of float32 lanes as the number type of the shared formulas, with its index vector I and
// mask M. Trivially constructible, as float is: the formulas' aggregates (Vec3<F>, PixelGeometry<F>)
// get implicit constructors, which GCC compiles without the target's instruction set.
struct I {
  VI v;
};
struct M {
  MF v;
};
struct F {
  VF v;
  F() = default;
  HWY_INLINE F(float x) : v(hn::Set(DF(), x)) {}            // NOLINT: 1.0f, 2.0f in the formulas
  HWY_INLINE F(VF x) : v(x) {}                              // NOLINT
  HWY_INLINE explicit F(const I& i) : v(hn::ConvertTo(DF(), i.v)) {}  // float(i)
};
HWY_INLINE F operator+(const F& a, const F& b) { return F(hn::Add(a.v, b.v)); }
HWY_INLINE F operator-(const F& a, const F& b) { return F(hn::Sub(a.v, b.v)); }
HWY_INLINE F operator*(const F& a, const F& b) { return F(hn::Mul(a.v, b.v)); }
HWY_INLINE F operator/(const F& a, const F& b) { return F(hn::Div(a.v, b.v)); }
HWY_INLINE M operator>=(const F& a, const F& b) { return {hn::Ge(a.v, b.v)}; }
HWY_INLINE M operator<=(const F& a, const F& b) { return {hn::Le(a.v, b.v)}; }  // false for NaN
HWY_INLINE M operator&&(const M& a, const M& b) { return {hn::And(a.v, b.v)}; }
HWY_INLINE I operator+(const I& a, const I& b) { return {hn::Add(a.v, b.v)}; }
HWY_INLINE I operator+(const I& a, int b) { return {hn::Add(a.v, hn::Set(DI(), b))}; }
HWY_INLINE I operator*(const I& a, int b) { return {hn::Mul(a.v, hn::Set(DI(), b))}; }
HWY_INLINE F sqrt(const F& a) { return F(hn::Sqrt(a.v)); }
HWY_INLINE F max(const F& a, float b) { return F(hn::Max(a.v, hn::Set(DF(), b))); }

// The formulas of src/kernel/pixel.glsl, in this target's namespace (Vec3, SampleFrame, pixel_geometry,
// interpolate_weights, stokes_response, effective_weights, kahan_add, ...).
#include "kernel/contribution-inl.hpp"

template <>
struct Lanes<F> {
  using Index = I;
  using Mask = M;
};

// The interpolation's hooks for vectors of lanes: Highway's conversion is defined for every input
// (lanes outside the grid get a clamped node, their weights discarded by select_weights).
HWY_INLINE I node_index(const F& u, const M&, int top) {
  return {hn::Min(hn::Max(hn::ConvertTo(DI(), u.v), hn::Zero(DI())), hn::Set(DI(), top))};
}
HWY_INLINE Vec4<F> select_weights(const M& inside, const Vec4<F>& w) {
  return {F(hn::IfThenElseZero(inside.v, w.x.v)), F(hn::IfThenElseZero(inside.v, w.y.v)),
          F(hn::IfThenElseZero(inside.v, w.z.v)), F(hn::IfThenElseZero(inside.v, w.w.v))};
}

constexpr std::size_t max_lanes = 64;
static_assert(HWY_MAX_BYTES / sizeof(float) <= max_lanes, "scratch arrays hold one vector of float32 lanes");

HWY_INLINE Vec3<F> broadcast(const detail::Vec3<double>& a) {
  return {F(float(a.x)), F(float(a.y)), F(float(a.z))};
}

// A sample's float64 frame in float32 lanes, and a plate's M(theta) (row-major, float64) by columns.
HWY_INLINE SampleFrame<F> broadcast(const detail::SampleFrame<double>& fd) {
  SampleFrame<F> f;
  f.theta_p = broadcast(fd.theta_p);
  f.phi_p = broadcast(fd.phi_p);
  f.p = broadcast(fd.p);
  f.e_c = broadcast(fd.e_c);
  return f;
}

// A range's rest (fewer than N pixels) joining the staging vector of the forward and the adjoint,
// which holds `fill` lanes: each quantity of the rest is rotated by fill lanes (one table lookup) and
// blended in. join() gives the staging vector completed with the rest's first lanes, and leaves in
// `stage` the rest rotated, whose lanes turned round to the front are the overflow that starts the
// next staging vector.
class RestStaging {
 public:
  explicit RestStaging(std::size_t fill)
      : rotate_(hn::IndicesFromVec(DF(), hn::And(hn::Sub(hn::Iota(DI(), 0), hn::Set(DI(), int(fill))),
                                                   hn::Set(DI(), int(hn::Lanes(DF()) - 1))))),
        keep_(hn::FirstN(DF(), fill)) {}
  HWY_INLINE VF join(const VF& rest, VF& stage) const {
    const VF rotated = hn::TableLookupLanes(rest, rotate_);
    const VF joined = hn::IfThenElse(keep_, stage, rotated);
    stage = rotated;
    return joined;
  }

 private:
  decltype(hn::IndicesFromVec(DF(), hn::Zero(DI()))) rotate_;
  MF keep_;
};

HWY_INLINE void plate_columns(const double* m, Vec4<F> columns[4]) {
  for (int c = 0; c < 4; ++c) columns[c] = {F(float(m[c])), F(float(m[4 + c])), F(float(m[8 + c])), F(float(m[12 + c]))};
}

// Makes the compiler read `a` back from memory after it is stored: left to itself, GCC extracts the
// offsets of a lookup from the vector one by one (vpextrd: two micro-ops each, and a lane-crossing
// extract every four), slower than a store and a scalar load each.
template <class T, std::size_t N>
HWY_INLINE void from_memory(T (&a)[N]) {
#if HWY_ARCH_X86 && (defined(__GNUC__) || defined(__clang__))
  asm("" : "+m"(a));
#else
  (void)a;
#endif
}

// Four weights of a node for every lane: the record at table + 4 node of each lane, (w_a(k),
// w_b(k), w_a(k + 1), w_b(k + 1)) for two columns a, b and a node k, as four vectors of its fields.
// Each lane's record is one 16-byte load; the records of lanes j, j + 4, j + 8, ... fill one vector
// block by block, and a 4 x 4 transpose within the blocks (two rounds of interleaves) puts every
// field in lane order. On the x86 processors measured (BENCHMARKS.md, 2026-11-24) hardware gathers
// cost about two cycles an element: the loads and shuffles here made the whole backend 1.5x faster.
template <std::size_t N = hn::MaxLanes(DF())>
HWY_INLINE void lookup_records(const float* table, VI node, F out[4]) {
  const DF df;
#if HWY_TARGET == HWY_SCALAR
  const VI o = hn::ShiftLeft<2>(node);
  for (int k = 0; k < 4; ++k) out[k] = F(hn::GatherIndex(df, table + k, o));
#else
  const DI di;
  static_assert(N == 4 || N == 8 || N == 16, "vectors of whole 16-byte blocks, at most four");
  HWY_ALIGN std::int32_t at[N];
  hn::Store(hn::ShiftLeft<2>(node), di, at);
  from_memory(at);
  const hn::Full128<float> d4;
  VF v[4];
  for (std::size_t j = 0; j < 4; ++j) {
    if constexpr (N == 4) {
      v[j] = hn::Load(d4, table + at[j]);
    } else if constexpr (N == 8) {
      v[j] = hn::Combine(df, hn::Load(d4, table + at[j + 4]), hn::Load(d4, table + at[j]));
    } else {
      const hn::Half<DF> d8;
      v[j] = hn::Combine(df, hn::Combine(d8, hn::Load(d4, table + at[j + 12]), hn::Load(d4, table + at[j + 8])),
                         hn::Combine(d8, hn::Load(d4, table + at[j + 4]), hn::Load(d4, table + at[j])));
    }
  }
  const hn::Repartition<double, DF> dd;
  const auto t0 = hn::BitCast(dd, hn::InterleaveLower(df, v[0], v[1]));  // f0 f0 f1 f1 of lanes 0, 1 a block
  const auto t1 = hn::BitCast(dd, hn::InterleaveUpper(df, v[0], v[1]));  // f2 f2 f3 f3
  const auto t2 = hn::BitCast(dd, hn::InterleaveLower(df, v[2], v[3]));  // the same of lanes 2, 3
  const auto t3 = hn::BitCast(dd, hn::InterleaveUpper(df, v[2], v[3]));
  out[0] = F(hn::BitCast(df, hn::InterleaveLower(dd, t0, t2)));
  out[1] = F(hn::BitCast(df, hn::InterleaveUpper(dd, t0, t2)));
  out[2] = F(hn::BitCast(df, hn::InterleaveLower(dd, t1, t3)));
  out[3] = F(hn::BitCast(df, hn::InterleaveUpper(dd, t1, t3)));
#endif
}

// A detector's float32 weights as records (lookup_records), for the shared interpolation: node k's
// (w_I, w_Q) and node k + 1's in one record of r01, and (w_U, w_V) of both in r23 (Columns == 4). A 2D
// grid keeps each cell's edge curvature terms beside its lower corner's node (stride 3,
// simd_backend.cpp's grid_records): records 3k, 3k + 1 = (ex(k), ex(k + n)) and 3k + 2 = (ey(k),
// ey(k + 1)), so that a pixel's reads of one row fall in one cache line. A radial profile: stride 1.
template <int Columns>
struct RecordGrid {
  const float* r01;
  const float* r23;
  int n;
  F a, inv_step;
  int stride;
};

template <int Columns>
HWY_INLINE void record_pair(const RecordGrid<Columns>& g, const I& r, Vec4<F>& w, Vec4<F>& next) {
  F a[4];
  lookup_records(g.r01, r.v, a);
  w.x = a[0];
  w.y = a[1];
  next.x = a[2];
  next.y = a[3];
  if constexpr (Columns == 4) {
    lookup_records(g.r23, r.v, a);
    w.z = a[0];
    w.w = a[1];
    next.z = a[2];
    next.w = a[3];
  } else {
    w.z = w.w = next.z = next.w = F(0.0f);
  }
}

template <int Columns>
HWY_INLINE void weight_pair(const RecordGrid<Columns>& g, const I& k, Vec4<F>& w, Vec4<F>& next) {
  record_pair(g, g.stride == 1 ? k : k * g.stride, w, next);
}

template <int Columns>
HWY_INLINE void edge_x_pair(const RecordGrid<Columns>& g, const I& k, const I&, const I&, Vec4<F>& ex0, Vec4<F>& ex1) {
  record_pair(g, k * g.stride + 1, ex0, ex1);
}

template <int Columns>
HWY_INLINE void edge_y_pair(const RecordGrid<Columns>& g, const I& k, Vec4<F>& ey0, Vec4<F>& ey1) {
  record_pair(g, k * g.stride + 2, ey0, ey1);
}

#if HWY_TARGET != HWY_SCALAR  // the float64 path there is the reference's scalar code
// The float64 path's counterpart of lookup_records: for every lane of a vector of doubles the
// record at table + off, (w(k), w(k + 1)) of one column; the even lanes' records fill one vector, the
// odd lanes' another, and one interleave puts w(k) and w(k + 1) each in lane order.
template <class DD, std::size_t H = hn::MaxLanes(DD())>
HWY_INLINE void lookup_pairs(DD dd, const double* table, hn::Vec<hn::RebindToSigned<DD>> off, hn::Vec<DD>& g0,
                             hn::Vec<DD>& g1) {
  static_assert(H == 2 || H == 4 || H == 8, "vectors of whole 16-byte blocks, at most four");
  HWY_ALIGN std::int64_t at[H];
  hn::Store(off, hn::RebindToSigned<DD>(), at);
  from_memory(at);
  const hn::Full128<double> d2;
  hn::Vec<DD> even, odd;
  if constexpr (H == 2) {
    even = hn::Load(d2, table + at[0]);
    odd = hn::Load(d2, table + at[1]);
  } else if constexpr (H == 4) {
    even = hn::Combine(dd, hn::Load(d2, table + at[2]), hn::Load(d2, table + at[0]));
    odd = hn::Combine(dd, hn::Load(d2, table + at[3]), hn::Load(d2, table + at[1]));
  } else {
    const hn::Half<DD> dq;
    even = hn::Combine(dd, hn::Combine(dq, hn::Load(d2, table + at[6]), hn::Load(d2, table + at[4])),
                       hn::Combine(dq, hn::Load(d2, table + at[2]), hn::Load(d2, table + at[0])));
    odd = hn::Combine(dd, hn::Combine(dq, hn::Load(d2, table + at[7]), hn::Load(d2, table + at[5])),
                      hn::Combine(dq, hn::Load(d2, table + at[3]), hn::Load(d2, table + at[1])));
  }
  g0 = hn::InterleaveLower(dd, even, odd);
  g1 = hn::InterleaveUpper(dd, even, odd);
}

// The float64 lanes D of the shared texts (float64_lanes-inl.h: half as many lanes as F's), for the
// float64 sums' beam coordinates and interpolation.
#include "simd/float64_lanes-inl.h"
static_assert(std::is_same_v<DD, hn::Rebind<double, hn::Half<DF>>>, "a vector of D holds half a vector of F");
HWY_INLINE D sqrt(const D& a) { return D(hn::Sqrt(a.v)); }
HWY_INLINE D max(const D& a, float b) { return D(hn::Max(a.v, hn::Set(DD(), double(b)))); }

template <>
struct Lanes<D> {
  using Index = L;
  using Mask = MD;
};

// The interpolation's hooks for float64 lanes: the node clamped (lanes outside the grid, whose
// weights select_weights discards, included), and one column's float64 records, (w(k), w(k + 1)) at
// record 2 k of its table (simd_backend.cpp's pairs64), the edges' curvature terms after the nodes
// (src/kernel/grid_curvature.hpp). Only x carries the column.
HWY_INLINE L node_index(const D& u, const MD&, int top) {
  return {hn::Min(hn::Max(hn::ConvertTo(DL(), u.v), hn::Zero(DL())), hn::Set(DL(), top))};
}
HWY_INLINE Vec4<D> select_weights(const MD& inside, const Vec4<D>& w) {
  return {D(hn::IfThenElseZero(inside.v, w.x.v)), D(hn::IfThenElseZero(inside.v, w.y.v)),
          D(hn::IfThenElseZero(inside.v, w.z.v)), D(hn::IfThenElseZero(inside.v, w.w.v))};
}
struct PairGrid {
  const double* table;
  int n;
  D a, inv_step;  // nodes at x_i = -a + i * step (radial: r_i = i * step)
};
HWY_INLINE void weight_pair(const PairGrid& g, const L& k, Vec4<D>& w, Vec4<D>& next) {
  hn::Vec<DD> w0, w1;
  lookup_pairs(DD(), g.table, hn::Add(k.v, k.v), w0, w1);
  w = {D(w0), D(0.0), D(0.0), D(0.0)};
  next = {D(w1), D(0.0), D(0.0), D(0.0)};
}
HWY_INLINE void edge_x_pair(const PairGrid& g, const L&, const L& i, const L& j, Vec4<D>& ex0, Vec4<D>& ex1) {
  weight_pair(g, i * g.n + j + g.n * g.n, ex0, ex1);
}
HWY_INLINE void edge_y_pair(const PairGrid& g, const L& k, Vec4<D>& ey0, Vec4<D>& ey1) {
  weight_pair(g, k + 2 * g.n * g.n, ey0, ey1);
}
#endif

// The float64 sums of pixels [p, p + count), count <= N, and their float64 beam coordinates
// rounded to float32 into xs, ys: the reference's arithmetic (beam_coordinates, interpolate_radial,
// interpolate_weights of kernel/interpolate.glsl), with T = D, vectors of N / 2 doubles, over the
// reference's own float64 weights; the branches of the interpolation become masks. Sums are kept per
// lane.
// Radial and Plate as Sample's; `monopole` and `norm` receive the sums (at finish(), where they are
// kept in vectors).
template <bool Radial, bool Plate>
struct Float64Sums {
#if HWY_TARGET == HWY_SCALAR
  Float64Sums(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, const detail::Vec4<double>& col0,
            double& monopole, double& norm)
      : sky(sky), in(in), fd(*in.frame), col0(col0), monopole(monopole), norm(norm),
        weights{det.weights, det.grid_n, det.grid_a_d, det.grid_inv_step_d},
        norm_weights{det.norm_weights, det.grid_n, det.grid_a_d, det.grid_inv_step_d} {}
  const KernelSky& sky;
  const SampleInput& in;
  const detail::SampleFrame<double>& fd;
  const detail::Vec4<double>& col0;
  double &monopole, &norm;
  const detail::ArrayGrid<double> weights, norm_weights;
  void operator()(std::size_t p, std::size_t count, float* xs, float* ys) {
    for (std::size_t l = 0; l < count; ++l) {
      const detail::Vec3<double> kd{sky.vx[p + l], sky.vy[p + l], sky.vz[p + l]};
      double x, y;
      detail::beam_coordinates(kd, fd.theta_p, fd.phi_p, x, y);
      xs[l] = float(x);
      ys[l] = float(y);
      const detail::Vec4<double> w =
          Radial ? detail::interpolate_radial(weights, x * x + y * y) : detail::interpolate_weights(weights, x, y);
      if (in.monopole)
        monopole += sky.boundary.at(p + l) * (Plate ? detail::plate_monopole_weight(w, col0) : w.x);
      if (in.per_sample)
        norm += (Radial ? detail::interpolate_radial(norm_weights, x * x + y * y)
                        : detail::interpolate_weights(norm_weights, x, y)).x;
    }
  }
  void finish() {}
#else
  using VD = hn::Vec<DD>;
  Float64Sums(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, const detail::Vec4<double>& col0,
            double& monopole, double& norm)
      : sky(sky), det(det), in(in), monopole(monopole), norm(norm), H(hn::Lanes(dd)) {
    const detail::SampleFrame<double>& fd = *in.frame;
    theta_p = {D(fd.theta_p.x), D(fd.theta_p.y), D(fd.theta_p.z)};
    phi_p = {D(fd.phi_p.x), D(fd.phi_p.y), D(fd.phi_p.z)};
    a = D(det.grid_a_d), inv_step = D(det.grid_inv_step_d);
    mono_acc = hn::Zero(dd), norm_acc = hn::Zero(dd);
    mcol = {D(col0.x), D(col0.y), D(col0.z), D(col0.w)};
  }
  const KernelSky& sky;
  const KernelDetector& det;
  const SampleInput& in;
  double &monopole, &norm;
  const DF df;
  const hn::Half<DF> dh;
  const DD dd;
  const std::size_t H;
  Vec3<D> theta_p, phi_p;
  D a, inv_step;
  VD mono_acc, norm_acc;
  Vec4<D> mcol;  // M(theta)'s column 0

  void operator()(std::size_t p, std::size_t count, float* xs, float* ys) {
    hn::Vec<hn::Half<DF>> xf[2], yf[2];
    for (std::size_t h = 0; h < 2; ++h) {
      const std::size_t first = p + h * H;
      const std::size_t live = count > h * H ? std::min(H, count - h * H) : 0;
      const Vec3<D> k{D(hn::LoadU(dd, sky.vx + first)), D(hn::LoadU(dd, sky.vy + first)), D(hn::LoadU(dd, sky.vz + first))};
      D x, y;
      beam_coordinates(k, theta_p, phi_p, x, y);
      xf[h] = hn::DemoteTo(dh, x.v);
      yf[h] = hn::DemoteTo(dh, y.v);
      // One column's weights at the pixels (the shared interpolation, kernel/interpolate.glsl).
      auto column = [&](const double* table) HWY_ATTR {
        const PairGrid g{table, det.grid_n, a, inv_step};
        return (Radial ? interpolate_radial(g, x * x + y * y) : interpolate_weights(g, x, y)).x;
      };
      const auto live_lanes = hn::FirstN(dd, live);
      if (in.monopole) {
        D w = column(det.pairs64[0]);
        if constexpr (Plate)
          w = plate_monopole_weight(Vec4<D>{w, column(det.pairs64[1]), column(det.pairs64[2]), column(det.pairs64[3])},
                                    mcol);
        // Pixels [p, p + count) lie in one ring: its weight, where the caps meet the belt.
        const double ring = sky.boundary.at(p);
        if (ring != 1.0) w = w * D(ring);
        mono_acc = hn::Add(mono_acc, hn::IfThenElseZero(live_lanes, w.v));
      }
      if (in.per_sample) norm_acc = hn::Add(norm_acc, hn::IfThenElseZero(live_lanes, column(det.pairs64[4]).v));
    }
    hn::StoreU(hn::Combine(df, xf[1], xf[0]), df, xs);
    hn::StoreU(hn::Combine(df, yf[1], yf[0]), df, ys);
  }
  void finish() {
    HWY_ALIGN double lanes[max_lanes];
    hn::Store(mono_acc, dd, lanes);
    for (std::size_t l = 0; l < H; ++l) monopole += lanes[l];
    hn::Store(norm_acc, dd, lanes);
    for (std::size_t l = 0; l < H; ++l) norm += lanes[l];
  }
#endif
};

// One sample. Radial: weights from a radial profile (else a 2D grid); Columns: weight columns stored
// (2: w_U = w_V = 0); Plate: effective weights w M(theta); Float64: the float64 sums (monopole,
// per-sample normalization), whose float64 beam coordinates the float32 evaluation then uses too,
// as the GPU kernels do (docs/vulkan.md, "Precision").
// flatten: the formulas, the lambdas and Highway's operations inlined into one loop (left to its
// heuristics, GCC calls pixel_geometry<F> out of line and passes its vectors through memory).
template <bool Radial, int Columns, bool Plate, bool Float64>
HWY_NOINLINE HWY_FLATTEN void Sample(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, SampleSums& out) {
  const DF df;
  const std::size_t N = hn::Lanes(df);
  const detail::SampleFrame<double>& fd = *in.frame;
  const SampleFrame<F> f = broadcast(fd);
  Vec4<F> mcols[4];  // Plate: the columns of M(theta) in float32, and its column 0 in float64
  detail::Vec4<double> col0{1.0, 0.0, 0.0, 0.0};
  if constexpr (Plate) {
    plate_columns(in.plate, mcols);
    col0 = {in.plate[0], in.plate[4], in.plate[8], in.plate[12]};
  }
  const RecordGrid<Columns> grid{det.records[0], det.records[Columns == 4 ? 1 : 0], det.grid_n, F(det.grid_a),
                                 F(det.grid_inv_step), Radial ? 1 : 3};
  const VF zero = hn::Zero(df);

  F sum(zero), carry(zero);
  double monopole = 0.0, norm = 0.0;

  // The float64 sums (Float64Sums) and the pixels' beam coordinates they round to float32.
  Float64Sums<Radial, Plate> float64(sky, det, in, col0, monopole, norm);

  // One vector of pixels: s[0..6] hold kx, ky, kz, I - I0, Q, U, V, and s[7], s[8] the float64 beam
  // coordinates rounded to float32 (Float64); lanes outside `live` add nothing.
  auto evaluate = [&](const VF* s, MF live) HWY_ATTR {
    const Vec3<F> k{F(s[0]), F(s[1]), F(s[2])};
    PixelGeometry<F> g = pixel_geometry(f, k);
    if constexpr (Float64) {
      g.x = F(s[7]);
      g.y = F(s[8]);
    }

    // The beam weights (zero outside the grid), through the records (RecordGrid).
    Vec4<F> w = Radial ? interpolate_radial(grid, g.r2) : interpolate_weights(grid, g.x, g.y);
    const Vec4<F> S{F(s[3]), F(s[4]), F(s[5]), F(s[6])};
    F response;
    if constexpr (Plate) {
      w = effective_weights(w, mcols[0], mcols[1], mcols[2], mcols[3]);
      response = stokes_response(w, g.cos2chi, g.sin2chi, S);
    } else if constexpr (Columns == 4) {
      response = stokes_response(w, g.cos2chi, g.sin2chi, S);
    } else {
      response = stokes_response_iq(w, g.cos2chi, g.sin2chi, S);
    }
    // Kahan-compensated float32 sum, lane by lane (as each GPU lane sums its pixels).
    kahan_add(sum, carry, F(hn::IfThenElseZero(live, response.v)));
  };

  // Whole vectors of a range straight from the sky; the rest of the range (fewer than N pixels)
  // joins a staging vector, which is evaluated whenever it is full. Rings crossing a Table 1 disc
  // are 17 to 40 pixels long: masking each range's last vector would leave up to half of the lanes
  // idle. The staging stays in registers: the rest of a range is rotated by the staging's fill
  // (one table lookup) and blended in; the lanes rotated round to the front are the overflow that
  // starts the next staging vector. The order depends only on the disc (deterministic results).
  const float* const columns[7] = {sky.kx, sky.ky, sky.kz, sky.i, sky.q, sky.u, sky.v};
  constexpr int quantities = (Columns == 4 || Plate) ? 7 : 6;  // V only where a weight multiplies it
  constexpr int staged = Float64 ? 9 : 7;
  HWY_ALIGN float xs[max_lanes] = {};
  HWY_ALIGN float ys[max_lanes] = {};
  VF stage[9], q[9];
  for (int c = 0; c < 9; ++c) stage[c] = q[c] = zero;
  std::size_t fill = 0;
  const MF all = hn::FirstN(df, N);
  for (std::size_t r = 0; r < in.range_count; ++r) {
    const std::size_t begin = in.ranges[2 * r], end = in.ranges[2 * r + 1];
    std::size_t p = begin;
    for (; p + N <= end; p += N) {
      for (int c = 0; c < quantities; ++c) q[c] = hn::LoadU(df, columns[c] + p);
      if constexpr (Float64) {
        float64(p, N, xs, ys);
        q[7] = hn::Load(df, xs);
        q[8] = hn::Load(df, ys);
      }
      evaluate(q, all);
    }
    if (p == end) continue;
    const std::size_t rest = end - p;
    if constexpr (Float64) float64(p, rest, xs, ys);
    const RestStaging staging(fill);
    for (int c = 0; c < staged; ++c) {
      if (c >= quantities && c < 7) continue;
      q[c] = staging.join(c < 7 ? hn::LoadU(df, columns[c] + p) : hn::Load(df, c == 7 ? xs : ys), stage[c]);
    }
    fill += rest;
    if (fill >= N) {
      evaluate(q, all);
      fill -= N;
    } else {
      for (int c = 0; c < staged; ++c) stage[c] = q[c];
    }
  }
  if (fill > 0) evaluate(stage, hn::FirstN(df, fill));

  if constexpr (Float64) float64.finish();
  HWY_ALIGN float totals[max_lanes];
  hn::Store(hn::Sub(sum.v, carry.v), df, totals);
  double total = 0.0;
  for (std::size_t l = 0; l < N; ++l) total += double(totals[l]);
  out.sum = total;
  out.monopole_weight = monopole;
  out.norm = norm;
}

template <bool Radial, int Columns, bool Plate>
HWY_INLINE void SampleFloat64(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, SampleSums& out) {
  if (in.monopole || in.per_sample)
    Sample<Radial, Columns, Plate, true>(sky, det, in, out);
  else
    Sample<Radial, Columns, Plate, false>(sky, det, in, out);
}

template <bool Radial, int Columns>
HWY_INLINE void SamplePlate(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, SampleSums& out) {
  if (in.plate)
    SampleFloat64<Radial, Columns, true>(sky, det, in, out);
  else
    SampleFloat64<Radial, Columns, false>(sky, det, in, out);
}

template <bool Radial>
HWY_INLINE void SampleColumns(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, SampleSums& out) {
  if (det.columns == 4)
    SamplePlate<Radial, 4>(sky, det, in, out);
  else
    SamplePlate<Radial, 2>(sky, det, in, out);
}

void ConvolveSample(const KernelSky& sky, const KernelDetector& det, const SampleInput& in, SampleSums& out) {
  if (det.radial)
    SampleColumns<true>(sky, det, in, out);
  else
    SampleColumns<false>(sky, det, in, out);
}

// The adjoint weights of a vector of pixels (unit vectors k); the fourth is zero where iq (two
// columns, no plate). With S (the normal pass), the forward's response of the lanes in `live` joins
// sum and carry (Kahan-compensated float32 lanes, as Sample sums them), from the sky's I - I0, Q, U (and
// V where a weight multiplies it).
template <bool Radial, int Columns, bool Plate>
struct AdjointWeights {
  static constexpr bool iq = Columns == 2 && !Plate;
  // Without U, V weights (two columns, no plate) the V column gets nothing: three maps are written.
  static constexpr int outputs = iq ? 3 : 4;
  static constexpr int stokes_in = (Columns == 4 || Plate) ? 4 : 3;
  AdjointWeights(const KernelDetector& det, const ScatterInput& in)
      : f(broadcast(*in.frame)),
        grid{det.records[0], det.records[Columns == 4 ? 1 : 0], det.grid_n, F(det.grid_a), F(det.grid_inv_step),
             Radial ? 1 : 3} {
    if constexpr (Plate) plate_columns(in.plate, mcols);
  }
  const DF df;
  const SampleFrame<F> f;
  Vec4<F> mcols[4];
  const RecordGrid<Columns> grid;
  F sum{hn::Zero(DF())}, carry{hn::Zero(DF())};

  Vec4<F> operator()(const VF& kx, const VF& ky, const VF& kz, const VF* S = nullptr, MF live = MF()) {
    const PixelGeometry<F> g = pixel_geometry(f, Vec3<F>{F(kx), F(ky), F(kz)});
    Vec4<F> w = Radial ? interpolate_radial(grid, g.r2) : interpolate_weights(grid, g.x, g.y);
    if constexpr (Plate) w = effective_weights(w, mcols[0], mcols[1], mcols[2], mcols[3]);
    if (S) {
      const Vec4<F> stokes{F(S[0]), F(S[1]), F(S[2]), F(stokes_in == 4 ? S[3] : hn::Zero(df))};
      const F response = iq ? stokes_response_iq(w, g.cos2chi, g.sin2chi, stokes)
                            : stokes_response(w, g.cos2chi, g.sin2chi, stokes);
      kahan_add(sum, carry, F(hn::IfThenElseZero(live, response.v)));
    }
    if constexpr (iq) {
      const Vec3<F> a = stokes_adjoint_iq(w, g.cos2chi, g.sin2chi);
      return Vec4<F>{a.x, a.y, a.z, F(0.0f)};
    } else {
      return stokes_adjoint(w, g.cos2chi, g.sin2chi);
    }
  }
};

#if HWY_TARGET != HWY_SCALAR
// A stretch of a range of a disc (Scatter): its place in the maps, whether its weights lie in the
// buffer of staged vectors (else of whole ones), its position there, and its pixels.
struct Stretch {
  std::uint32_t entry, at, count, staged;
};

// Pass 2 for one stretch: d times its weights (Mul, squared for the diagonal) added to its pixels,
// a float64 vector at a time (Mul, then Add: the same bits on every instruction set, with or
// without fused multiply-adds). A pixel's float32 weights do not depend on the lane that computes
// them, and each pixel of a disc is added once, so the order of the stretches changes no bit. The
// last vector's lanes past the stretch add zero to the pixels after it when those are the caller's
// own (below in.limit); otherwise it goes through a scratch copy of them.
// `from` is its buffer, by column; dv holds d.
template <class VD>
HWY_INLINE void AddStretch(const ScatterInput& in, const Stretch& s, float* const* from, int outputs, VD dv) {
  const hn::Half<DF> dh;
  const hn::Rebind<double, hn::Half<DF>> dd;
  const std::size_t H = hn::Lanes(dd);
  auto product = [&](const float* at) {
    auto v = hn::Mul(dv, hn::PromoteTo(dd, hn::LoadU(dh, at)));
    return in.squares ? hn::Mul(v, v) : v;
  };
  std::size_t j = 0;
  for (; j + H <= s.count; j += H)
    for (int c = 0; c < outputs; ++c) {
      double* map = in.maps[c] + s.entry + j;
      hn::StoreU(hn::Add(hn::LoadU(dd, map), product(from[c] + s.at + j)), dd, map);
    }
  if (j == s.count) return;
  const std::size_t rest = s.count - j;
  const auto live = hn::FirstN(dd, rest);
  if (s.entry + j + H <= in.limit) {
    for (int c = 0; c < outputs; ++c) {
      double* map = in.maps[c] + s.entry + j;
      hn::StoreU(hn::Add(hn::LoadU(dd, map), hn::IfThenElseZero(live, product(from[c] + s.at + j))), dd, map);
    }
    return;
  }
  for (int c = 0; c < outputs; ++c) {
    double* map = in.maps[c] + s.entry + j;
    HWY_ALIGN double scratch[max_lanes] = {};
    for (std::size_t l = 0; l < H; ++l) scratch[l] = l < rest ? map[l] : 0.0;
    hn::Store(hn::Add(hn::Load(dd, scratch), hn::IfThenElseZero(live, product(from[c] + s.at + j))), dd, scratch);
    for (std::size_t l = 0; l < rest; ++l) map[l] = scratch[l];
  }
}
#endif

#if HWY_TARGET != HWY_SCALAR
// Scatter's passes on vectors (below).
template <bool Normal, class W>
HWY_INLINE void ScatterVectors(const KernelSky& sky, const ScatterInput& in, W& weights) {
  const DF df;
  double d = in.value;
  constexpr int outputs = W::outputs;
  constexpr bool normal = Normal;  // a template parameter: the adjoint's own code has none of it
  const std::size_t N = hn::Lanes(df);
  const hn::Half<DF> dh;
  const hn::Rebind<double, hn::Half<DF>> dd;
  const std::size_t H = hn::Lanes(dd);
  auto dv = hn::Set(dd, d);
  // Pass 1 evaluates the disc's pixels as the forward does: a range's whole vectors straight from the
  // sky, the rest of it (fewer than N pixels) joined to a staging vector held in registers
  // (RestStaging), evaluated whenever it is full. Their float32 weights a go,
  // by column, to two buffers: `whole` a vector after the other, `staged` one staging vector after the
  // other (so that a range's rest, split between two staging vectors, lies in one stretch). Stretches
  // of ranges (a place in the maps, a buffer, a position in it, pixels) record where. When a buffer
  // is full, pass 2 adds d times each stretch's weights to its pixels.
  // The normal pass keeps the whole disc's weights (in.scratch: normal_scratch_floats), since d is
  // known only once every pixel is evaluated.
  std::size_t chunk = 2 * max_lanes;
  HWY_ALIGN float whole[4][2 * max_lanes + max_lanes];
  HWY_ALIGN float staged[4][2 * max_lanes + max_lanes];
  Stretch own_stretches[4 * max_lanes];
  float* whole_at[4] = {whole[0], whole[1], whole[2], whole[3]};
  float* staged_at[4] = {staged[0], staged[1], staged[2], staged[3]};
  Stretch* stretches = own_stretches;
  std::size_t max_stretches = 2 * chunk;
  if constexpr (normal) {
    chunk = in.pixels + 2 * max_lanes;
    const std::size_t column = (chunk + max_lanes + 15) & ~std::size_t(15);  // 64-byte aligned columns
    float* at = reinterpret_cast<float*>((reinterpret_cast<std::uintptr_t>(in.scratch) + 63) & ~std::uintptr_t(63));
    for (int c = 0; c < 4; ++c, at += column) whole_at[c] = at;
    for (int c = 0; c < 4; ++c, at += column) staged_at[c] = at;
    stretches = reinterpret_cast<Stretch*>(at);
    max_stretches = 2 * in.range_count + 2;
  }
  for (int c = 0; c < outputs; ++c) {  // the padding a stretch's last float64 vector reads
    std::fill_n(whole_at[c] + chunk, max_lanes, 0.0f);
    std::fill_n(staged_at[c] + chunk, max_lanes, 0.0f);
  }
  std::size_t whole_fill = 0, staged_fill = 0, count = 0, fill = 0;  // fill: the staging vector's lanes
  // The weights of one vector of pixels (q: kx, ky, kz, then the normal pass's I - I0, Q, U, V)
  // stored at `to` (by column).
  const MF all = hn::FirstN(df, N);
  auto evaluate = [&](const VF* v, MF live, float* const* to, std::size_t at) {
    const Vec4<F> a = weights(v[0], v[1], v[2], normal ? v + 3 : nullptr, live);
    const VF columns[4] = {a.x.v, a.y.v, a.z.v, a.w.v};
    for (int c = 0; c < outputs; ++c) hn::Store(columns[c], df, to[c] + at);
  };
  const float* const unit[7] = {sky.kx, sky.ky, sky.kz, sky.i, sky.q, sky.u, sky.v};
  constexpr int quantities = normal ? 3 + W::stokes_in : 3;
  VF stage[7], q[7];
  for (int c = 0; c < 7; ++c) stage[c] = q[c] = hn::Zero(df);
  // Pass 2 for every stretch so far; the staging vector's lanes so far (fill) evaluated first. The
  // normal pass flushes once, at the end of the disc, and takes d from its sum first, as the forward
  // does (its lanes' compensated totals added in float64 in lane order).
  auto flush = [&] {
    if (fill > 0) {
      evaluate(stage, hn::FirstN(df, fill), staged_at, staged_fill);
      staged_fill += N;
      fill = 0;
    }
    if constexpr (normal) {
      HWY_ALIGN float totals[max_lanes];
      hn::Store(hn::Sub(weights.sum.v, weights.carry.v), df, totals);
      double total = 0.0;
      for (std::size_t l = 0; l < N; ++l) total += double(totals[l]);
      d = total + sky.monopole * 0.0;  // the forward's d without the float64 path (no monopole term)
      dv = hn::Set(dd, d);
    }
    for (std::size_t s = 0; s < count; ++s) AddStretch(in, stretches[s], stretches[s].staged ? staged_at : whole_at, outputs, dv);
    whole_fill = staged_fill = count = 0;
  };
  for (std::size_t r = 0; r < in.range_count; ++r) {
    const std::size_t end = in.ranges[2 * r + 1];
    const std::uint32_t offset = in.ring_offset[in.rings[r]];
    std::size_t p = in.ranges[2 * r];
    for (; p + N <= end; p += N) {
      if (whole_fill + N > chunk || count + 2 > max_stretches) flush();
      Stretch* last = count ? &stretches[count - 1] : nullptr;
      if (last && !last->staged && last->entry + last->count == std::uint32_t(p + offset) &&
          last->at + last->count == whole_fill)
        last->count += std::uint32_t(N);
      else
        stretches[count++] = {std::uint32_t(p + offset), std::uint32_t(whole_fill), std::uint32_t(N), 0};
      for (int c = 0; c < quantities; ++c) q[c] = hn::LoadU(df, unit[c] + p);
      evaluate(q, all, whole_at, whole_fill);
      whole_fill += N;
    }
    if (p == end) continue;
    // The rest: lanes [fill, fill + rest) of this staging vector and the next, which follow each other
    // in `staged`.
    if (staged_fill + 2 * N > chunk || count + 2 > max_stretches) flush();
    const std::size_t rest = end - p;
    stretches[count++] = {std::uint32_t(p + offset), std::uint32_t(staged_fill + fill), std::uint32_t(rest), 1};
    const RestStaging staging(fill);
    for (int c = 0; c < quantities; ++c) q[c] = staging.join(hn::LoadU(df, unit[c] + p), stage[c]);
    fill += rest;
    if (fill >= N) {
      evaluate(q, all, staged_at, staged_fill);
      staged_fill += N;
      fill -= N;
    } else {
      for (int c = 0; c < quantities; ++c) stage[c] = q[c];
    }
  }
  flush();
}
#else
// Scatter a pixel at a time.
template <bool Normal, class W>
HWY_INLINE void ScatterScalar(const KernelSky& sky, const ScatterInput& in, W& weights) {
  const DF df;
  double d = in.value;
  constexpr int outputs = W::outputs;
  constexpr bool normal = Normal;  // a template parameter: the adjoint's own code has none of it
  HWY_ALIGN float out[4][max_lanes];
  if constexpr (normal) {  // d first: the forward's sum of the disc, a pixel at a time
    const MF one = hn::FirstN(df, 1);
    for (std::size_t r = 0; r < in.range_count; ++r)
      for (std::size_t p = in.ranges[2 * r]; p < in.ranges[2 * r + 1]; ++p) {
        const VF S[4] = {hn::LoadU(df, sky.i + p), hn::LoadU(df, sky.q + p), hn::LoadU(df, sky.u + p),
                         hn::LoadU(df, sky.v + p)};
        weights(hn::LoadU(df, sky.kx + p), hn::LoadU(df, sky.ky + p), hn::LoadU(df, sky.kz + p), S, one);
      }
    HWY_ALIGN float totals[max_lanes];
    hn::Store(hn::Sub(weights.sum.v, weights.carry.v), df, totals);
    d = double(totals[0]) + sky.monopole * 0.0;
  }
  for (std::size_t r = 0; r < in.range_count; ++r) {
    const std::size_t begin = in.ranges[2 * r], end = in.ranges[2 * r + 1];
    for (std::size_t p = begin; p < end; ++p) {
      const Vec4<F> a = weights(hn::LoadU(df, sky.kx + p), hn::LoadU(df, sky.ky + p), hn::LoadU(df, sky.kz + p));
      hn::Store(a.x.v, df, out[0]);
      hn::Store(a.y.v, df, out[1]);
      hn::Store(a.z.v, df, out[2]);
      hn::Store(a.w.v, df, out[3]);
      for (int c = 0; c < outputs; ++c) {
        const double v = d * double(out[c][0]);
        in.maps[c][std::uint32_t(p + in.ring_offset[in.rings[r]])] += in.squares ? v * v : v;
      }
    }
  }
}
#endif

// The adjoint of one sample: the forward's float32 geometry and weights, stokes_adjoint, and d times
// each pixel's weights added to it in float64. In two passes over a chunk of the disc's pixels at a
// time: first the pixels are evaluated a whole vector at a time as the forward evaluates them, their
// float32 weights stored by column; then each range adds d times its stretch of those weights to its
// pixels, float64 vector by vector. A pixel's float32 weights do not depend on the lane that computes
// them, so the maps are the same bits however the ranges are cut.
// The normal pass (ScatterInput::normal): d is the forward's sum of the same pixels, summed here as
// Sample sums it (Kahan-compensated float32 lanes), from the sky's I - I0, Q, U (and V where a weight
// multiplies it).
template <bool Radial, int Columns, bool Plate, bool Normal>
HWY_NOINLINE HWY_FLATTEN void Scatter(const KernelSky& sky, const KernelDetector& det, const ScatterInput& in) {
  AdjointWeights<Radial, Columns, Plate> weights(det, in);
#if HWY_TARGET != HWY_SCALAR
  ScatterVectors<Normal>(sky, in, weights);
#else
  ScatterScalar<Normal>(sky, in, weights);
#endif
}

template <bool Radial, int Columns, bool Plate>
HWY_INLINE void ScatterPass(const KernelSky& sky, const KernelDetector& det, const ScatterInput& in) {
  if (in.normal)
    Scatter<Radial, Columns, Plate, true>(sky, det, in);
  else
    Scatter<Radial, Columns, Plate, false>(sky, det, in);
}

template <bool Radial, int Columns>
HWY_INLINE void ScatterPlate(const KernelSky& sky, const KernelDetector& det, const ScatterInput& in) {
  if (in.plate)
    ScatterPass<Radial, Columns, true>(sky, det, in);
  else
    ScatterPass<Radial, Columns, false>(sky, det, in);
}

void ScatterSample(const KernelSky& sky, const KernelDetector& det, const ScatterInput& in) {
  if (det.radial)
    det.columns == 4 ? ScatterPlate<true, 4>(sky, det, in) : ScatterPlate<true, 2>(sky, det, in);
  else
    det.columns == 4 ? ScatterPlate<false, 4>(sky, det, in) : ScatterPlate<false, 2>(sky, det, in);
}

const char* TargetHere() { return hwy::TargetName(HWY_TARGET); }
std::size_t LanesHere() { return hn::Lanes(DF()); }

}  // namespace HWY_NAMESPACE
}  // namespace pisco::detail::simd
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace pisco::detail::simd {

HWY_EXPORT(ConvolveSample);
HWY_EXPORT(ScatterSample);
HWY_EXPORT(TargetHere);
HWY_EXPORT(LanesHere);

namespace {
std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

constexpr std::size_t table_size = sizeof(HWY_DISPATCH_TABLE(ConvolveSample)) / sizeof(HWY_DISPATCH_TABLE(ConvolveSample)[0]);
}  // namespace

Kernel choose_kernel(const std::string& name) {
  const std::vector<std::int64_t> targets = hwy::SupportedAndGeneratedTargets();  // best first
  std::string available;
  for (const std::int64_t t : targets) available += (available.empty() ? "" : ", ") + std::string(hwy::TargetName(t));
  std::int64_t pick = 0;
  if (name.empty() || lower(name) == "auto") {
    if (!targets.empty()) pick = targets.front();
  } else {
    for (const std::int64_t t : targets)
      if (!pick && lower(hwy::TargetName(t)) == lower(name)) pick = t;
    if (!pick)
      throw Error("simd: no instruction set named '" + name + "' on this machine; available: " + available +
                  " (or auto)");
  }
  Kernel k;
  if (pick) {
    hwy::ChosenTarget chosen;  // this engine's own choice, not Highway's process-wide one
    chosen.Update(pick);
    k.index = chosen.GetIndex();
  }
  if (!pick || k.index >= table_size) {  // a build with a single target: its static dispatch
    k.index = table_size;
    k.description = std::string(hwy::TargetName(HWY_STATIC_TARGET)) + ", " +
                    std::to_string(HWY_STATIC_DISPATCH(LanesHere)()) + " float32 lanes";
    return k;
  }
  k.description = std::string(HWY_DISPATCH_TABLE(TargetHere)[k.index]()) + ", " +
                  std::to_string(HWY_DISPATCH_TABLE(LanesHere)[k.index]()) + " float32 lanes";
  return k;
}

void convolve_sample(const Kernel& kernel, const KernelSky& sky, const KernelDetector& det, const SampleInput& in,
                     SampleSums& out) {
  if (kernel.index < table_size)
    HWY_DISPATCH_TABLE(ConvolveSample)[kernel.index](sky, det, in, out);
  else
    HWY_STATIC_DISPATCH(ConvolveSample)(sky, det, in, out);
}

void scatter_sample(const Kernel& kernel, const KernelSky& sky, const KernelDetector& det, const ScatterInput& in) {
  if (kernel.index < table_size)
    HWY_DISPATCH_TABLE(ScatterSample)[kernel.index](sky, det, in);
  else
    HWY_STATIC_DISPATCH(ScatterSample)(sky, det, in);
}

}  // namespace pisco::detail::simd
#endif  // HWY_ONCE
