#include "pisco/pointing.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include "core/frame.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace {

detail::DetectorOffset kernel_offset(const Quat& q) { return detail::make_offset({q.x, q.y, q.z, q.w}); }

void push_sample(const detail::SampleFrame<double>& f, double theta, double phi, Pointing& out) {
  out.push_back(theta, phi, detail::position_angle(f.theta_p, theta, phi));
}

}  // namespace

void detector_pointing(const PointingView& b, const Quat& offset, Pointing& out) {
  out.clear();
  out.reserve(b.size());
  const detail::DetectorOffset o = kernel_offset(offset);
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (!o.active) {
      out.push_back(b.theta[i], detail::wrap_phi(b.phi[i]), b.psi[i]);
      continue;
    }
    double theta = 0.0, phi = 0.0;
    const auto f = detail::angle_sample(b.theta[i], b.phi[i], b.psi[i], o, 1.0, 0.0, theta, phi);
    push_sample(f, theta, phi, out);
  }
}

void detector_pointing(const QuatPointingView& b, const Quat& offset, Pointing& out) {
  out.clear();
  out.reserve(b.size());
  const detail::DetectorOffset o = kernel_offset(offset);
  for (std::size_t i = 0; i < b.size(); ++i) {
    const Quat& q = b.quats[i];
    double theta = 0.0, phi = 0.0;
    const auto f = detail::quat_sample({q.x, q.y, q.z, q.w}, o, 1.0, 0.0, theta, phi);
    push_sample(f, theta, phi, out);
  }
}

void offset_pointing(const PointingView& b, double xi, double eta, double gamma, Pointing& out) {
  detector_pointing(b, offset_quat(xi, eta, gamma), out);
}

void check_pointing(const PointingView& p, const char* origin) {
  if (p.phi.size() != p.theta.size() || p.psi.size() != p.theta.size())
    throw Error(std::string(origin) + ": theta, phi and psi have different lengths (" +
                std::to_string(p.theta.size()) + ", " + std::to_string(p.phi.size()) + ", " +
                std::to_string(p.psi.size()) + ")");
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double t = p.theta[i];
    if (!std::isfinite(t) || !std::isfinite(p.phi[i]) || !std::isfinite(p.psi[i]))
      throw Error(std::string(origin) + ": sample " + std::to_string(i) +
                  " has a non-finite theta, phi or psi");
    if (t < 0.0 || t > std::numbers::pi)
      throw Error(std::string(origin) + ": sample " + std::to_string(i) + " has theta = " +
                  std::to_string(t) + " rad, outside [0, pi]");
  }
}

void check_pointing(const QuatPointingView& p, const char* origin) {
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Quat& q = p.quats[i];
    const double n = norm(q);
    if (!std::isfinite(n))
      throw Error(std::string(origin) + ": quaternion of sample " + std::to_string(i) + " has a non-finite component");
    if (std::abs(n - 1.0) > 1e-6)
      throw Error(std::string(origin) + ": quaternion of sample " + std::to_string(i) + " has norm " +
                  std::to_string(n) + "; expected a unit quaternion (x, y, z, w), to within 1e-6");
  }
}

}  // namespace pisco
