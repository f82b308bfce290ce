// The antenna basis of one sample from its pointing, in either input form (docs/physics.md,
// "Pointing as a rotation"): written once for the float64 reference, the host-side expansion and the
// CUDA kernel; shaders/frame.glsl mirrors it and tests/test_frame.cpp holds the two together.
//
// - Quaternion pointing: q = q_boresight q_offset, composed per sample; the basis is the rotation's
//   columns, theta' = q x^ q*, phi' = q y^ q*, p' = q z^ q*: no angle on the way.
// - Angle pointing (theta, phi, psi) of the boresight: the basis from trigonometry (make_frame); a
//   detector offset then turns it by the offset's rotation matrix, whose columns are the detector's
//   basis vectors in the boresight's basis.
// The disc selection needs the line of sight as angles: theta and phi from p' with atan2.
#pragma once

#include <cmath>

#include "core/contribution.hpp"
#include "core/disc.hpp"
#include "core/hd.hpp"

namespace pisco::detail {

struct Q4 {
  double x, y, z, w;  // scalar last
};

PISCO_HD Q4 quat_mul(const Q4& a, const Q4& b) {
  return {a.w * b.x + b.w * a.x + (a.y * b.z - a.z * b.y), a.w * b.y + b.w * a.y + (a.z * b.x - a.x * b.z),
          a.w * b.z + b.w * a.z + (a.x * b.y - a.y * b.x), a.w * b.w - (a.x * b.x + a.y * b.y + a.z * b.z)};
}

// The rotation matrix of a quaternion, as its three columns q x^ q*, q y^ q*, q z^ q*. With
// s = 2 / |q|^2 the matrix is orthonormal for any non-zero q, so a quaternion a few ulp off the unit
// sphere needs no renormalization (and a unit one gets exactly the textbook matrix).
struct Rotation {
  Vec3<double> ex, ey, ez;
};

PISCO_HD Rotation rotation_matrix(const Q4& q) {
  const double s = 2.0 / (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  const double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
  const double xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  const double wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  Rotation r;
  r.ex = {1.0 - s * (yy + zz), s * (xy + wz), s * (xz - wy)};
  r.ey = {s * (xy - wz), 1.0 - s * (xx + zz), s * (yz + wx)};
  r.ez = {s * (xz + wy), s * (yz - wx), 1.0 - s * (xx + yy)};
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

// The basis f turned by an offset whose rotation matrix is m: column c of m holds the detector's
// basis vector c in f's basis.
PISCO_HD SampleFrame<double> offset_frame(const SampleFrame<double>& f, const Rotation& m, double cos_zeta,
                                          double sin_zeta) {
  auto in_f = [&](const Vec3<double>& c) {
    return Vec3<double>{c.x * f.theta_p.x + c.y * f.phi_p.x + c.z * f.p.x,
                        c.x * f.theta_p.y + c.y * f.phi_p.y + c.z * f.p.y,
                        c.x * f.theta_p.z + c.y * f.phi_p.z + c.z * f.p.z};
  };
  return frame_with_zeta(in_f(m.ex), in_f(m.ey), in_f(m.ez), cos_zeta, sin_zeta);
}

// theta in [0, pi] and phi in [0, 2 pi) of a unit vector.
PISCO_HD void direction_angles(const Vec3<double>& p, double& theta, double& phi) {
  theta = atan2(sqrt(p.x * p.x + p.y * p.y), p.z);
  phi = atan2(p.y, p.x);
  if (phi < 0.0) phi += 6.283185307179586476925286766559;
  if (phi >= 6.283185307179586476925286766559) phi = 0.0;
}

// The angle of theta' from the meridian theta^ at (theta, phi) towards phi^: the pointing's psi.
PISCO_HD double position_angle(const Vec3<double>& theta_p, double theta, double phi) {
  const double ct = cos(theta), st = sin(theta), cp = cos(phi), sp = sin(phi);
  const double along_theta = theta_p.x * ct * cp + theta_p.y * ct * sp - theta_p.z * st;
  const double along_phi = -theta_p.x * sp + theta_p.y * cp;
  return atan2(along_phi, along_theta);
}

// A detector's offset as the kernels use it: its quaternion (composed with boresight quaternions)
// and its rotation matrix (applied to bases from angles).
struct DetectorOffset {
  bool active = false;  // false: on the boresight
  Q4 quat{0.0, 0.0, 0.0, 1.0};
  Rotation matrix{{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}};
};

PISCO_HD DetectorOffset make_offset(const Q4& q) {
  DetectorOffset o;
  o.active = q.x != 0.0 || q.y != 0.0 || q.z != 0.0;
  o.quat = q;
  o.matrix = rotation_matrix(q);
  return o;
}

// One sample's detector basis and line of sight (theta, phi in [0, 2 pi)) from boresight angles.
// On the boresight the angles pass through untouched (phi wrapped), as they always have.
PISCO_HD SampleFrame<double> angle_sample(double theta, double phi, double psi, const DetectorOffset& o,
                                          double cos_zeta, double sin_zeta, double& theta_out, double& phi_out) {
  phi = wrap_phi(phi);
  if (!o.active) {
    theta_out = theta;
    phi_out = phi;
    return make_frame(cos(theta), sin(theta), cos(phi), sin(phi), cos(psi), sin(psi), cos_zeta, sin_zeta);
  }
  const SampleFrame<double> b = make_frame(cos(theta), sin(theta), cos(phi), sin(phi), cos(psi), sin(psi), 1.0, 0.0);
  const SampleFrame<double> f = offset_frame(b, o.matrix, cos_zeta, sin_zeta);
  direction_angles(f.p, theta_out, phi_out);
  return f;
}

// The same from a boresight quaternion: q = q_boresight q_offset, then the rotation's columns.
PISCO_HD SampleFrame<double> quat_sample(const Q4& boresight, const DetectorOffset& o, double cos_zeta,
                                         double sin_zeta, double& theta_out, double& phi_out) {
  const SampleFrame<double> f = frame_from_quat(quat_mul(boresight, o.quat), cos_zeta, sin_zeta);
  direction_angles(f.p, theta_out, phi_out);
  return f;
}

}  // namespace pisco::detail
