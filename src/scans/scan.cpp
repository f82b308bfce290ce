#include "pisco/scan.hpp"

#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include <healpix_base.h>
#include <pointing.h>

#include "kernel/disc.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco {
namespace {

constexpr double pi = std::numbers::pi;
constexpr double two_pi = 2.0 * std::numbers::pi;

// 64-bit pixel indices, so that every NSIDE HEALPix supports is addressable.
using Base = T_Healpix_Base<int64>;


void check_psis(const char* fn, const std::vector<double>& psis) {
  if (psis.empty()) throw Error(std::string(fn) + ": psis is empty; give at least one angle");
  for (std::size_t i = 0; i < psis.size(); ++i)
    if (!std::isfinite(psis[i]))
      throw Error(std::string(fn) + ": psis[" + std::to_string(i) + "] is not finite");
}

Base ring_base(int nside) { return Base(int64(nside), RING, SET_NSIDE); }

// Moves a point whose co-latitude has left [0, pi] back over the pole it crossed: crossing a pole
// puts the point on the opposite meridian.
void reflect_at_poles(double& theta, double& phi) {
  if (theta < 0.0) {
    theta = -theta;
    phi += pi;
  } else if (theta > pi) {
    theta = two_pi - theta;
    phi += pi;
  }
  phi = detail::wrap_phi(phi);
}

// Uniform in [-1/2, 1/2) from the top 53 bits of one 64-bit draw. Written out rather than through
// std::uniform_real_distribution, whose algorithm the standard leaves to each library, so a seed
// gives the same scan on every platform.
double centred_uniform(std::mt19937_64& rng) { return double(rng() >> 11) * 0x1.0p-53 - 0.5; }

}  // namespace

Pointing pixel_centre_scan(int nside, const std::vector<double>& psis) {
  pisco::check_nside(nside, "pixel_centre_scan");
  check_psis("pixel_centre_scan", psis);
  const Base base = ring_base(nside);
  Pointing out;
  out.reserve(std::size_t(base.Npix()) * psis.size());
  for (const double psi : psis)
    for (int64 pix = 0; pix < base.Npix(); ++pix) {
      const pointing c = base.pix2ang(pix);
      out.push_back(c.theta, c.phi, psi);
    }
  return out;
}

Pointing random_offset_scan(int nside, const std::vector<double>& psis, double f,
                            std::uint64_t seed, bool symmetric) {
  pisco::check_nside(nside, "random_offset_scan");
  check_psis("random_offset_scan", psis);
  if (!std::isfinite(f) || f < 0.0)
    throw Error("random_offset_scan: f = " + std::to_string(f) +
                " must be a finite, non-negative fraction of the pixel size");
  const Base base = ring_base(nside);
  const double width = f * std::sqrt(4.0 * pi / double(base.Npix()));  // f Omega
  // One offset per pixel, shared by every psi: each pixel is seen at the same displaced position
  // at all angles (paper 6.3), so the map-maker solves a consistent I, Q, U there and the only
  // error left is that position's displacement from the centre (E -> B from intra-pixel gradients,
  // no temperature-to-polarization leakage).
  std::mt19937_64 rng(seed);
  std::vector<double> dtheta(std::size_t(base.Npix())), dphi(std::size_t(base.Npix()));
  for (int64 pix = 0; pix < base.Npix(); ++pix) {
    dtheta[pix] = width * centred_uniform(rng);
    // Dividing by sin(theta) makes the longitude offset a comparable arc on the sphere; pixel
    // centres never sit on a pole, so sin(theta) > 0.
    dphi[pix] = width * centred_uniform(rng) / std::sin(base.pix2ang(pix).theta);
  }
  Pointing out;
  out.reserve(std::size_t(base.Npix()) * psis.size() * (symmetric ? 2 : 1));
  for (const double psi : psis)
    for (int64 pix = 0; pix < base.Npix(); ++pix) {
      const pointing c = base.pix2ang(pix);
      for (const double sign : {1.0, -1.0}) {
        double theta = c.theta + sign * dtheta[pix];
        double phi = c.phi + sign * dphi[pix];
        reflect_at_poles(theta, phi);
        out.push_back(theta, phi, psi);
        if (!symmetric) break;
      }
    }
  return out;
}

Pointing raster_scan(double theta0, double phi0, double radius, int nside,
                     const std::vector<double>& psis) {
  if (!std::isfinite(theta0) || theta0 < 0.0 || theta0 > pi)
    throw Error("raster_scan: theta0 = " + std::to_string(theta0) + " rad must be in [0, pi]");
  if (!std::isfinite(phi0)) throw Error("raster_scan: phi0 is not finite");
  if (!std::isfinite(radius) || radius <= 0.0 || radius >= pi)
    throw Error("raster_scan: radius = " + std::to_string(radius) + " rad must be in (0, pi)");
  pisco::check_nside(nside, "raster_scan");
  check_psis("raster_scan", psis);
  const Base base = ring_base(nside);
  // Non-inclusive: only pixels whose centres lie within the radius.
  const std::vector<int64> pixels = base.query_disc(pointing(theta0, phi0), radius).toVector();
  Pointing out;
  out.reserve(pixels.size() * psis.size());
  for (const double psi : psis)
    for (const int64 pix : pixels) {
      const pointing c = base.pix2ang(pix);
      out.push_back(c.theta, c.phi, psi);
    }
  return out;
}

}  // namespace pisco

namespace pisco {

std::size_t ang2pix(int nside, double theta, double phi) {
  pisco::check_nside(nside, "ang2pix");
  if (!(theta >= 0 && theta <= std::numbers::pi) || !std::isfinite(phi))
    throw Error("ang2pix: theta must be in [0, pi] and phi finite");
  return static_cast<std::size_t>(T_Healpix_Base<int64>(nside, RING, SET_NSIDE).ang2pix(pointing(theta, phi)));
}

}  // namespace pisco
