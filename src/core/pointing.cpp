#include "pisco/pointing.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include "pisco/error.hpp"

namespace pisco {

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
