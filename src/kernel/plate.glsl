// A half-wave plate's Mueller matrix at an angle and the monopole's weight behind it (docs/physics.md,
// "Half-wave plates"), written once, in the common subset of GLSL and C++ (common.glsl), for every
// backend:
// - kernel.glsl includes it as GLSL, in float64 (REAL double) or, built for devices without float64
//   (PISCO_FF), in float32 (the float-float kernel then keeps M(theta)'s column 0 in float-float);
// - src/kernel/contribution-inl.hpp includes it as C++ templates of the number type T: src/kernel/plate.hpp's
//   plate_at (pisco::rotated_mueller, the float64 reference, the simd and CUDA kernels) with T = double,
//   and the simd backend's float64 sums with T a vector of float64 lanes.
#if defined(PISCO_TEMPLATE_TEXT) || !defined(PISCO_PLATE_GLSL)
#ifndef PISCO_TEMPLATE_TEXT
#define PISCO_PLATE_GLSL
#include "common.glsl"

#define PISCO_PLATE_TEMPLATE
#if PISCO_FF
#define PISCO_PLATE_REAL float
#define PISCO_PLATE_V4 vec4
#else
#define PISCO_PLATE_REAL double
#define PISCO_PLATE_V4 dvec4
#endif
#define PISCO_PLATE_VEC4(a, b, c, d) PISCO_PLATE_V4(a, b, c, d)
#endif

// Row r of M0 R(theta), c = cos 2 theta, s = sin 2 theta: R(theta) has rows (1,0,0,0), (0,c,s,0),
// (0,-s,c,0), (0,0,0,1), so columns 1 and 2 mix.
PISCO_PLATE_TEMPLATE
PISCO_FN PISCO_PLATE_V4 plate_turn_row(PISCO_PLATE_V4 r, PISCO_PLATE_REAL c, PISCO_PLATE_REAL s) {
  return PISCO_PLATE_VEC4(r.x, c * r.y - s * r.z, s * r.y + c * r.z, r.w);
}

// The rows m0 ... m3 of M(theta) = R(-theta) M0 R(theta) from M0's rows r0 ... r3: of M0 R(theta),
// rows 1 and 2 mix. Column 0, (m0.x, m1.x, m2.x, m3.x), weighs the monopole (plate_monopole_weight).
PISCO_PLATE_TEMPLATE
PISCO_FN void plate_rows(PISCO_PLATE_V4 r0, PISCO_PLATE_V4 r1, PISCO_PLATE_V4 r2, PISCO_PLATE_V4 r3,
                         PISCO_PLATE_REAL c, PISCO_PLATE_REAL s, PISCO_OUT(PISCO_PLATE_V4) m0,
                         PISCO_OUT(PISCO_PLATE_V4) m1, PISCO_OUT(PISCO_PLATE_V4) m2, PISCO_OUT(PISCO_PLATE_V4) m3) {
  const PISCO_PLATE_V4 a1 = plate_turn_row(r1, c, s);
  const PISCO_PLATE_V4 a2 = plate_turn_row(r2, c, s);
  m0 = plate_turn_row(r0, c, s);
  m1 = c * a1 - s * a2;
  m2 = s * a1 + c * a2;
  m3 = plate_turn_row(r3, c, s);
}

// A pixel's weight in the monopole's sum behind the plate, sum_a w_a M_a0: the sky's monopole, I0
// alone, reaches the detector through M(theta)'s column 0 (col0), w the pixel's float64 weights
// (w_I, w_Q, w_U, w_V).
PISCO_PLATE_TEMPLATE
PISCO_FN PISCO_PLATE_REAL plate_monopole_weight(PISCO_PLATE_V4 w, PISCO_PLATE_V4 col0) {
  return w.x * col0.x + w.y * col0.y + w.z * col0.z + w.w * col0.w;
}

#endif
