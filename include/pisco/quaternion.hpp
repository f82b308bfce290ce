// Rotations as unit quaternions, in the layout and meaning of TOAST 3 and litebird_sim: the vector
// part first, the scalar last (x, y, z, w). A pointing quaternion q rotates the frame of the sky
// basis onto the detector's antenna basis (docs/physics.md, "Pointing as a rotation"):
//   p'     = q z^ q*  (the line of sight),
//   theta' = q x^ q*  (the axis polarization angles are measured from, zeta = 0),
//   phi'   = q y^ q*.
// Detector pointing is the boresight's composed with the detector's offset: q = q_boresight q_offset.
#pragma once

#include <array>
#include <string>

namespace pisco {

struct Quat {
  double x = 0.0, y = 0.0, z = 0.0, w = 1.0;  // identity by default
};
// How far from 1 the norm of a quaternion taken as a rotation may be (offsets, boresight quaternions):
// rounding, never a mistake. Beyond it the quaternion is refused, not normalized.
inline constexpr double unit_quat_tolerance = 1e-6;
static_assert(sizeof(Quat) == 4 * sizeof(double), "a Quat is four packed doubles (x, y, z, w)");

// Hamilton product: the rotation b, then a.
Quat operator*(const Quat& a, const Quat& b) noexcept;
Quat conjugate(const Quat& q) noexcept;
double norm(const Quat& q) noexcept;
// The same without overflow or underflow on the way (components of 1e200 have a norm of about 2e200,
// not inf): for the checks that report a quaternion's norm.
double checked_norm(const Quat& q) noexcept;
// Why q is not a rotation, the one check of every reader of quaternions (pointing, pointing files,
// focal planes, Python): "has a non-finite component (expected a unit quaternion x, y, z, w)" or "has
// norm N (expected a unit quaternion x, y, z, w, to within 1e-06)"; empty when its norm is 1 to
// within unit_quat_tolerance. The caller names the quaternion before it.
std::string rotation_problem(const Quat& q);
// q rotated onto the unit sphere; throws pisco::Error for a zero or non-finite quaternion.
Quat normalized(const Quat& q);
// The rotation by `angle` (radians) about the unit vector `axis`.
Quat quat_from_axis_angle(const std::array<double, 3>& axis, double angle) noexcept;
// q v q*.
std::array<double, 3> rotate(const Quat& q, const std::array<double, 3>& v) noexcept;

// ZYZ Euler angles, TOAST's "ISO" angles: q = R_z(phi) R_y(theta) R_z(psi), so that q z^ q* points
// at (theta, phi) and q x^ q* lies at psi from the local meridian theta^ towards phi^ (the COSMO
// convention). This is the (theta, phi, psi) of pisco::PointingView.
Quat quat_from_pointing(double theta, double phi, double psi) noexcept;
// The inverse: theta in [0, pi], phi in [0, 2 pi), psi in (-pi, pi]. At the poles (theta = 0 or pi)
// phi is 0 and psi carries the whole rotation about z.
void quat_to_pointing(const Quat& q, double& theta, double& phi, double& psi) noexcept;

// A detector's offset from the boresight: the two spellings of pisco::Detector's offset, converted
// here and nowhere else. (xi, eta, gamma) in radians: the detector's line of sight lies at distance
// sqrt(xi^2 + eta^2) from the boresight towards atan2(eta, xi), measured from the boresight's theta'
// towards phi'; its theta' is the boresight's carried along that great circle, then turned by gamma.
// The quaternion is the rotation R(n, r) R_z(gamma), n = (-sin a, cos a, 0), r = hypot(xi, eta),
// a = atan2(eta, xi). (TOAST's own xi, eta, gamma columns parameterize the offset differently; its
// `quat` column is the offset itself: read_toast_focal_plane.)
Quat offset_quat(double xi, double eta, double gamma) noexcept;
// The inverse of offset_quat, for offsets r < pi.
void offset_from_quat(const Quat& q, double& xi, double& eta, double& gamma) noexcept;

}  // namespace pisco
