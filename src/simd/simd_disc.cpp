// The simd backend's disc walk (docs/simd.md, "The disc walk"): the reference's disc ranges with the
// rings' arctangents taken in vectors of doubles. A translation unit of its own, compiled as the rest
// of the project, floating-point expressions as written: the ring edges must be the reference's bit
// for bit, where the kernel's file lets the compiler fuse multiply-adds (src/simd/simd.cmake).
#include "simd/targets.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "simd/simd_disc.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>
#include <hwy/contrib/math/math-inl.h>

#include <algorithm>
#include <vector>

#include "simd/simd_kernel.hpp"

#ifndef PISCO_SIMD_DISC_RANGE_WRITER  // once, not once per target
#define PISCO_SIMD_DISC_RANGE_WRITER
namespace pisco::detail::simd {
namespace {
// Writes non-empty ranges through a pointer. Defined outside the targets' namespaces, with no target
// attribute, as kernel/disc.hpp's emitters that call it: GCC inlines a function only into one whose
// instruction set includes its own, so a lambda of the walk (AVX-512, say) would be called out of
// line, vectors saved around each call.
struct RangeWriter {
  std::uint32_t* w;
  void operator()(std::uint32_t b, std::uint32_t e) {
    if (e <= b) return;
    w[0] = b;
    w[1] = e;
    w += 2;
  }
};
}  // namespace
}  // namespace pisco::detail::simd
#endif

