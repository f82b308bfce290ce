// The ground in the horizon frame (pisco/ground.hpp; docs/ground.md).
#include "pisco/ground.hpp"

#include <healpix_base.h>

#include <cmath>
#include <numbers>
#include <string>

#include "core/text.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace {
constexpr double pi = std::numbers::pi;
}  // namespace

Sky ground_sky(int nside, const GroundModel& model, const std::string& units) {
  if (!std::isfinite(model.value)) throw Error("ground: the brightness must be finite");
  if (model.horizon.empty()) throw Error("ground: the horizon needs at least one elevation");
  for (std::size_t k = 0; k < model.horizon.size(); ++k)
    if (!(std::abs(model.horizon[k]) < pi / 2))
      throw Error("ground: the horizon's elevation " + std::to_string(k) + " is " +
                  detail::degrees_text(model.horizon[k]) + "; expected one within (-90, 90) deg");
  if (!(model.width >= 0.0 && model.width <= pi / 2))
    throw Error("ground: the horizon's width is " + detail::degrees_text(model.width) + "; expected [0, 90] deg");
  Sky sky(nside, units);
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const std::size_t n = model.horizon.size();
  std::span<double> I = sky.I();
  for (std::size_t p = 0; p < sky.npix(); ++p) {
    const pointing at = base.pix2ang(static_cast<int>(p));
    const double elevation = pi / 2 - at.theta;
    double azimuth = std::fmod(-at.phi, 2 * pi);
    if (azimuth < 0) azimuth += 2 * pi;
    // The horizon at this azimuth: linear between the N given, periodic.
    const double x = azimuth / (2 * pi) * double(n);
    const std::size_t k = std::min(static_cast<std::size_t>(x), n - 1);
    const double f = x - double(k);
    const double horizon = (1.0 - f) * model.horizon[k] + f * model.horizon[(k + 1) % n];
    const double d = elevation - horizon;
    double below = d < 0 ? 1.0 : 0.0;
    if (model.width > 0) {
      if (d <= -model.width / 2) below = 1.0;
      else if (d >= model.width / 2) below = 0.0;
      else below = 0.5 * (1.0 - std::sin(pi * d / model.width));
    }
    I[p] = model.value * below;
  }
  return sky;
}

double rayleigh_jeans_in(const std::string& units, double kelvin, double frequency_ghz) {
  const bool micro = units.rfind("uK", 0) == 0;
  const std::string kind = micro ? units.substr(2) : units.rfind("K", 0) == 0 ? units.substr(1) : "";
  if (kind != "_RJ" && kind != "_CMB")
    throw Error("ground: the sky's units are '" + units +
                "'; a ground temperature converts to K_RJ, uK_RJ, K_CMB or uK_CMB only (give a ground map in the "
                "sky's units instead)");
  double value = kelvin * (micro ? 1e6 : 1.0);
  if (kind == "_CMB") {
    if (!(frequency_ghz > 0 && std::isfinite(frequency_ghz)))
      throw Error("ground: a ground temperature in " + units + " needs the frequency (GHz), for dT_CMB / dT_RJ");
    // (e^x - 1)^2 / (x^2 e^x), x = h nu / k T_CMB.
    const double x = 6.62607015e-34 * frequency_ghz * 1e9 / (1.380649e-23 * 2.72548);
    value *= std::expm1(x) * std::expm1(x) / (x * x * std::exp(x));
  }
  return value;
}

}  // namespace pisco
