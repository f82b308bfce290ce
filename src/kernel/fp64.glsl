// float64 sine, cosine and arctangent for the kernels: GLSL has no double-precision transcendental
// functions. The disc selection (disc.glsl) must reproduce the reference's double arithmetic
// (src/kernel/disc.hpp) to the last bits, so these follow fdlibm's algorithms and coefficients:
// Cody-Waite reduction by pi/2 (valid for |x| < 2^19) and minimax polynomials on [-pi/4, pi/4];
// atan by argument reduction to |x| < 7/16 with the tabulated atan(0.5), atan(1), atan(1.5).
// Within 1 ulp of the C library (tests/test_fp64.cpp runs this same file as C++).
// Written in the common subset of GLSL and C++ (tests/test_fp64.cpp compiles it as C++ once the build
// has stripped the `lf` suffixes): every constant is suffixed, since an unsuffixed GLSL literal is
// single precision, even beside a double.
#ifndef PISCO_FP64_GLSL
#define PISCO_FP64_GLSL

#include "common.glsl"

// sin(r) and cos(r) for |r| <= pi/4 (fdlibm __kernel_sin, __kernel_cos).
PISCO_FN double pisco_kernel_sin(double r) {
  const double S1 = -1.66666666666666324348e-01lf;
  const double S2 = 8.33333333332248946124e-03lf;
  const double S3 = -1.98412698298579493134e-04lf;
  const double S4 = 2.75573137070700676789e-06lf;
  const double S5 = -2.50507602534068634195e-08lf;
  const double S6 = 1.58969099521155010221e-10lf;
  const double z = r * r;
  const double v = z * r;
  const double p = S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)));
  return r + v * (S1 + z * p);
}

PISCO_FN double pisco_kernel_cos(double r) {
  const double C1 = 4.16666666666666019037e-02lf;
  const double C2 = -1.38888888888741095749e-03lf;
  const double C3 = 2.48015872894767294178e-05lf;
  const double C4 = -2.75573143513906633035e-07lf;
  const double C5 = 2.08757232129817482790e-09lf;
  const double C6 = -1.13596475577881948265e-11lf;
  const double z = r * r;
  const double p = C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6))));
  const double hz = 0.5lf * z;
  const double w = 1.0lf - hz;
  return w + (((1.0lf - w) - hz) + z * z * p);
}

// x = n pi/2 + r, |r| <= pi/4; returns r; q = n mod 4.
PISCO_FN double pisco_reduce(double x, PISCO_OUT(int) q) {
  const double invpio2 = 6.36619772367581382433e-01lf;
  const double pio2_1 = 1.57079632673412561417e+00lf;   // first 33 bits of pi/2
  const double pio2_1t = 6.07710050650619224932e-11lf;  // pi/2 - pio2_1
  const double fn = floor(x * invpio2 + 0.5lf);
  q = int(fn - 4.0lf * floor(fn * 0.25lf));
  return (x - fn * pio2_1) - fn * pio2_1t;
}

PISCO_FN double pisco_sin(double x) {
  int q;
  const double r = pisco_reduce(x, q);
  if (q == 0) return pisco_kernel_sin(r);
  if (q == 1) return pisco_kernel_cos(r);
  if (q == 2) return -pisco_kernel_sin(r);
  return -pisco_kernel_cos(r);
}

PISCO_FN double pisco_cos(double x) {
  int q;
  const double r = pisco_reduce(x, q);
  if (q == 0) return pisco_kernel_cos(r);
  if (q == 1) return -pisco_kernel_sin(r);
  if (q == 2) return -pisco_kernel_cos(r);
  return pisco_kernel_sin(r);
}

// atan(x) for x >= 0 (fdlibm s_atan.c).
PISCO_FN double pisco_atan_nonneg(double x) {
  const double aT0 = 3.33333333333329318027e-01lf, aT1 = -1.99999999998764832476e-01lf;
  const double aT2 = 1.42857142725034663711e-01lf, aT3 = -1.11111104054623557880e-01lf;
  const double aT4 = 9.09088713343650656196e-02lf, aT5 = -7.69187620504482999495e-02lf;
  const double aT6 = 6.66107313738753120669e-02lf, aT7 = -5.83357013379057348645e-02lf;
  const double aT8 = 4.97687799461593236017e-02lf, aT9 = -3.65315727442169155270e-02lf;
  const double aT10 = 1.62858201153657823623e-02lf;
  double hi = 0.0lf, lo = 0.0lf;
  int id = -1;
  if (x >= 0.4375lf) {
    if (x < 0.6875lf) {
      id = 0; hi = 4.63647609000806093515e-01lf; lo = 2.26987774529616870924e-17lf;
      x = (2.0lf * x - 1.0lf) / (2.0lf + x);
    } else if (x < 1.1875lf) {
      id = 1; hi = 7.85398163397448278999e-01lf; lo = 3.06161699786838301793e-17lf;
      x = (x - 1.0lf) / (x + 1.0lf);
    } else if (x < 2.4375lf) {
      id = 2; hi = 9.82793723247329054082e-01lf; lo = 1.39033110312309984516e-17lf;
      x = (x - 1.5lf) / (1.0lf + 1.5lf * x);
    } else {
      id = 3; hi = 1.57079632679489655800e+00lf; lo = 6.12323399573676603587e-17lf;
      x = -1.0lf / x;
    }
  }
  const double z = x * x;
  const double w = z * z;
  const double s1 = z * (aT0 + w * (aT2 + w * (aT4 + w * (aT6 + w * (aT8 + w * aT10)))));
  const double s2 = w * (aT1 + w * (aT3 + w * (aT5 + w * (aT7 + w * aT9))));
  if (id < 0) return x - x * (s1 + s2);
  return hi - ((x * (s1 + s2) - lo) - x);
}

// atan2(y, x) for y >= 0 (fdlibm e_atan2.c): the angle in [0, pi].
PISCO_FN double pisco_atan2_nonneg_y(double y, double x) {
  const double pi = 3.1415926535897931160e+00lf;
  const double pi_lo = 1.2246467991473531772e-16lf;
  if (x == 0.0lf) return y == 0.0lf ? 0.0lf : 1.57079632679489655800e+00lf;
  if (x > 0.0lf) return pisco_atan_nonneg(y / x);
  return pi - (pisco_atan_nonneg(y / -x) - pi_lo);
}

#endif