HWY_BEFORE_NAMESPACE();
namespace pisco::detail::simd {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// The ring edges' arithmetic, kernel/rings.glsl's, on float64 lanes: the text again in this target's
// namespace, its ring_edge_x and ring_edge_ysq with T = D (float64_lanes-inl.h).
#include "simd/float64_lanes-inl.h"
#include "kernel/text_begin.hpp"
#define PISCO_RING_INT std::int64_t
#define PISCO_RING_TEMPLATE template <class T>
#define PISCO_RING_REAL T
#include "kernel/rings.glsl"
#undef PISCO_RING_INT
#undef PISCO_RING_TEMPLATE
#undef PISCO_RING_REAL
#include "kernel/text_end.hpp"

// The disc's pixel ranges, exactly for_each_disc_range's (kernel/disc.hpp), with the arctangent of
// each ring's half-width taken a vector of rings at a time. The reference computes
// floor(arg(phi0 -+ dphi)) with dphi = atan2(sqrt(ysq), x), the C library's arctangent, some 30 ns a
// ring: a third of this backend's time at rho_max = 5 deg. Here x and ysq are the reference's
// (rings.glsl's ring_edge_x and ring_edge_ysq on vectors of rings), the square root is IEEE's in both, and the arctangent is Highway's (within 3
// ulp), so the vector's dphi is within 1e-15 rad of the reference's; a bound is taken from it only
// when floor() gives the same integer anywhere within a margin (count / 2 pi x 1e-12 + 1e-9) of the
// argument, far wider than that error and than the arithmetic's rounding. A ring where either bound
// falls within its margin of an integer (about 1e-9 of rings) is done again with the reference's own
// arithmetic: the ranges are the reference's, bit for bit.
std::size_t DiscRanges(const RingEntry* rings, const RingColumns* columns, std::int64_t nside, double theta0,
                       double phi0, double rho, double cos_rho, std::vector<std::uint32_t>& ranges,
                       std::size_t* redone, double margin_abs) {
  const DD dd;  // float64_lanes-inl.h's lanes
  using VD = hn::Vec<DD>;
  const std::size_t lanes = hn::Lanes(dd);
  const double pi = 3.141592653589793238462643383279502884;
  const DiscRings d = disc_rings(nside, theta0, rho);
  // At most two ranges a ring and one a polar cap, written through a pointer (the ranges are most of
  // what the walk writes; a growing vector's checks cost more than the writes).
  const std::size_t most = 4 * std::size_t(std::max<std::int64_t>(0, d.last - d.first + 1)) + 4;
  if (ranges.size() < most) ranges.resize(std::max(most, 2 * ranges.size()));
  std::uint32_t* const out = ranges.data();
  RangeWriter emit{out};
  emit_north_cap(rings, d, emit);
  // Rings a block at a time: the block's vectors (independent of one another: the processor overlaps
  // their long square-root, division and polynomial chains), then the ranges. Each ring's edge x,
  // ysq is the reference's text itself (correctly rounded in a vector lane as in a scalar register,
  // no operation fused: simd.cmake), from the columns' z; lanes past the disc's
  // last ring read the columns' padding and are not used.
  constexpr std::size_t block = 64;
  static_assert(block % (HWY_MAX_BYTES / sizeof(double)) == 0, "whole vectors of doubles per block");
  static_assert(RingColumns::pad >= HWY_MAX_BYTES / sizeof(double), "a vector of rings past the last");
  HWY_ALIGN double x[block], ysq[block], lo[block], hi[block], ok[block];
  const VD zero = hn::Zero(dd), half_pi = hn::Set(dd, 0.5 * pi), pi_v = hn::Set(dd, pi);
  const VD phi_v = hn::Set(dd, phi0), rel = hn::Set(dd, 1e-12), abs_margin = hn::Set(dd, margin_abs);
  const VD one = hn::Set(dd, 1.0), tiny = hn::Set(dd, 1e-300);
  const D z0(d.z0), xa(d.xa), cr(cos_rho);
  for (std::int64_t first = d.first; first <= d.last; first += std::int64_t(block)) {
    const std::size_t n = std::size_t(std::min<std::int64_t>(std::int64_t(block), d.last - first + 1));
    const std::size_t padded = (n + lanes - 1) / lanes * lanes;
    const std::size_t at = std::size_t(first - 1);  // ring `first`'s entry
    for (std::size_t v = 0; v < padded; v += lanes) {
      const D z = D(hn::LoadU(dd, columns->z.data() + at + v));
      // ring_edge's x = (cos_rho - z z0) xa and ysq = 1 - z^2 - x^2, the shared text.
      const D edge_x = ring_edge_x(z, z0, xa, cr);
      const VD xv = edge_x.v, ysq_v = ring_edge_ysq(z, edge_x).v;
      hn::Store(xv, dd, x + v);
      hn::Store(ysq_v, dd, ysq + v);
      const VD s = hn::Sqrt(hn::Max(ysq_v, zero));
      const VD ax = hn::Abs(xv);
      // atan2(s, x) for s >= 0 from the arctangent of a ratio within [0, 1].
      const auto steep = hn::Lt(ax, s);
      const VD num = hn::IfThenElse(steep, ax, s), den = hn::IfThenElse(steep, s, ax);
      VD a = hn::Atan(dd, hn::Div(num, hn::Max(den, tiny)));
      a = hn::IfThenElse(steep, hn::Sub(half_pi, a), a);
      const VD dphi = hn::IfThenElse(hn::Lt(xv, zero), hn::Sub(pi_v, a), a);
      const VD t = hn::LoadU(dd, columns->scale.data() + at + v), sh = hn::LoadU(dd, columns->shift.data() + at + v);
      const VD margin = hn::Add(hn::Mul(t, rel), abs_margin);
      const VD arg_lo = hn::Sub(hn::Mul(t, hn::Sub(phi_v, dphi)), sh);
      const VD arg_hi = hn::Sub(hn::Mul(t, hn::Add(phi_v, dphi)), sh);
      const VD f_lo = hn::Floor(hn::Sub(arg_lo, margin)), f_hi = hn::Floor(hn::Sub(arg_hi, margin));
      const auto sure = hn::And(hn::Eq(f_lo, hn::Floor(hn::Add(arg_lo, margin))),
                                hn::Eq(f_hi, hn::Floor(hn::Add(arg_hi, margin))));
      hn::Store(f_lo, dd, lo + v);
      hn::Store(f_hi, dd, hi + v);
      hn::Store(hn::IfThenElseZero(sure, one), dd, ok + v);
    }
    for (std::size_t l = 0; l < n; ++l) {
      if (ysq[l] <= 0) continue;  // the ring does not cross the disc boundary
      const RingEntry& r = rings[first + std::int64_t(l) - 1];
      if (ok[l] == 1.0) {
        emit_ring_pixels(r, std::int64_t(lo[l]) + 1, std::int64_t(hi[l]), emit);
        continue;
      }
      if (redone) ++*redone;
      emit_ring_crossing(r, phi0, x[l], ysq[l], emit);
    }
  }
  emit_south_cap(rings, nside, d, emit);
  return std::size_t(emit.w - out);
}

}  // namespace HWY_NAMESPACE
}  // namespace pisco::detail::simd
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace pisco::detail::simd {

HWY_EXPORT(DiscRanges);

RingColumns::RingColumns(const std::vector<RingEntry>& rings)
    : z(rings.size() + pad, 0.0), scale(rings.size() + pad, 0.0), shift(rings.size() + pad, 0.0) {
  for (std::size_t i = 0; i < rings.size(); ++i) {
    z[i] = rings[i].z;
    scale[i] = ring_pixels_per_radian(rings[i]);
    shift[i] = ring_shift(rings[i]);
  }
}

std::size_t disc_ranges(const Kernel& kernel, const RingEntry* rings, const RingColumns& columns, std::int64_t nside,
                        double theta0, double phi0, double rho, double cos_rho, std::vector<std::uint32_t>& ranges,
                        std::size_t* redone, double margin) {
  constexpr std::size_t table_size = sizeof(HWY_DISPATCH_TABLE(DiscRanges)) / sizeof(HWY_DISPATCH_TABLE(DiscRanges)[0]);
  if (kernel.index < table_size)
    return HWY_DISPATCH_TABLE(DiscRanges)[kernel.index](rings, &columns, nside, theta0, phi0, rho, cos_rho, ranges,
                                                        redone, margin);
  return HWY_STATIC_DISPATCH(DiscRanges)(rings, &columns, nside, theta0, phi0, rho, cos_rho, ranges, redone, margin);
}

}  // namespace pisco::detail::simd
#endif  // HWY_ONCE
