// The float64 ring arithmetic of the disc selection (docs/physics.md, "Disc selection"), written once
// in the common subset of GLSL and C++: the shaders include it from disc.glsl, src/kernel/disc.hpp
// includes it as C++ for the reference, the simd disc walk and the CUDA kernels, and
// tests/test_kernel_host.cpp runs both builds on every ring of many NSIDE and requires the same bits.
// The disc must be HEALPix query_disc's pixel set exactly, so every product that feeds an addition
// goes through mul_rn, rounded by itself: `precise` in GLSL, __dmul_rn on CUDA devices, and on the host
// a product the compiler may not fuse (tests/test_kernel_host.cpp builds this file with contraction
// on to prove that nothing here depends on -ffp-contract=off). No `lf` literal: doubles are written
// double(n) or double(m.5f), exact in both languages. The includer defines PISCO_PI (float64) and the
// float64 functions GLSL lacks: pisco_cos and pisco_atan2_nonneg_y (fp64.glsl in the shaders, the C
// library's cos and atan2 in C++).
#if defined(PISCO_TEMPLATE_TEXT) || !defined(PISCO_RINGS_GLSL)
#ifndef PISCO_TEMPLATE_TEXT
#define PISCO_RINGS_GLSL
#include "common.glsl"
#define PISCO_RING_INT int
#define PISCO_RING_TEMPLATE
#define PISCO_RING_REAL double

#ifndef __cplusplus
// A float64 product rounded by itself, never fused with the addition or subtraction it feeds (the
// GLSL-as-C++ host build has its own, in common.glsl).
double mul_rn(double a, double b) {
  precise const double r = a * b;
  return r;
}
#endif
#endif

// HEALPix's ring_above: the index of the ring just north of z (0 when z is north of ring 1).
PISCO_FN PISCO_RING_INT ring_above(PISCO_RING_INT nside, double z) {
  const double az = z < double(0) ? -z : z;
  if (az <= double(2) / double(3)) return PISCO_RING_INT(double(nside) * (double(2) - mul_rn(double(1.5f), z)));
  const PISCO_RING_INT iring = PISCO_RING_INT(double(nside) * sqrt(double(3) * (double(1) - az)));
  return (z > double(0)) ? iring : 4 * nside - iring - 1;
}

// Where the ring at z crosses the edge of the disc of cos_rho around colatitude theta0 (z0 =
// cos theta0, xa = 1 / sin theta0): x = cos(dphi) sin(theta_ring) in the units of the ring's radius,
// and ysq = 1 - z^2 - x^2 (the ring crosses the edge only where ysq > 0; its half-width in longitude
// is then atan2(sqrt(ysq), x)).
// Templates of the number type in C++ (PISCO_RING_TEMPLATE, PISCO_RING_REAL): double, or the simd disc
// walk's vectors of float64 lanes, a vector of rings at a time (src/simd/simd_disc.cpp).
PISCO_RING_TEMPLATE
PISCO_FN PISCO_RING_REAL ring_edge_x(PISCO_RING_REAL z, PISCO_RING_REAL z0, PISCO_RING_REAL xa, PISCO_RING_REAL cos_rho) {
  return (cos_rho - mul_rn(z, z0)) * xa;
}
PISCO_RING_TEMPLATE
PISCO_FN PISCO_RING_REAL ring_edge_ysq(PISCO_RING_REAL z, PISCO_RING_REAL x) {
  return PISCO_RING_REAL(1) - mul_rn(z, z) - mul_rn(x, x);
}

// The argument whose floor bounds a ring's pixel indices at longitude phi: floor(arg(phi0 - dphi)) + 1
// is the first pixel inside, floor(arg(phi0 + dphi)) the last; a ring of `count` pixels whose centres
// sit at phi = (j + 1/2) 2 pi / count when `shifted`; its factors, the ring's pixels per radian and
// the offset of its pixel centres in pixels, also serve the simd disc walk's estimate
// (src/simd/simd_disc.cpp), which ring_bound settles.
PISCO_FN double ring_pixels_per_radian(uint count) { return double(count) * (double(0.5f) / PISCO_PI); }
PISCO_FN double ring_shift(bool shifted) { return shifted ? double(0.5f) : double(0); }
PISCO_FN double ring_bound(uint count, bool shifted, double phi) {
  return mul_rn(ring_pixels_per_radian(count), phi) - ring_shift(shifted);
}

