// Sidelobes (docs/beams.md, "Sidelobes"; docs/validation.md, "K3"): a beam with a -30 dB ring
// sidelobe at 10 deg, split into a main part on the sky's pixels and an outer part on a band-limited
// coarser sky, against the same beam summed whole over a 20 deg disc.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "backend_fixtures.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/spectra.hpp"

namespace {

using pisco::Beamsor;
using pisco::deg;
constexpr double pi = std::numbers::pi;

// A 1 deg Gaussian main beam, polarized along x, and a ring of 3 deg FWHM at 10 deg whose peak is
// 1e-3 (-30 dB) of the main beam's, with a little cross-polar response.
pisco::Mueller ring_beam(double rho, double sigma) {
  const double s = 1.0 * deg / std::sqrt(8 * std::log(2.0)), sr = 3.0 * deg / std::sqrt(8 * std::log(2.0));
  const double main = std::exp(-rho * rho / (2 * s * s));
  const double ring = 1e-3 * std::exp(-std::pow(rho - 10 * deg, 2) / (2 * sr * sr));
  const double k = 0.1 * std::sin(2 * sigma);  // the ring's cross-polar field ratio
  const double i = main + ring * (1 + k * k), q = main + ring * (1 - k * k), u = ring * 2 * k;
  return Beamsor::stokes_mueller(i, q, u, 0.0);
}

// The ring beam's main part alone, as the split at 5 deg tapers it (from 3.75 deg to 5 deg), over the
// whole 20 deg disc.
Beamsor main_part_beam(double step) {
  return Beamsor::from_field(
      [](double r, double s) {
        pisco::Mueller m = ring_beam(r, s);
        const double t = r <= 3.75 * deg ? 1.0 : r >= 5 * deg ? 0.0 : 0.5 * (1 + std::cos(pi * (r - 3.75 * deg) / (1.25 * deg)));
        for (auto& row : m)
          for (double& e : row) e *= t;
        return m;
      },
      20 * deg, step, "main part");
}

pisco::Sky test_sky(int nside, bool monopole, int lmax = 0) {
  pisco::Spectra cls;
  if (lmax == 0) lmax = 3 * nside - 1;
  for (auto* v : {&cls.TT, &cls.EE, &cls.BB, &cls.TE, &cls.EB, &cls.TB}) v->assign(std::size_t(lmax) + 1, 0.0);
  for (int l = 2; l <= lmax; ++l) {
    cls.TT[std::size_t(l)] = 1.0 / (l * (l + 1.0));
    cls.EE[std::size_t(l)] = 0.1 / (l * (l + 1.0));
    cls.BB[std::size_t(l)] = 0.03 / (l * (l + 1.0));
  }
  pisco::Sky sky = pisco::synthesize_sky(cls, nside, 5);
  if (monopole) {
    const Healpix_Base base(nside, RING, SET_NSIDE);
    for (std::size_t p = 0; p < sky.I().size(); ++p) {
      const pointing a = base.pix2ang(static_cast<int>(p));
      sky.I()[p] += 100.0 + 3.0 * std::cos(a.theta) + 1.5 * std::sin(a.theta) * std::cos(a.phi);
    }
  }
  return sky;
}

pisco::Pointing test_pointing(std::size_t n) {
  std::mt19937 g(3);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing p;
  for (std::size_t i = 0; i < n; ++i) {
    // Across both poles too: a tenth of the samples within 15 deg of one.
    const double theta = i % 10 == 0 ? (i % 20 == 0 ? 15 * deg * u(g) : pi - 15 * deg * u(g)) : std::acos(2 * u(g) - 1);
    p.push_back(theta, 2 * pi * u(g), 2 * pi * u(g) - pi);
  }
  return p;
}

double rms(const std::vector<double>& a) {
  double s = 0;
  for (double x : a) s += x * x;
  return std::sqrt(s / double(a.size()));
}

class Sidelobes : public ::testing::TestWithParam<std::string> {};

TEST_P(Sidelobes, SplitPathMatchesTheWholeDisc) {
  const std::string backend = GetParam();
  const std::string why = pisco_test::backend_unavailable(backend);
  if (!why.empty()) GTEST_SKIP() << backend << ": " << why;
  const int nside = 256;
  const double step = 0.05 * deg;
  const Beamsor whole = Beamsor::from_field(ring_beam, 20 * deg, step, "ring beam");
  pisco::SidelobeSplit split;
  split.rho_main = 5 * deg;
  const Beamsor parted = Beamsor::from_field(ring_beam, 20 * deg, step, "ring beam", 0.0, false, split);
  ASSERT_NE(parted.sidelobes(), nullptr);
  EXPECT_DOUBLE_EQ(parted.rho_max(), 5 * deg);
  EXPECT_NEAR(parted.omega_tilde() / whole.omega_tilde(), 1.0, 1e-9);
  // The main part alone, with the whole beam's normalization: the full-disc TOD of the split's main part.
  const Beamsor main_only = main_part_beam(step);
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "d";
  d.zeta = 0.3;
  fp.add(d);
  pisco::EngineOptions o;
  o.backend = backend;
  const pisco::Pointing p = test_pointing(backend == "cpu" ? 1000 : 3000);
  for (const bool monopole : {false, true}) {
    const pisco::Sky sky = test_sky(nside, monopole);
    std::vector<double> full(p.size()), fast(p.size()), main_part(p.size());
    pisco::Engine(sky, {whole}, fp, o).convolve(0, p, full);
    pisco::Engine split_engine(sky, {parted}, fp, o);
    split_engine.convolve(0, p, fast);
    pisco::Engine(sky, {main_only}, fp, o).convolve(0, p, main_part);
    std::vector<double> side(p.size()), err(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
      // main_part was normalized by its own Omega~; with the whole beam's it is main_part * that ratio.
      side[i] = full[i] - main_part[i] * main_only.omega_tilde() / whole.omega_tilde();
      err[i] = fast[i] - full[i];
    }
    const double ratio = rms(err) / rms(side);
    std::printf("%s, %s sky NSIDE %d: sidelobes on NSIDE %d (band limit %d); split vs whole disc: %.2e of the sidelobes' "
                "part (rms %.3e), %.2e of the TOD\n",
                backend.c_str(), monopole ? "monopole + dipole +" : "random", nside, split_engine.sidelobe_nside(),
                parted.sidelobe_band_limit(), ratio, rms(side), rms(err) / rms(full));
    EXPECT_LE(ratio, 1e-3);
    EXPECT_LT(split_engine.sidelobe_nside(), nside);
  }
}

// The outer parts at the poles (docs/physics.md, "The quadrature"): summed on the coarse sky's own
// polar copy, as the whole beam is on the sky's, the split agrees with the whole disc there as well as
// elsewhere. Every sample is within 12 deg of a pole (both), the sky a monopole, a dipole and power up
// to l = NSIDE (where both polar copies are exact to 1e-5, so what is left is the split's own
// error). Without the coarse sky's copy, the plain sum's end term at the coarse pole gave 2.0e-4 of
// the sidelobes' part (rms) and 4.3e-4 at worst; with it, 1.9e-5 and 1.3e-4.
TEST_P(Sidelobes, OuterPartsAreRightAtThePoles) {
  const std::string backend = GetParam();
  const std::string why = pisco_test::backend_unavailable(backend);
  if (!why.empty()) GTEST_SKIP() << backend << ": " << why;
  const int nside = 256;
  const double step = 0.05 * deg;
  const Beamsor whole = Beamsor::from_field(ring_beam, 20 * deg, step, "ring beam");
  pisco::SidelobeSplit split;
  split.rho_main = 5 * deg;
  const Beamsor parted = Beamsor::from_field(ring_beam, 20 * deg, step, "ring beam", 0.0, false, split);
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "d";
  d.zeta = 0.3;
  fp.add(d);
  pisco::EngineOptions o;
  o.backend = backend;
  std::mt19937 g(11);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing p;
  const std::size_t n = backend == "cpu" ? 400 : 1200;
  for (std::size_t i = 0; i < n; ++i) {
    const double t = 12 * deg * std::sqrt(u(g));  // uniform over the caps' area
    p.push_back(i % 2 ? t : pi - t, 2 * pi * u(g), 2 * pi * u(g) - pi);
  }
  const pisco::Sky sky = test_sky(nside, true, nside);
  std::vector<double> full(n), fast(n), err(n);
  pisco::Engine(sky, {whole}, fp, o).convolve(0, p, full);
  pisco::Engine split_engine(sky, {parted}, fp, o);
  split_engine.convolve(0, p, fast);
  // The sidelobes' part: the whole beam less its main part, as above (here through the outer part's
  // own RMS, which the ring's 1e-3 of the monopole dominates).
  for (std::size_t i = 0; i < n; ++i) err[i] = fast[i] - full[i];
  double worst = 0;
  for (const double e : err) worst = std::max(worst, std::abs(e));
  // The sidelobes' share of the TOD: the ring's integral over the whole beam's, times the TOD.
  const double side = rms(full) * (1.0 - main_part_beam(step).omega_tilde() / whole.omega_tilde());
  std::printf("%s, samples within 12 deg of the poles: split vs whole disc %.2e (rms), %.2e (worst) of the sidelobes' "
              "part (%.3e), %.2e of the TOD\n",
              backend.c_str(), rms(err) / side, worst / side, side, rms(err) / rms(full));
  EXPECT_LE(rms(err) / side, 5e-5);
  EXPECT_LE(worst / side, 2.5e-4);
}

INSTANTIATE_TEST_SUITE_P(Backends, Sidelobes, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

TEST(SidelobeSplit, BadSplitsNameTheProblem) {
  pisco::SidelobeSplit s;
  s.rho_main = 25 * deg;
  try {
    Beamsor::from_field(ring_beam, 20 * deg, 0.2 * deg, "ring", 0.0, false, s);
    FAIL();
  } catch (const pisco::Error& e) {
    EXPECT_EQ(e.key(), "split.rho_main");
    EXPECT_NE(std::string(e.what()).find("25 deg must lie in (0, rho_max = 20 deg)"), std::string::npos) << e.what();
  }
  s.rho_main = 5 * deg;
  s.nside = 100;
  EXPECT_THROW(Beamsor::from_field(ring_beam, 20 * deg, 0.2 * deg, "ring", 0.0, false, s), pisco::Error);
}

}  // namespace
