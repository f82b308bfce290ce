// Disc selection from a ring table (docs/physics.md, "Disc selection"): the RING pixels whose centres lie within rho of a
// pointing, the same set as HEALPix C++ query_disc(..., inclusive = false), produced as one or two
// contiguous index ranges per ring crossing the disc. The reference's, the simd and the CUDA kernels'
// walk; its arithmetic (the disc's rings, each ring's crossing and pixel ranges) is one text with the
// shaders' float64 walk (src/kernel/disc.glsl), src/kernel/rings.glsl. Double precision throughout: the result must be exact. Every product
// that feeds an addition is mul_rn (kernel/hd.hpp), rounded by itself on the device as on the host.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "kernel/fp64.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail {

struct RingEntry {
  double z;             // cos(theta) of the ring
  std::uint32_t first;  // first pixel index of the ring
  std::uint32_t count;  // pixels in the ring
  std::uint32_t shifted;  // 1 when pixel centres sit at phi = (j + 1/2) 2 pi / count
  std::uint32_t pad;
};

// A longitude wrapped into [0, 2 pi), as the disc selection expects phi0. One definition for the
// reference, the scan generators and the CUDA kernels.
PISCO_HD double wrap_phi(double phi) {
  const double twopi = 6.283185307179586476925286766559;
  double p = fmod(phi, twopi);
  if (p < 0) p += twopi;
  // fmod of a tiny negative number plus 2 pi rounds to 2 pi itself.
  if (p >= twopi) p = 0.0;
  return p;
}

// z of ring `ring` (1 ... 4 nside - 1), with HEALPix's own arithmetic so that boundary decisions agree.
PISCO_HD double ring_z(std::int64_t nside, std::int64_t ring) {
  const double fact2 = 4.0 / double(12 * nside * nside);
  const double fact1 = double(nside << 1) * fact2;
  if (ring < nside) return 1.0 - mul_rn(double(ring * ring), fact2);
  if (ring <= 3 * nside) return double(2 * nside - ring) * fact1;
  const std::int64_t r = 4 * nside - ring;
  return mul_rn(double(r * r), fact2) - 1.0;
}

// The float64 ring arithmetic and disc walk shared with the shaders (src/kernel/rings.glsl): ring_above,
// ring_edge_x, ring_edge_ysq, ring_bound, disc_ring_span, ring_half_width, ring_pixel_span and
// ring_pixel_ranges; mul_rn is kernel/hd.hpp's, and the trigonometry GLSL lacks the C library's
// (kernel/fp64.hpp).
constexpr double PISCO_PI = 3.141592653589793238462643383279502884;
#include "kernel/text_begin.hpp"
#define PISCO_RING_INT std::int64_t
#define PISCO_RING_TEMPLATE template <class T>
#define PISCO_RING_REAL T
using uint = unsigned int;
#include "kernel/rings.glsl"
#undef PISCO_RING_INT
#undef PISCO_RING_TEMPLATE
#undef PISCO_RING_REAL
#include "kernel/text_end.hpp"

// The table for all 4 nside - 1 rings; entry r - 1 describes ring r.
std::vector<RingEntry> make_ring_table(int nside);

// The rings a disc of radius rho around colatitude theta0 crosses, first ... last (1-based), and
// whether it holds a pole; z0 = cos(theta0) and xa = 1 / sin(theta0), as the ring bounds need them.
struct DiscRings {
  std::int64_t first, last;
  bool north, south;  // every ring north of `first` (south of `last`) lies wholly inside
  double z0, xa;
};

PISCO_HD DiscRings disc_rings(std::int64_t nside, double theta0, double rho) {
  DiscRings d;
  d.z0 = cos(theta0);
  d.xa = 1.0 / sqrt((1.0 - d.z0) * (1.0 + d.z0));
  disc_ring_span(nside, theta0, rho, d.first, d.last, d.north, d.south);
  return d;
}

