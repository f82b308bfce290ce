#include "pisco/pointing.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include "pisco/error.hpp"

namespace pisco {

void offset_pointing(const PointingView& b, double xi, double eta, double gamma, Pointing& out) {
  out.theta.clear();
  out.phi.clear();
  out.psi.clear();
  out.reserve(b.size());
  // In the boresight's antenna frame (theta', phi', p') the detector's axis is at distance r towards
  // bearing a; rotating about n = (-sin a, cos a, 0) by r carries p' there and theta', phi' along.
  const double r = std::hypot(xi, eta), a = std::atan2(eta, xi);
  const double sa = std::sin(a), ca = std::cos(a), sr = std::sin(r), cr = std::cos(r), v = 1 - cr;
  const double rx[3] = {cr + sa * sa * v, -sa * ca * v, -ca * sr};  // R x^
  const double ry[3] = {-sa * ca * v, cr + ca * ca * v, -sa * sr};  // R y^
  const double d[3] = {sr * ca, sr * sa, cr};                       // R z^
  const double cg = std::cos(gamma), sg = std::sin(gamma);
  const double t[3] = {cg * rx[0] + sg * ry[0], cg * rx[1] + sg * ry[1], cg * rx[2] + sg * ry[2]};
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double st = std::sin(b.theta[i]), ct = std::cos(b.theta[i]);
    const double sp = std::sin(b.phi[i]), cp = std::cos(b.phi[i]);
    const double ss = std::sin(b.psi[i]), cs = std::cos(b.psi[i]);
    const double th[3] = {ct * cp, ct * sp, -st}, ph[3] = {-sp, cp, 0.0}, p[3] = {st * cp, st * sp, ct};
    double e1[3], e2[3], k[3], e[3];
    for (int j = 0; j < 3; ++j) {
      e1[j] = cs * th[j] + ss * ph[j];   // theta'
      e2[j] = -ss * th[j] + cs * ph[j];  // phi'
    }
    for (int j = 0; j < 3; ++j) {
      k[j] = d[0] * e1[j] + d[1] * e2[j] + d[2] * p[j];
      e[j] = t[0] * e1[j] + t[1] * e2[j] + t[2] * p[j];
    }
    const double theta = std::atan2(std::hypot(k[0], k[1]), k[2]);
    const double phi = std::atan2(k[1], k[0]);
    const double kt = std::cos(theta), ks = std::sin(theta), kc = std::cos(phi), kp = std::sin(phi);
    const double e_theta = e[0] * kt * kc + e[1] * kt * kp - e[2] * ks, e_phi = -e[0] * kp + e[1] * kc;
    out.push_back(theta, phi < 0 ? phi + 2 * std::numbers::pi : phi, std::atan2(e_phi, e_theta));
  }
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

}  // namespace pisco
