// A4 (docs/validation.md, "A") and the beamsor builders: the integral normalization against an independent
// quadrature of the analytic profile, grid sampling, cross-polar terms and input errors.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <numbers>
#include <random>

#include "support.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"
#include "pisco/units.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;
const double fwhm_to_sigma = 1.0 / std::sqrt(8 * std::log(2.0));

// Adaptive Simpson: independent of the builder's composite Gauss-Legendre rule.
double simpson(const std::function<double(double)>& f, double a, double b, double fa, double fm,
               double fb, double whole, double tol, int depth) {
  const double m = 0.5 * (a + b), lm = 0.5 * (a + m), rm = 0.5 * (m + b);
  const double flm = f(lm), frm = f(rm);
  const double left = (m - a) / 6 * (fa + 4 * flm + fm), right = (b - m) / 6 * (fm + 4 * frm + fb);
  if (depth <= 0 || std::abs(left + right - whole) <= 15 * tol) return left + right + (left + right - whole) / 15;
  return simpson(f, a, m, fa, flm, fm, left, tol / 2, depth - 1) +
         simpson(f, m, b, fm, frm, fb, right, tol / 2, depth - 1);
}
double integrate(const std::function<double(double)>& f, double a, double b, double tol) {
  const double fa = f(a), fb = f(b), fm = f(0.5 * (a + b));
  return simpson(f, a, b, fa, fm, fb, (b - a) / 6 * (fa + 4 * fm + fb), tol, 30);
}

// Omega~ of an elliptical Gaussian over the cap: the sigma integral in closed form,
// 2 pi exp(-rho^2 (A+B)/2) I0(rho^2 (A-B)/2), then adaptive Simpson in rho.
double reference_omega(double fwhm_x, double fwhm_y, double rho_max) {
  const double sx = fwhm_x * fwhm_to_sigma, sy = fwhm_y * fwhm_to_sigma;
  const double A = 0.5 / (sx * sx), B = 0.5 / (sy * sy);
  auto f = [&](double rho) {
    const double r2 = rho * rho;
    return 2 * pi * std::exp(-r2 * (A + B) / 2) * std::cyl_bessel_i(0.0, r2 * std::abs(A - B) / 2) * std::sin(rho);
  };
  // Sub-intervals of half the smallest width, so that no adaptive step can miss the peak.
  const int parts = static_cast<int>(std::ceil(rho_max / (0.5 * std::min(sx, sy))));
  double total = 0;
  const double tol = 1e-12 * 2 * pi * sx * sy / parts;  // 1e-12 of the flat-sky Omega~ overall
  for (int i = 0; i < parts; ++i) total += integrate(f, rho_max * i / parts, rho_max * (i + 1) / parts, tol);
  return total;
}

TEST(Beamsor, CircularNormalizationA4) {
  for (double fwhm_deg : {0.5, 1.5, 5.0}) {
    for (double rho_deg : {5.0, 10.0, 30.0}) {
      if (fwhm_deg / 2 >= rho_deg) continue;
      pisco::BeamOptions o;
      o.rho_max = rho_deg * deg;
      o.grid_step = fwhm_deg * deg / 5;  // the grid does not enter the normalization
      const auto b = pisco::Beamsor::gaussian(fwhm_deg * deg, o);
      const double ref = reference_omega(fwhm_deg * deg, fwhm_deg * deg, rho_deg * deg);
      const double rel = std::abs(b.omega_tilde() / ref - 1);
      std::cout << "A4 circular FWHM " << fwhm_deg << " deg, rho_max " << rho_deg
                << " deg: Omega~ " << b.omega_tilde() << " sr, reference " << ref << ", rel. diff " << rel
                << " (bar 1e-6)\n";
      EXPECT_LT(rel, 1e-6);
    }
  }
}

TEST(Beamsor, EllipticalNormalizationA4) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 8; ++i) {
    const double fx = (0.8 + 2 * u(rng)) * deg, fy = (0.8 + 2 * u(rng)) * deg, angle = pi * u(rng);
    pisco::BeamOptions o;
    o.rho_max = (6 + 20 * u(rng)) * deg;
    o.grid_step = 0.2 * deg;
    const auto b = pisco::Beamsor::elliptical_gaussian(fx, fy, angle, o);
    const double ref = reference_omega(fx, fy, o.rho_max);
    const double rel = std::abs(b.omega_tilde() / ref - 1);
    std::cout << "A4 elliptical " << fx / deg << " x " << fy / deg << " deg at " << angle / deg
              << " deg, rho_max " << o.rho_max / deg << " deg: rel. diff " << rel << " (bar 1e-6)\n";
    EXPECT_LT(rel, 1e-6);
  }
}

