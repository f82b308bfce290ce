// One sample's antenna basis in float64, from boresight angles or a boresight quaternion, with the
// detector's offset applied (docs/physics.md, "Pointing as a rotation"), written once in the common
// subset of GLSL and C++: the shaders include it, and src/kernel/frame.hpp includes its float64 part as
// C++ (PISCO_TEMPLATE_TEXT, with the C library's sine, cosine and arctangent) for the float64
// reference, the simd backend's frames and the CUDA kernels; tests/test_frame.cpp runs the shader
// build (its own sine, cosine and arctangent, fp64.glsl) against it. Without float64 (PISCO_FF), the
// same from a boresight quaternion in float-float (the host turns angles into quaternions for that
// path). The includer of the template text defines PISCO_D3, PISCO_D4 (vector and quaternion types
// with x, y, z(, w)), PISCO_DVEC3, PISCO_DVEC4 (their constructors), PISCO_COS, PISCO_SIN and
// PISCO_ATAN2_NONNEG_Y (atan2 for y >= 0) and PISCO_TWO_PI (2 pi in float64). No `lf` literal:
// doubles are written double(n), exact in both languages.
#if defined(PISCO_TEMPLATE_TEXT) || !defined(PISCO_FRAME_GLSL)
#ifndef PISCO_TEMPLATE_TEXT
#define PISCO_FRAME_GLSL

#include "common.glsl"

#if !PISCO_FF
#include "fp64.glsl"
#define PISCO_D3 dvec3
#define PISCO_D4 dvec4
#define PISCO_DVEC3(a, b, c) dvec3(a, b, c)
#define PISCO_DVEC4(a, b, c, d) dvec4(a, b, c, d)
#define PISCO_COS pisco_cos
#define PISCO_SIN pisco_sin
#define PISCO_ATAN2_NONNEG_Y pisco_atan2_nonneg_y
#define PISCO_TWO_PI 6.283185307179586476925286766559lf
#endif
#endif

#if defined(PISCO_TEMPLATE_TEXT) || !PISCO_FF

// q a b: the rotation b, then a (quaternions as (x, y, z, w), scalar last).
PISCO_FN PISCO_D4 pisco_quat_mul(PISCO_D4 a, PISCO_D4 b) {
  return PISCO_DVEC4(a.w * b.x + b.w * a.x + (a.y * b.z - a.z * b.y), a.w * b.y + b.w * a.y + (a.z * b.x - a.x * b.z),
                     a.w * b.z + b.w * a.z + (a.x * b.y - a.y * b.x), a.w * b.w - (a.x * b.x + a.y * b.y + a.z * b.z));
}

