// Inputs and comparisons shared by the backend tests (docs/validation.md, "B"): a CMB-like sky, pointings that
// reach the poles and cross phi = 0, the error statistics of a TOD against the reference, and why a
// backend cannot run here.
#pragma once

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <healpix_base.h>
#include <pointing.h>

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/hwp.hpp"
#include "pisco/pointing.hpp"
#include "pisco/sky.hpp"
#include "pisco/units.hpp"

namespace pisco_test {

// CMB-like sky in K: smooth large-scale structure plus white noise, polarized, small V, on top of
// `monopole`.
inline pisco::Sky cmb_like_sky(int nside, std::uint64_t seed, double monopole = 0.0) {
  pisco::Sky sky(nside, "K_CMB");
  const Healpix_Base base(nside, RING, SET_NSIDE);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  for (std::size_t i = 0; i < sky.npix(); ++i) {
    const pointing p = base.pix2ang(int(i));
    const double smooth = std::sin(3 * p.theta) * std::cos(2 * p.phi) + 0.5 * std::cos(5 * p.theta + p.phi);
    sky.I()[i] = monopole + 1e-6 * (80 * smooth + 20 * g(rng));
    sky.Q()[i] = 1e-6 * (3 * std::cos(4 * p.theta) * std::sin(p.phi) + g(rng));
    sky.U()[i] = 1e-6 * (3 * std::sin(2 * p.theta) * std::cos(3 * p.phi) + g(rng));
    sky.V()[i] = 1e-8 * g(rng);
  }
  return sky;
}

// Random pointings over the sphere, with some within 1 deg of each pole and across phi = 0.
inline pisco::Pointing random_pointing(std::size_t n, std::uint64_t seed) {
  constexpr double pi = std::numbers::pi;
  using pisco::deg;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing p;
  for (std::size_t i = 0; i < n; ++i) {
    double theta = std::acos(1 - 2 * u(rng));
    double phi = 2 * pi * u(rng) - (i % 5 == 0 ? pi : 0.0);
    if (i % 17 == 0) theta = u(rng) * deg;
    if (i % 19 == 0) theta = pi - u(rng) * deg;
    if (i % 23 == 0) phi = 1e-3 * (u(rng) - 0.5);
    p.push_back(theta, phi, 4 * pi * (u(rng) - 0.5));
  }
  return p;
}

struct Stats {
  double rms_ref = 0, rms_err = 0, max_err = 0;
  std::size_t non_finite = 0;  // samples of `got` left unwritten (NaN-poisoned) or not finite
};

inline Stats compare(const std::vector<double>& ref, const std::vector<double>& got) {
  Stats s;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    if (!std::isfinite(got[i])) ++s.non_finite;
    const double e = got[i] - ref[i];
    s.rms_ref += ref[i] * ref[i];
    s.rms_err += e * e;
    s.max_err = std::max(s.max_err, std::abs(e));
  }
  s.rms_ref = std::sqrt(s.rms_ref / double(ref.size()));
  s.rms_err = std::sqrt(s.rms_err / double(ref.size()));
  return s;
}

struct Scene {
  pisco::Sky sky;
  std::vector<pisco::Beamsor> beams;
  pisco::FocalPlane focal_plane;
};

// A PSB pair with mismatched elliptical beams carrying cross-polar lobes and Mueller leakage, a
// detector with a round beam (stored as a radial profile), one with a plain elliptical beam and one
// with a round beam and in-phase cross-polar response, over cmb_like_sky(nside, 7, monopole). The
// five cover both weight layouts (2D grid, radial profile) with and without w_U and w_V, which the
// GPU kernels store in different ways.
inline Scene backend_scene(int nside, double monopole = 0.0) {
  using pisco::deg;
  Scene s{cmb_like_sky(nside, 7, monopole), {}, {}};
  pisco::BeamOptions a;
  a.rho_max = 5 * deg;
  a.cross_polar = 0.03;
  a.cross_polar_pattern = pisco::CrossPolarPattern::quadrupole;
  a.mueller[1][0] = 0.01;  // T -> Q leakage
  a.mueller[2][0] = -0.004;
  pisco::BeamOptions b = a;
  b.cross_polar = 0.02;
  b.cross_polar_pattern = pisco::CrossPolarPattern::uniform;
  s.beams.push_back(pisco::Beamsor::elliptical_gaussian(1.6 * deg, 1.4 * deg, 20 * deg, a));
  s.beams.push_back(pisco::Beamsor::elliptical_gaussian(1.5 * deg, 1.45 * deg, -35 * deg, b));
  pisco::BeamOptions r;
  r.rho_max = 4 * deg;
  s.beams.push_back(pisco::Beamsor::gaussian(1.5 * deg, r));
  s.beams.push_back(pisco::Beamsor::elliptical_gaussian(1.7 * deg, 1.3 * deg, 60 * deg, r));
  pisco::BeamOptions rx = r;
  rx.cross_polar = 0.05;
  rx.cross_polar_pattern = pisco::CrossPolarPattern::uniform;
  s.beams.push_back(pisco::Beamsor::gaussian(1.5 * deg, rx));
  s.focal_plane.add_pair("psb", 22.5 * deg, 0, 1, 0.01, 1.0, 0.98);
  s.focal_plane.add({"round", -10 * deg, 0.0, 1.02, 2});
  s.focal_plane.add({"ellip", 40 * deg, 0.0, 1.0, 3});
  s.focal_plane.add({"roundx", 70 * deg, 0.02, 1.0, 4});
  return s;
}

// A generic half-wave plate: the ideal one with all 16 entries perturbed (M_QI, M_UV, ... non-zero),
// with a 2% loss in M_II so that it stays a passive element (docs/physics.md, "Physical bounds on
// Mueller matrices").
inline pisco::Mueller generic_plate() {
  pisco::Mueller m0 = pisco::ideal_hwp_mueller();
  const double leak[4][4] = {{-0.02, 0.012, -0.008, 0.005},
                             {0.021, -0.03, 0.017, -0.011},
                             {-0.015, 0.009, 0.025, 0.04},
                             {0.007, -0.02, 0.033, 0.02}};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) m0[i][j] += leak[i][j];
  return m0;
}

// Why `backend` cannot run on this machine, or "" when it can.
inline std::string backend_unavailable(const std::string& backend) {
  for (const auto& b : pisco::Engine::backends())
    if (b.name == backend) return b.available ? "" : b.detail;
  return "the backend '" + backend + "' is unknown to this library";
}

// Sets the setting `name` where the options' backend takes it (every backend that has it under
// "auto"): the parametrized suites give host threads and device chunks to the backends that have them.
inline void set_taken(pisco::EngineOptions& o, const std::string& name, const pisco::EngineValue& value) {
  if (o.backend == "auto" || pisco::backend_has_setting(o.backend, name)) o.set(name, value);
}

}  // namespace pisco_test