// The rings of the disc of radius rho around colatitude theta0, HEALPix query_disc's: first ... last
// (1-based; first > last when none), and whether the disc holds the north (south) pole, in which case
// every ring north of `first` (south of `last`) lies wholly inside it: disc_ring_span, and
// disc_ring_span_cos with cos(theta0 - rho) and cos(theta0 + rho) from the caller (the CUDA kernels take
// them on lanes of their own).
PISCO_FN void disc_ring_span_cos(PISCO_RING_INT nside, double theta0, double rho, double cos_north, double cos_south,
                                 PISCO_OUT(PISCO_RING_INT) first, PISCO_OUT(PISCO_RING_INT) last, PISCO_OUT(bool) north,
                                 PISCO_OUT(bool) south) {
  const PISCO_RING_INT nrings = 4 * nside - 1;
  first = ring_above(nside, cos_north) + 1;
  north = theta0 - rho <= double(0) && first > 1;
  last = ring_above(nside, cos_south);
  if (last > nrings) last = nrings;
  if (first < 1) first = 1;
  south = theta0 + rho >= PISCO_PI && last + 1 < 4 * nside;
}
PISCO_FN void disc_ring_span(PISCO_RING_INT nside, double theta0, double rho, PISCO_OUT(PISCO_RING_INT) first,
                             PISCO_OUT(PISCO_RING_INT) last, PISCO_OUT(bool) north, PISCO_OUT(bool) south) {
  disc_ring_span_cos(nside, theta0, rho, pisco_cos(theta0 - rho), pisco_cos(theta0 + rho), first, last, north, south);
}

// A ring's half-width in longitude within the disc, dphi = atan2(sqrt(ysq), x), from where it crosses
// the disc's edge (ring_edge_x's x and ring_edge_ysq's ysq > 0); the ring has no pixel inside unless
// dphi > 0.
PISCO_FN double ring_half_width(double x, double ysq) { return pisco_atan2_nonneg_y(sqrt(ysq), x); }

// The pixels of a ring (count, shifted) within dphi of phi0: indices lo ... hi, which may run past the
// ring's ends (ring_pixel_ranges takes them modulo the ring).
PISCO_FN void ring_pixel_span(uint count, bool shifted, double phi0, double dphi, PISCO_OUT(PISCO_RING_INT) lo,
                              PISCO_OUT(PISCO_RING_INT) hi) {
  lo = PISCO_RING_INT(floor(ring_bound(count, shifted, phi0 - dphi))) + 1;
  hi = PISCO_RING_INT(floor(ring_bound(count, shifted, phi0 + dphi)));
}

// Pixels lo ... hi of the ring whose `count` pixels start at `first`, taken modulo the ring: the ranges
// [b0, b0 + l0) and [b1, b1 + l1), one, or two where they wrap through phi = 0 (then [first, ...)
// comes first). Returns how many (0 when lo > hi; lengths 0 where absent).
PISCO_FN int ring_pixel_ranges(uint first, uint count, PISCO_RING_INT lo, PISCO_RING_INT hi, PISCO_OUT(uint) b0,
                               PISCO_OUT(uint) l0, PISCO_OUT(uint) b1, PISCO_OUT(uint) l1) {
  b0 = 0u;
  l0 = 0u;
  b1 = 0u;
  l1 = 0u;
  if (lo > hi) return 0;
  const PISCO_RING_INT nr = PISCO_RING_INT(count);
  if (hi >= nr) {
    lo -= nr;
    hi -= nr;
  }
  if (lo < 0) {
    b0 = first;
    l0 = uint(hi + 1);
    b1 = first + uint(lo + nr);
    l1 = uint(-lo);
    return 2;
  }
  b0 = first + uint(lo);
  l0 = uint(hi - lo + 1);
  return 1;
}

#endif