// The columns of q's rotation matrix, q x^ q*, q y^ q*, q z^ q*. With s = 2 / |q|^2 the matrix is
// orthonormal for any non-zero q, so a quaternion a few ulp off the unit sphere needs no
// renormalization (and a unit one gets exactly the textbook matrix).
PISCO_FN void pisco_rotation(PISCO_D4 q, PISCO_OUT(PISCO_D3) ex, PISCO_OUT(PISCO_D3) ey, PISCO_OUT(PISCO_D3) ez) {
  const double s = double(2) / (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  const double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
  const double xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  const double wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  ex = PISCO_DVEC3(double(1) - s * (yy + zz), s * (xy + wz), s * (xz - wy));
  ey = PISCO_DVEC3(s * (xy - wz), double(1) - s * (xx + zz), s * (yz + wx));
  ez = PISCO_DVEC3(s * (xz + wy), s * (yz - wx), double(1) - s * (xx + yy));
}

// c's components taken in the basis (a, b, p): c.x a + c.y b + c.z p.
PISCO_FN PISCO_D3 pisco_in_basis(PISCO_D3 c, PISCO_D3 a, PISCO_D3 b, PISCO_D3 p) {
  return PISCO_DVEC3(c.x * a.x + c.y * b.x + c.z * p.x, c.x * a.y + c.y * b.y + c.z * p.y,
                     c.x * a.z + c.y * b.z + c.z * p.z);
}

// theta in [0, pi] (k = 0) or phi in [0, 2 pi) (k = 1) of the unit vector p, each through one
// arctangent of the same function (the CUDA kernels take the two on two lanes at once), and both.
PISCO_FN double pisco_direction_angle(PISCO_D3 p, int k) {
  const double twopi = PISCO_TWO_PI;
  const double y = k == 0 ? sqrt(p.x * p.x + p.y * p.y) : (p.y >= double(0) ? p.y : -p.y);
  const double a = PISCO_ATAN2_NONNEG_Y(y, k == 0 ? p.z : p.x);
  if (k == 0) return a;
  const double phi = p.y >= double(0) ? a : twopi - a;
  return phi >= twopi ? double(0) : phi;
}
PISCO_FN void pisco_direction_angles(PISCO_D3 p, PISCO_OUT(double) theta, PISCO_OUT(double) phi) {
  theta = pisco_direction_angle(p, 0);
  phi = pisco_direction_angle(p, 1);
}

// The boresight's basis from the cosines and sines of its angles (theta, phi, psi).
PISCO_FN void pisco_angle_basis(double ct, double st, double cp, double sp, double cs, double ss,
                                PISCO_OUT(PISCO_D3) theta_p, PISCO_OUT(PISCO_D3) phi_p, PISCO_OUT(PISCO_D3) p) {
  const PISCO_D3 th = PISCO_DVEC3(ct * cp, ct * sp, -st);
  const PISCO_D3 ph = PISCO_DVEC3(-sp, cp, double(0));
  theta_p = PISCO_DVEC3(cs * th.x + ss * ph.x, cs * th.y + ss * ph.y, cs * th.z + ss * ph.z);
  phi_p = PISCO_DVEC3(-ss * th.x + cs * ph.x, -ss * th.y + cs * ph.y, -ss * th.z + cs * ph.z);
  p = PISCO_DVEC3(st * cp, st * sp, ct);
}

// A basis turned by a detector's offset: column c of the offset's rotation matrix holds the
// detector's basis vector c in the boresight's basis (theta_p, phi_p, p).
PISCO_FN void pisco_offset_basis(PISCO_D4 offset_quat, PISCO_INOUT(PISCO_D3) theta_p, PISCO_INOUT(PISCO_D3) phi_p,
                                 PISCO_INOUT(PISCO_D3) p) {
  PISCO_D3 mx, my, mz;
  pisco_rotation(offset_quat, mx, my, mz);
  const PISCO_D3 t = pisco_in_basis(mx, theta_p, phi_p, p);
  const PISCO_D3 f = pisco_in_basis(my, theta_p, phi_p, p);
  const PISCO_D3 d = pisco_in_basis(mz, theta_p, phi_p, p);
  theta_p = t;
  phi_p = f;
  p = d;
}

// The detector basis (theta', phi', p') and line of sight of one sample. quaternion: the boresight
// is b (x, y, z, w) and the basis is the columns of b * offset. Otherwise b is (theta, phi, psi, 0),
// phi in [0, 2 pi), the basis comes from trigonometry, and the offset, when `offset`, turns it: column
// c of the offset's rotation matrix holds the detector's basis vector c in the boresight's basis.
PISCO_FN void pisco_sample_frame(bool quaternion, bool offset, PISCO_D4 b, PISCO_D4 offset_quat,
                                 PISCO_OUT(PISCO_D3) theta_p, PISCO_OUT(PISCO_D3) phi_p, PISCO_OUT(PISCO_D3) p,
                                 PISCO_OUT(double) theta, PISCO_OUT(double) phi) {
  if (quaternion) {
    pisco_rotation(pisco_quat_mul(b, offset_quat), theta_p, phi_p, p);
    pisco_direction_angles(p, theta, phi);
    return;
  }
  theta = b.x;
  phi = b.y;
  pisco_angle_basis(PISCO_COS(b.x), PISCO_SIN(b.x), PISCO_COS(b.y), PISCO_SIN(b.y), PISCO_COS(b.z), PISCO_SIN(b.z),
                    theta_p, phi_p, p);
  if (offset) {
    pisco_offset_basis(offset_quat, theta_p, phi_p, p);
    pisco_direction_angles(p, theta, phi);
  }
}

#endif

#ifndef PISCO_TEMPLATE_TEXT
#if PISCO_FF

#include "ff.glsl"

struct ffquat {
  vec2 x, y, z, w;  // scalar last
};

// q a b: the rotation b, then a.
PISCO_FN ffquat ff_quat_mul(ffquat a, ffquat b) {
  ffquat r;
  r.x = ff_add(ff_add(ff_mul(a.w, b.x), ff_mul(b.w, a.x)), ff_sub(ff_mul(a.y, b.z), ff_mul(a.z, b.y)));
  r.y = ff_add(ff_add(ff_mul(a.w, b.y), ff_mul(b.w, a.y)), ff_sub(ff_mul(a.z, b.x), ff_mul(a.x, b.z)));
  r.z = ff_add(ff_add(ff_mul(a.w, b.z), ff_mul(b.w, a.z)), ff_sub(ff_mul(a.x, b.y), ff_mul(a.y, b.x)));
  r.w = ff_sub(ff_mul(a.w, b.w), ff_add(ff_add(ff_mul(a.x, b.x), ff_mul(a.y, b.y)), ff_mul(a.z, b.z)));
  return r;
}

// The columns of q's rotation matrix, exact for any norm of q (s = 2 / |q|^2).
PISCO_FN void ff_rotation(ffquat q, PISCO_OUT(ff3) ex, PISCO_OUT(ff3) ey, PISCO_OUT(ff3) ez) {
  const vec2 one = vec2(1.0f, 0.0f);
  const vec2 xx = ff_mul(q.x, q.x), yy = ff_mul(q.y, q.y), zz = ff_mul(q.z, q.z), ww = ff_mul(q.w, q.w);
  const vec2 s = ff_div(vec2(2.0f, 0.0f), ff_add(ff_add(xx, yy), ff_add(zz, ww)));
  const vec2 xy = ff_mul(q.x, q.y), xz = ff_mul(q.x, q.z), yz = ff_mul(q.y, q.z);
  const vec2 wx = ff_mul(q.w, q.x), wy = ff_mul(q.w, q.y), wz = ff_mul(q.w, q.z);
  ex.x = ff_sub(one, ff_mul(s, ff_add(yy, zz)));
  ex.y = ff_mul(s, ff_add(xy, wz));
  ex.z = ff_mul(s, ff_sub(xz, wy));
  ey.x = ff_mul(s, ff_sub(xy, wz));
  ey.y = ff_sub(one, ff_mul(s, ff_add(xx, zz)));
  ey.z = ff_mul(s, ff_add(yz, wx));
  ez.x = ff_mul(s, ff_add(xz, wy));
  ez.y = ff_mul(s, ff_sub(yz, wx));
  ez.z = ff_sub(one, ff_mul(s, ff_add(xx, yy)));
}

// The detector basis (theta', phi', p') of a sample whose boresight is the quaternion b: the columns
// of b * offset_quat, or of b when the detector is on the boresight.
PISCO_FN void ff_sample_frame(bool offset, ffquat b, ffquat offset_quat, PISCO_OUT(ff3) theta_p, PISCO_OUT(ff3) phi_p,
                              PISCO_OUT(ff3) p) {
  ff_rotation(offset ? ff_quat_mul(b, offset_quat) : b, theta_p, phi_p, p);
}

#endif

#endif
#endif
