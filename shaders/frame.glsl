// One sample's antenna basis in float64, from boresight angles or a boresight quaternion, with the
// detector's offset applied: src/core/frame.hpp line for line (docs/physics.md, "Pointing as a
// rotation"). Without float64 (PISCO_FF), the same from a boresight quaternion in float-float (the
// host turns angles into quaternions for that path). Written in the common subset of GLSL and C++
// (common.glsl) so that tests/test_frame.cpp and tests/test_kernel_host.cpp run this very file as C++.
#ifndef PISCO_FRAME_GLSL
#define PISCO_FRAME_GLSL

#include "common.glsl"

#if !PISCO_FF

#include "fp64.glsl"

// q a b: the rotation b, then a (quaternions as (x, y, z, w), scalar last).
PISCO_FN dvec4 pisco_quat_mul(dvec4 a, dvec4 b) {
  return dvec4(a.w * b.x + b.w * a.x + (a.y * b.z - a.z * b.y), a.w * b.y + b.w * a.y + (a.z * b.x - a.x * b.z),
               a.w * b.z + b.w * a.z + (a.x * b.y - a.y * b.x), a.w * b.w - (a.x * b.x + a.y * b.y + a.z * b.z));
}

// The columns of q's rotation matrix, exact for any norm of q (s = 2 / |q|^2).
PISCO_FN void pisco_rotation(dvec4 q, PISCO_OUT(dvec3) ex, PISCO_OUT(dvec3) ey, PISCO_OUT(dvec3) ez) {
  const double s = 2.0lf / (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  const double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
  const double xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  const double wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  ex = dvec3(1.0lf - s * (yy + zz), s * (xy + wz), s * (xz - wy));
  ey = dvec3(s * (xy - wz), 1.0lf - s * (xx + zz), s * (yz + wx));
  ez = dvec3(s * (xz + wy), s * (yz - wx), 1.0lf - s * (xx + yy));
}

// c's components taken in the basis (a, b, p): c.x a + c.y b + c.z p.
PISCO_FN dvec3 pisco_in_basis(dvec3 c, dvec3 a, dvec3 b, dvec3 p) {
  return dvec3(c.x * a.x + c.y * b.x + c.z * p.x, c.x * a.y + c.y * b.y + c.z * p.y, c.x * a.z + c.y * b.z + c.z * p.z);
}

// theta in [0, pi] and phi in [0, 2 pi) of the unit vector p.
PISCO_FN void pisco_direction_angles(dvec3 p, PISCO_OUT(double) theta, PISCO_OUT(double) phi) {
  const double twopi = 6.283185307179586476925286766559lf;
  theta = pisco_atan2_nonneg_y(sqrt(p.x * p.x + p.y * p.y), p.z);
  phi = p.y >= 0.0lf ? pisco_atan2_nonneg_y(p.y, p.x) : twopi - pisco_atan2_nonneg_y(-p.y, p.x);
  if (phi >= twopi) phi = 0.0lf;
}

// The detector basis (theta', phi', p') and line of sight of one sample. quaternion: the boresight
// is b (x, y, z, w) and the basis is the columns of b * offset. Otherwise b is (theta, phi, psi, 0),
// phi in [0, 2 pi), and the offset, when `offset`, turns the basis from trigonometry.
PISCO_FN void pisco_sample_frame(bool quaternion, bool offset, dvec4 b, dvec4 offset_quat, PISCO_OUT(dvec3) theta_p,
                                 PISCO_OUT(dvec3) phi_p, PISCO_OUT(dvec3) p, PISCO_OUT(double) theta,
                                 PISCO_OUT(double) phi) {
  if (quaternion) {
    pisco_rotation(pisco_quat_mul(b, offset_quat), theta_p, phi_p, p);
    pisco_direction_angles(p, theta, phi);
    return;
  }
  theta = b.x;
  phi = b.y;
  const double ct = pisco_cos(b.x), st = pisco_sin(b.x);
  const double cp = pisco_cos(b.y), sp = pisco_sin(b.y);
  const double cs = pisco_cos(b.z), ss = pisco_sin(b.z);
  const dvec3 th = dvec3(ct * cp, ct * sp, -st);
  const dvec3 ph = dvec3(-sp, cp, 0.0lf);
  theta_p = dvec3(cs * th.x + ss * ph.x, cs * th.y + ss * ph.y, cs * th.z + ss * ph.z);
  phi_p = dvec3(-ss * th.x + cs * ph.x, -ss * th.y + cs * ph.y, -ss * th.z + cs * ph.z);
  p = dvec3(st * cp, st * sp, ct);
  if (offset) {
    dvec3 mx, my, mz;
    pisco_rotation(offset_quat, mx, my, mz);
    const dvec3 t = pisco_in_basis(mx, theta_p, phi_p, p);
    const dvec3 f = pisco_in_basis(my, theta_p, phi_p, p);
    const dvec3 d = pisco_in_basis(mz, theta_p, phi_p, p);
    theta_p = t;
    phi_p = f;
    p = d;
    pisco_direction_angles(p, theta, phi);
  }
}

#else  // PISCO_FF

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
