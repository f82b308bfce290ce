// The antenna basis of one sample from its pointing, in either input form (docs/physics.md,
// "Pointing as a rotation"), for the float64 reference, the host-side expansion and the CUDA kernel.
// The per-sample maths is src/kernel/frame.glsl's, included here as C++ (with the C library's sine,
// cosine and arctangent, kernel/fp64.hpp), the one text the shaders run too; tests/test_frame.cpp holds the shader build
// to it.
//
// - Quaternion pointing: q = q_boresight q_offset, composed per sample; the basis is the rotation's
//   columns, theta' = q x^ q*, phi' = q y^ q*, p' = q z^ q*: no angle on the way.
// - Angle pointing (theta, phi, psi) of the boresight: the basis from trigonometry; a detector offset
//   then turns it by the offset's rotation matrix, whose columns are the detector's basis vectors in
//   the boresight's basis.
// The disc selection needs the line of sight as angles: theta and phi from p' with atan2.
#pragma once

#include <cmath>

#include "kernel/contribution.hpp"
#include "kernel/disc.hpp"
#include "kernel/fp64.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail {

struct Q4 {
  double x, y, z, w;  // scalar last
};

// src/kernel/frame.glsl's float64 part: pisco_quat_mul, pisco_rotation, pisco_in_basis,
// pisco_direction_angles, pisco_sample_frame.
#include "kernel/text_begin.hpp"
#define PISCO_D3 Vec3<double>
#define PISCO_D4 Q4
#define PISCO_DVEC3(a, b, c) \
  Vec3<double> { a, b, c }
#define PISCO_DVEC4(a, b, c, d) \
  Q4 { a, b, c, d }
#define PISCO_COS pisco_cos
#define PISCO_SIN pisco_sin
#define PISCO_ATAN2_NONNEG_Y pisco_atan2_nonneg_y
#define PISCO_TWO_PI 6.283185307179586476925286766559
#include "kernel/frame.glsl"
#undef PISCO_D3
#undef PISCO_D4
#undef PISCO_DVEC3
#undef PISCO_DVEC4
#undef PISCO_COS
#undef PISCO_SIN
#undef PISCO_ATAN2_NONNEG_Y
#undef PISCO_TWO_PI
#include "kernel/text_end.hpp"

PISCO_HD Q4 quat_mul(const Q4& a, const Q4& b) { return pisco_quat_mul(a, b); }

// The rotation matrix of a quaternion, as its three columns q x^ q*, q y^ q*, q z^ q* (exact for any
// norm of q: pisco_rotation).
struct Rotation {
  Vec3<double> ex, ey, ez;
};

PISCO_HD Rotation rotation_matrix(const Q4& q) {
  Rotation r;
  pisco_rotation(q, r.ex, r.ey, r.ez);
  return r;
}

PISCO_HD Vec3<double> quat_rotate(const Q4& q, const Vec3<double>& v) {
  const Rotation r = rotation_matrix(q);
  return {r.ex.x * v.x + r.ey.x * v.y + r.ez.x * v.z, r.ex.y * v.x + r.ey.y * v.y + r.ez.y * v.z,
          r.ex.z * v.x + r.ey.z * v.y + r.ez.z * v.z};
}

PISCO_HD SampleFrame<double> frame_with_zeta(const Vec3<double>& theta_p, const Vec3<double>& phi_p,
                                             const Vec3<double>& p, double cos_zeta, double sin_zeta) {
  SampleFrame<double> f;
  f.theta_p = theta_p;
  f.phi_p = phi_p;
  f.p = p;
  f.e_c = {cos_zeta * theta_p.x + sin_zeta * phi_p.x, cos_zeta * theta_p.y + sin_zeta * phi_p.y,
           cos_zeta * theta_p.z + sin_zeta * phi_p.z};
  return f;
}

// The antenna basis of the rotation q (a unit quaternion).
PISCO_HD SampleFrame<double> frame_from_quat(const Q4& q, double cos_zeta, double sin_zeta) {
  const Rotation r = rotation_matrix(q);
  return frame_with_zeta(r.ex, r.ey, r.ez, cos_zeta, sin_zeta);
}

// theta in [0, pi] and phi in [0, 2 pi) of a unit vector.
PISCO_HD void direction_angles(const Vec3<double>& p, double& theta, double& phi) {
  pisco_direction_angles(p, theta, phi);
}

// The angle of theta' from the meridian theta^ at (theta, phi) towards phi^: the pointing's psi.
PISCO_HD double position_angle(const Vec3<double>& theta_p, double theta, double phi) {
  const double ct = cos(theta), st = sin(theta), cp = cos(phi), sp = sin(phi);
  const double along_theta = theta_p.x * ct * cp + theta_p.y * ct * sp - theta_p.z * st;
  const double along_phi = -theta_p.x * sp + theta_p.y * cp;
  return atan2(along_phi, along_theta);
}

// A detector's offset as the kernels use it: its quaternion, composed with boresight quaternions, and
// whose rotation matrix turns bases from angles (pisco_sample_frame).
struct DetectorOffset {
  bool active = false;  // false: on the boresight
  Q4 quat{0.0, 0.0, 0.0, 1.0};
};

PISCO_HD DetectorOffset make_offset(const Q4& q) {
  DetectorOffset o;
  o.active = q.x != 0.0 || q.y != 0.0 || q.z != 0.0;
  o.quat = q;
  return o;
}

// One sample's detector basis and line of sight (theta, phi in [0, 2 pi)) from boresight angles.
// On the boresight the angles pass through untouched (phi wrapped), as they always have.
PISCO_HD SampleFrame<double> angle_sample(double theta, double phi, double psi, const DetectorOffset& o,
                                          double cos_zeta, double sin_zeta, double& theta_out, double& phi_out) {
  Vec3<double> theta_p, phi_p, p;
  pisco_sample_frame(false, o.active, Q4{theta, wrap_phi(phi), psi, 0.0}, o.quat, theta_p, phi_p, p, theta_out, phi_out);
  return frame_with_zeta(theta_p, phi_p, p, cos_zeta, sin_zeta);
}

// The same from a boresight quaternion: q = q_boresight q_offset, then the rotation's columns.
PISCO_HD SampleFrame<double> quat_sample(const Q4& boresight, const DetectorOffset& o, double cos_zeta,
                                         double sin_zeta, double& theta_out, double& phi_out) {
  Vec3<double> theta_p, phi_p, p;
  pisco_sample_frame(true, o.active, boresight, o.quat, theta_p, phi_p, p, theta_out, phi_out);
  return frame_with_zeta(theta_p, phi_p, p, cos_zeta, sin_zeta);
}

}  // namespace pisco::detail