TEST(Beamsor, CrossPolarNormalizationIncludesItsPower) {
  pisco::BeamOptions o;
  o.cross_polar = 0.2;
  const auto b = pisco::Beamsor::gaussian(1.5 * deg, o);
  const double ref = (1 + 0.04) * reference_omega(1.5 * deg, 1.5 * deg, o.rho_max);
  EXPECT_LT(std::abs(b.omega_tilde() / ref - 1), 1e-6);
  // X(kappa) = (1 + k^2) R(atan k): Q -> U coupling 2k, U -> Q coupling -2k, QQ = 1 - k^2.
  const auto m = b.at(0, 0);
  EXPECT_NEAR(m[0][0], 1.04, 2e-3);  // the beam peak (1) times 1 + kappa^2
  EXPECT_NEAR(m[1][1] / m[0][0], (1 - 0.04) / 1.04, 1e-12);
  EXPECT_NEAR(m[1][2] / m[0][0], 0.4 / 1.04, 1e-12);
  EXPECT_NEAR(m[2][1] / m[0][0], -0.4 / 1.04, 1e-12);
  EXPECT_TRUE(b.has_element(1, 2));
  EXPECT_FALSE(b.has_element(0, 1));
  // The quadrupole pattern vanishes on the axes sigma = 0, 90 deg and peaks at 45 deg.
  o.cross_polar_pattern = pisco::CrossPolarPattern::quadrupole;
  const auto q = pisco::Beamsor::gaussian(1.5 * deg, o);
  // kappa(rho, sigma) = kappa sin(2 sigma) (rho^2 / 2 s^2) exp(1 - rho^2 / 2 s^2): zero on the axis,
  // largest (kappa) at rho = sqrt(2) s on the diagonals.
  const double s_beam = 1.5 * deg * fwhm_to_sigma, r = std::sin(std::sqrt(2.0) * s_beam);
  EXPECT_NEAR(q.at(r, 0)[1][2], 0.0, 1e-12);
  EXPECT_NEAR(q.at(0, 0)[1][2], 0.0, 1e-12);
  const auto diag = q.at(r / std::sqrt(2.0), r / std::sqrt(2.0));
  EXPECT_NEAR(diag[1][2] / diag[0][0], 0.4 / 1.04, 4e-3);  // bilinear interpolation between nodes
}

TEST(Beamsor, GridSamplesTheProfile) {
  pisco::BeamOptions o;
  o.rho_max = 5 * deg;
  const double fwhm = 1.5 * deg;
  const auto b = pisco::Beamsor::elliptical_gaussian(fwhm, 0.8 * fwhm, 30 * deg, o);
  EXPECT_LE(b.grid_step(), fwhm * 0.8 / 16 * (1 + 1e-12));  // default: 1/16 of the smallest FWHM
  EXPECT_NEAR(b.grid_half_width(), std::sin(5 * deg), 1e-15);
  EXPECT_EQ(b.grid_size() % 1, 0);
  // At the nodes the interpolant equals the analytic profile.
  const int n = b.grid_size();
  const double sx = fwhm * fwhm_to_sigma, sy = 0.8 * fwhm * fwhm_to_sigma;
  double worst = 0;
  for (int j = 0; j < n; j += 7)
    for (int i = 0; i < n; i += 5) {
      const double x = -b.grid_half_width() + i * b.grid_step(), y = -b.grid_half_width() + j * b.grid_step();
      if (x * x + y * y > b.grid_half_width() * b.grid_half_width()) continue;
      const double rho = std::asin(std::hypot(x, y)), sigma = std::atan2(y, x);
      const double u = rho * std::cos(sigma - 30 * deg), v = rho * std::sin(sigma - 30 * deg);
      const double expected = std::exp(-u * u / (2 * sx * sx) - v * v / (2 * sy * sy));
      worst = std::max(worst, std::abs(b.at(x, y)[0][0] - expected));
      EXPECT_NEAR(b.at(x, y)[3][3], b.at(x, y)[0][0], 0.0);
    }
  EXPECT_LT(worst, 1e-14);
  // Between nodes the interpolation (bilinear less the edges' curvature terms, docs/physics.md,
  // "Interpolation on the grid") errs at order step^3: 5.4e-5 of the peak at the default step, where
  // bilinear interpolation alone erred by up to step^2/8 |b''|, 2e-3 of the peak at FWHM / 20.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u01(-1, 1);
  double between = 0;
  for (int t = 0; t < 20000; ++t) {
    const double x = u01(rng) * 2 * fwhm, y = u01(rng) * 2 * fwhm;
    const double rho = std::asin(std::hypot(x, y)), sigma = std::atan2(y, x);
    const double uu = rho * std::cos(sigma - 30 * deg), vv = rho * std::sin(sigma - 30 * deg);
    between = std::max(between, std::abs(b.at(x, y)[0][0] - std::exp(-uu * uu / (2 * sx * sx) - vv * vv / (2 * sy * sy))));
  }
  std::cout << "interpolation error at the default grid step: " << between << " of the peak\n";
  EXPECT_LT(between, 1e-4);
  // Outside rho_max the beamsor is zero.
  EXPECT_EQ(b.at(std::sin(5.1 * deg), 0)[0][0], 0.0);
}

TEST(Beamsor, ConstantMuellerMatrix) {
  pisco::BeamOptions o;
  o.mueller = pisco::identity_mueller();
  o.mueller[1][0] = 0.01;  // T -> Q leakage (B_TQ)
  const auto b = pisco::Beamsor::gaussian(1.5 * deg, o);
  EXPECT_TRUE(b.has_element(1, 0));
  EXPECT_NEAR(b.at(0, 0)[1][0] / b.at(0, 0)[0][0], 0.01, 1e-15);
}

TEST(Beamsor, BadInputsAreRejected) {
  const auto message = pisco_test::error_of;
  pisco::BeamOptions o;
  EXPECT_NE(message([&] { pisco::Beamsor::gaussian(-1 * deg, o); }).find("fwhm"), std::string::npos);
  EXPECT_NE(message([&] { pisco::Beamsor::gaussian(NAN, o); }).find("fwhm"), std::string::npos);
  EXPECT_NE(message([&] { pisco::Beamsor::gaussian(12 * deg, o); }).find("wider than the beam grid"), std::string::npos);
  o.rho_max = 90 * deg;
  EXPECT_NE(message([&] { pisco::Beamsor::gaussian(1.5 * deg, o); }).find("rho_max"), std::string::npos);
  o.rho_max = 5 * deg;
  o.grid_step = 1e-6;
  EXPECT_NE(message([&] { pisco::Beamsor::gaussian(1.5 * deg, o); }).find("nodes"), std::string::npos);
}

}  // namespace
