// A1-A2 (docs/validation.md, "A"): the trigonometry-free antenna coordinates and polarization angle of
// kernel/contribution.hpp against the paper's Appendix A (spherical trigonometry).
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>
#include <random>

#include "kernel/contribution.hpp"
#include "kernel/grid_curvature.hpp"
#include "pisco/units.hpp"

namespace {

using pisco::detail::make_frame;
using pisco::detail::pixel_geometry;
using pisco::detail::SampleFrame;
using pisco::detail::Vec3;

constexpr double pi = std::numbers::pi;
using pisco::deg;

double angle_diff(double a, double b) { return std::remainder(a - b, 2 * pi); }

SampleFrame<double> frame(double theta0, double phi0, double psi0, double zeta) {
  return make_frame(std::cos(theta0), std::sin(theta0), std::cos(phi0), std::sin(phi0), std::cos(psi0),
                    std::sin(psi0), std::cos(zeta), std::sin(zeta));
}

Vec3<double> direction(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

// The paper's Appendix A: rho, sigma and chi by spherical trigonometry, evaluated in long double so
// that its cancellations near the poles do not limit the comparison.
struct AppendixA {
  double rho, sigma, chi;
};
AppendixA appendix_a(long double theta0, long double phi0, long double psi0, long double zeta,
                     long double theta, long double phi) {
  using std::atan2, std::cos, std::sin, std::acos;
  const long double pi_l = 3.141592653589793238462643383279502884L;
  const long double dphi = phi - phi0;
  const long double alpha = atan2(sin(theta) * sin(dphi), cos(theta) * sin(theta0) - sin(theta) * cos(theta0) * cos(dphi));
  const long double sigma = pi_l - psi0 - alpha;
  const long double beta = atan2(sin(theta0) * sin(dphi), cos(theta0) * sin(theta) - sin(theta0) * cos(theta) * cos(dphi));
  AppendixA r;
  r.rho = double(acos(cos(theta) * cos(theta0) + sin(theta) * sin(theta0) * cos(dphi)));
  r.sigma = double(sigma);
  r.chi = double(beta + zeta - sigma);
  return r;
}

// A random sky direction at angular distance rho from (theta0, phi0) in direction `bearing`.
Vec3<double> offset(double theta0, double phi0, double rho, double bearing) {
  const Vec3<double> p = direction(theta0, phi0);
  const Vec3<double> th{std::cos(theta0) * std::cos(phi0), std::cos(theta0) * std::sin(phi0), -std::sin(theta0)};
  const Vec3<double> ph{-std::sin(phi0), std::cos(phi0), 0};
  const double c = std::cos(rho), s = std::sin(rho);
  return {c * p.x + s * (std::cos(bearing) * th.x + std::sin(bearing) * ph.x),
          c * p.y + s * (std::cos(bearing) * th.y + std::sin(bearing) * ph.y),
          c * p.z + s * (std::cos(bearing) * th.z + std::sin(bearing) * ph.z)};
}

void check_random(double theta_lo, double theta_hi, int n, std::uint64_t seed, const char* label) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  double max_rho = 0, max_sigma = 0, max_chi = 0;
  for (int i = 0; i < n; ++i) {
    const double theta0 = theta_lo + (theta_hi - theta_lo) * u(rng);
    const double phi0 = 2 * pi * u(rng), psi0 = 2 * pi * u(rng) - pi, zeta = 2 * pi * u(rng) - pi;
    const double rho = (0.5 + 29.5 * u(rng)) * deg;
    const Vec3<double> k = offset(theta0, phi0, rho, 2 * pi * u(rng));
    const double theta = std::atan2(std::hypot(k.x, k.y), k.z), phi = std::atan2(k.y, k.x);
    if (std::sin(theta) < 1e-6) continue;  // chi is undefined at the sky poles
    const auto g = pixel_geometry(frame(theta0, phi0, psi0, zeta), k);
    const AppendixA a = appendix_a(theta0, phi0, psi0, zeta, theta, phi);
    const double our_rho = std::atan2(std::hypot(g.x, g.y), g.z);
    const double our_sigma = std::atan2(g.y, g.x);
    const double our_2chi = std::atan2(g.sin2chi, g.cos2chi);
    max_rho = std::max(max_rho, std::abs(our_rho - a.rho));
    max_sigma = std::max(max_sigma, std::abs(angle_diff(our_sigma, a.sigma)));
    max_chi = std::max(max_chi, std::abs(angle_diff(our_2chi, 2 * a.chi)) / 2);
    EXPECT_NEAR(g.cos2chi * g.cos2chi + g.sin2chi * g.sin2chi, 1.0, 1e-14);
  }
  std::cout << "A1 " << label << ": max |d rho| " << max_rho << ", |d sigma| " << max_sigma
            << ", |d chi| " << max_chi << " rad over " << n << " configurations (bar 1e-12)\n";
  EXPECT_LT(max_rho, 1e-12);
  EXPECT_LT(max_sigma, 1e-12);
  EXPECT_LT(max_chi, 1e-12);
}

TEST(Geometry, AgreesWithAppendixAEverywhere) { check_random(0.0, pi, 20000, 1, "full sky"); }
TEST(Geometry, AgreesWithAppendixANearNorthPole) { check_random(1e-4, 1 * deg, 5000, 2, "within 1 deg of the north pole"); }
TEST(Geometry, AgreesWithAppendixANearSouthPole) { check_random(pi - 1 * deg, pi - 1e-4, 5000, 3, "within 1 deg of the south pole"); }

TEST(Geometry, BeamCentreChiIsPsiPlusZeta) {
  // A2: at the beam centre chi = psi0 + zeta, (x, y, z) = (0, 0, 1).
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(0, 1);
  double worst = 0;
  for (int i = 0; i < 5000; ++i) {
    const double theta0 = std::acos(1 - 2 * u(rng)), phi0 = 2 * pi * u(rng);
    const double psi0 = 2 * pi * u(rng), zeta = 2 * pi * u(rng);
    const auto g = pixel_geometry(frame(theta0, phi0, psi0, zeta), direction(theta0, phi0));
    worst = std::max({worst, std::abs(g.x), std::abs(g.y), std::abs(g.z - 1),
                      std::abs(g.cos2chi - std::cos(2 * (psi0 + zeta))),
                      std::abs(g.sin2chi - std::sin(2 * (psi0 + zeta)))});
  }
  std::cout << "A2 beam centre: max deviation from chi = psi0 + zeta " << worst << "\n";
  EXPECT_LT(worst, 1e-13);
}

TEST(Geometry, IdealDetectorResponse) {
  // A2: with w = s/2 [(1+eps), (1-eps), 0, 0] the response is
  // s/2 [(1+eps) I + (1-eps)(Q cos 2chi + U sin 2chi)].
  const double s = 1.3, eps = 0.07, I = 2.0, Q = -0.4, U = 0.9, V = 0.2;
  const pisco::detail::Vec4<double> w{s / 2 * (1 + eps), s / 2 * (1 - eps), 0, 0};
  for (double chi : {0.0, 0.3, 1.1, 2.5, -0.7}) {
    const double d = pisco::detail::stokes_response(w, std::cos(2 * chi), std::sin(2 * chi),
                                                    pisco::detail::Vec4<double>{I, Q, U, V});
    const double expected = s / 2 * ((1 + eps) * I + (1 - eps) * (Q * std::cos(2 * chi) + U * std::sin(2 * chi)));
    EXPECT_NEAR(d, expected, 1e-15);
  }
}

TEST(Geometry, GridInterpolationIsExactForQuadraticFields) {
  // The grid's interpolation (bilinear less the edges' curvature terms, src/kernel/grid_curvature.hpp):
  // a field f = a + b x + c y + d x y is reproduced exactly inside every cell, and one with x^2 and y^2
  // terms too inside every cell whose edges' second differences are all interior.
  const int n = 7;
  const double a = 0.5, step = 2 * a / (n - 1);
  for (const double q : {0.0, 1.0}) {
    std::vector<double> grid(n * n * 4);
    auto f = [q](double x, double y, int m) {
      return 1.0 + m + (2.0 - m) * x - 0.5 * y + 3.0 * m * x * y + q * (2.5 * x * x - (1.0 + m) * y * y);
    };
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (int m = 0; m < 4; ++m) grid[(j * n + i) * 4 + m] = f(-a + i * step, -a + j * step, m);
    pisco::detail::append_edge_curvature(grid, n, 4);
    const pisco::detail::ArrayGrid<double> g{grid.data(), n, a, 1 / step};
    std::mt19937_64 rng(5);
    const double within = q == 0.0 ? a : a - step;
    std::uniform_real_distribution<double> u(-within, within);
    for (int t = 0; t < 1000; ++t) {
      const double x = u(rng), y = u(rng);
      const auto w = pisco::detail::interpolate_weights(g, x, y);
      const double wm[4] = {w.x, w.y, w.z, w.w};
      for (int m = 0; m < 4; ++m) EXPECT_NEAR(wm[m], f(x, y, m), 1e-13) << "q " << q;
    }
  }
  // Outside the grid, a NaN included: zero (a grid of ones, 1 within it).
  std::vector<double> grid(n * n * 4, 1.0);
  pisco::detail::append_edge_curvature(grid, n, 4);
  const pisco::detail::ArrayGrid<double> g{grid.data(), n, a, 1 / step};
  EXPECT_EQ(pisco::detail::interpolate_weights(g, 0.3 * a, -0.2 * a).x, 1.0);
  for (const double x : {a * 1.01, -a * 1.01, std::nan("")}) {
    const auto w = pisco::detail::interpolate_weights(g, x, 0.0);
    EXPECT_EQ(w.x, 0.0);
    EXPECT_EQ(w.w, 0.0);
  }
}

}  // namespace
