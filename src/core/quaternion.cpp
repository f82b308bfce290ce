#include "pisco/quaternion.hpp"

#include <cmath>
#include <numbers>

#include "core/text.hpp"
#include "kernel/frame.hpp"
#include "pisco/error.hpp"

namespace pisco {

Quat operator*(const Quat& a, const Quat& b) noexcept {
  const detail::Q4 q = detail::quat_mul(detail::Q4{a.x, a.y, a.z, a.w}, detail::Q4{b.x, b.y, b.z, b.w});
  return {q.x, q.y, q.z, q.w};
}

Quat conjugate(const Quat& q) noexcept { return {-q.x, -q.y, -q.z, q.w}; }

double norm(const Quat& q) noexcept { return std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w); }

double checked_norm(const Quat& q) noexcept {
  return std::hypot(std::hypot(q.x, q.y), std::hypot(q.z, q.w));
}

std::string rotation_problem(const Quat& q) {
  if (std::abs(norm(q) - 1.0) <= unit_quat_tolerance) return {};  // the common case, at the cost of the plain norm
  if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z) || !std::isfinite(q.w))
    return "has a non-finite component (expected a unit quaternion x, y, z, w)";
  // Finite components as large as 1e200 have a norm of that size, not an infinite one.
  const double n = checked_norm(q);
  if (std::abs(n - 1.0) <= unit_quat_tolerance) return {};
  return "has norm " + detail::number_text(n, 17) + " (expected a unit quaternion x, y, z, w, to within " +
         detail::number_text(unit_quat_tolerance) + ")";
}

Quat normalized(const Quat& q) {
  const double n = norm(q);
  if (!std::isfinite(n) || n == 0.0)
    throw Error("quaternion (" + std::to_string(q.x) + ", " + std::to_string(q.y) + ", " + std::to_string(q.z) +
                ", " + std::to_string(q.w) + ") cannot be normalized");
  return {q.x / n, q.y / n, q.z / n, q.w / n};
}

Quat quat_from_axis_angle(const std::array<double, 3>& axis, double angle) noexcept {
  const double s = std::sin(angle / 2);
  return {axis[0] * s, axis[1] * s, axis[2] * s, std::cos(angle / 2)};
}

std::array<double, 3> rotate(const Quat& q, const std::array<double, 3>& v) noexcept {
  const detail::Vec3<double> r = detail::quat_rotate(detail::Q4{q.x, q.y, q.z, q.w}, {v[0], v[1], v[2]});
  return {r.x, r.y, r.z};
}

Quat quat_from_pointing(double theta, double phi, double psi) noexcept {
  const Quat rz_phi = quat_from_axis_angle({0, 0, 1}, phi);
  const Quat ry_theta = quat_from_axis_angle({0, 1, 0}, theta);
  const Quat rz_psi = quat_from_axis_angle({0, 0, 1}, psi);
  return rz_phi * ry_theta * rz_psi;
}

void quat_to_pointing(const Quat& q, double& theta, double& phi, double& psi) noexcept {
  const detail::SampleFrame<double> f = detail::frame_from_quat(detail::Q4{q.x, q.y, q.z, q.w}, 1.0, 0.0);
  detail::direction_angles(f.p, theta, phi);
  psi = detail::position_angle(f.theta_p, theta, phi);
}

Quat offset_quat(double xi, double eta, double gamma) noexcept {
  const double r = std::hypot(xi, eta), a = std::atan2(eta, xi);
  return quat_from_axis_angle({-std::sin(a), std::cos(a), 0.0}, r) * quat_from_axis_angle({0, 0, 1}, gamma);
}

void offset_from_quat(const Quat& q, double& xi, double& eta, double& gamma) noexcept {
  const std::array<double, 3> d = rotate(q, {0, 0, 1});
  const double r = std::atan2(std::hypot(d[0], d[1]), d[2]), a = std::atan2(d[1], d[0]);
  xi = r * std::cos(a);
  eta = r * std::sin(a);
  // What remains after the move along the great circle is a turn about z.
  const Quat turn = conjugate(offset_quat(xi, eta, 0.0)) * q;
  gamma = 2 * std::atan2(turn.z, turn.w);
  if (gamma > std::numbers::pi) gamma -= 2 * std::numbers::pi;
  if (gamma <= -std::numbers::pi) gamma += 2 * std::numbers::pi;
}

}  // namespace pisco
