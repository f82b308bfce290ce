// The float64 ring arithmetic of the disc selection (docs/physics.md, "Disc selection"), written once
// in the common subset of GLSL and C++: the shaders include it from disc.glsl, src/kernel/disc.hpp
// includes it as C++ for the reference, the simd disc walk and the CUDA kernels, and
// tests/test_kernel_host.cpp runs both builds on every ring of many NSIDE and requires the same bits.
// The disc must be HEALPix query_disc's pixel set exactly, so every product that feeds an addition
// goes through mul_rn, rounded by itself: `precise` in GLSL, __dmul_rn on CUDA devices, and on the host
// a product the compiler may not fuse (tests/test_kernel_host.cpp builds this file with contraction
// on to prove that nothing here depends on -ffp-contract=off). No `lf` literal: doubles are written
// double(n) or double(m.5f), exact in both languages. The includer defines PISCO_PI (float64).
#if defined(PISCO_TEMPLATE_TEXT) || !defined(PISCO_RINGS_GLSL)
#ifndef PISCO_TEMPLATE_TEXT
#define PISCO_RINGS_GLSL
#include "common.glsl"
#define PISCO_RING_INT int

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
PISCO_FN double ring_edge_x(double z, double z0, double xa, double cos_rho) { return (cos_rho - mul_rn(z, z0)) * xa; }
PISCO_FN double ring_edge_ysq(double z, double x) { return double(1) - mul_rn(z, z) - mul_rn(x, x); }

// The argument whose floor bounds a ring's pixel indices at longitude phi: floor(arg(phi0 - dphi)) + 1
// is the first pixel inside, floor(arg(phi0 + dphi)) the last; a ring of `count` pixels whose centres
// sit at phi = (j + 1/2) 2 pi / count when `shifted`.
PISCO_FN double ring_bound(uint count, bool shifted, double phi) {
  const double pixels_per_radian = double(count) * (double(0.5f) / PISCO_PI);
  return mul_rn(pixels_per_radian, phi) - (shifted ? double(0.5f) : double(0));
}

#endif