// The same from the three cosines, disc_cos(theta0, rho, k) for k = 0, 1, 2, computed by the caller
// (the CUDA kernels take them on three lanes): the same bits.
PISCO_HD double disc_cos(double theta0, double rho, int k) {
  return pisco_cos(k == 0 ? theta0 : k == 1 ? theta0 - rho : theta0 + rho);
}
PISCO_HD DiscRings disc_rings_from_cos(std::int64_t nside, double theta0, double rho, double z0, double cos_north,
                                       double cos_south) {
  DiscRings d;
  d.z0 = z0;
  d.xa = 1.0 / sqrt((1.0 - d.z0) * (1.0 + d.z0));
  disc_ring_span_cos(nside, theta0, rho, cos_north, cos_south, d.first, d.last, d.north, d.south);
  return d;
}

// Where ring r crosses the disc's edge: x = cos(dphi) sin(theta_r) in the units of the ring's
// radius, and ysq = 1 - z^2 - x^2 (the ring does not cross the edge unless ysq > 0); the ring's
// half-width in longitude is then dphi = atan2(sqrt(ysq), x).
PISCO_HD void ring_edge(const RingEntry& r, const DiscRings& d, double cos_rho, double& x, double& ysq) {
  x = ring_edge_x(r.z, d.z0, d.xa, cos_rho);
  ysq = ring_edge_ysq(r.z, x);
}

// ring_bound's factors for a ring of the table (the simd disc walk's estimate, src/simd/simd_disc.cpp).
PISCO_HD double ring_pixels_per_radian(const RingEntry& r) { return ring_pixels_per_radian(uint(r.count)); }
PISCO_HD double ring_shift(const RingEntry& r) { return ring_shift(r.shifted != 0); }

// Emits ring r's pixels first ... last, indices taken modulo the ring (one range, or two where they
// wrap through phi = 0: ring_pixel_ranges); none when first > last.
template <class Emit>
PISCO_HD void emit_ring_pixels(const RingEntry& r, std::int64_t ip_lo, std::int64_t ip_hi, Emit&& emit) {
  uint b0, l0, b1, l1;
  const int ranges = ring_pixel_ranges(r.first, r.count, ip_lo, ip_hi, b0, l0, b1, l1);
  if (ranges > 0) emit(std::uint32_t(b0), std::uint32_t(b0 + l0));
  if (ranges > 1) emit(std::uint32_t(b1), std::uint32_t(b1 + l1));
}

// Emits the pixels of ring r within dphi = atan2(sqrt(ysq), x) of phi0 (ring_edge's x and ysq > 0),
// with the C library's arctangent.
template <class Emit>
PISCO_HD void emit_ring_crossing(const RingEntry& r, double phi0, double x, double ysq, Emit&& emit) {
  const double dphi = ring_half_width(x, ysq);
  if (!(dphi > 0)) return;
  std::int64_t lo, hi;
  ring_pixel_span(r.count, r.shifted != 0, phi0, dphi, lo, hi);
  emit_ring_pixels(r, lo, hi, emit);
}

// The polar caps of a disc that holds a pole: every ring north of d.first (south of d.last) whole.
template <class Emit>
PISCO_HD void emit_north_cap(const RingEntry* rings, const DiscRings& d, Emit&& emit) {
  if (!d.north) return;
  const RingEntry& r = rings[d.first - 2];
  emit(std::uint32_t(0), r.first + r.count);
}
template <class Emit>
PISCO_HD void emit_south_cap(const RingEntry* rings, std::int64_t nside, const DiscRings& d, Emit&& emit) {
  if (!d.south) return;
  const RingEntry& r = rings[d.last];
  emit(r.first, std::uint32_t(12 * nside * nside));
}

// Calls emit(begin, end) for each range [begin, end) of pixels in the disc of radius rho around
// (theta0, phi0); cos_rho = cos(rho). rho must be in (0, pi/2].
template <class Emit>
PISCO_HD void for_each_disc_range(const RingEntry* rings, std::int64_t nside, double theta0,
                                  double phi0, double rho, double cos_rho, Emit&& emit) {
  const DiscRings d = disc_rings(nside, theta0, rho);
  emit_north_cap(rings, d, emit);
  for (std::int64_t iz = d.first; iz <= d.last; ++iz) {
    const RingEntry& r = rings[iz - 1];
    double x, ysq;
    ring_edge(r, d, cos_rho, x, ysq);
    if (ysq <= 0) continue;  // the ring does not cross the disc boundary
    emit_ring_crossing(r, phi0, x, ysq, emit);
  }
  emit_south_cap(rings, nside, d, emit);
}

}  // namespace pisco::detail
