// The pair mismatch metrics of paper 7.1.5 (pisco/mismatch.hpp) against closed forms and 1D root
// finding done here independently.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>

#include "pisco/error.hpp"
#include "pisco/mismatch.hpp"
#include "pisco/units.hpp"

namespace {

using pisco::BeamNormalization;
using pisco::GaussianBeamShape;
constexpr double pi = std::numbers::pi;
const double to_sigma = 1.0 / std::sqrt(8.0 * std::log(2.0));

GaussianBeamShape round_beam(double fwhm, double xi = 0, double eta = 0) { return {fwhm, fwhm, 0.0, xi, eta}; }

// Two concentric round Gaussians of widths s1 < s2, each of peak 1: |exp(-u/2s2^2) - exp(-u/2s1^2)|,
// u = r^2, is largest where its derivative in u vanishes, u* = ln(a/b) / (a - b).
double concentric_peak_delta(double s1, double s2) {
  const double a = 0.5 / (s1 * s1), b = 0.5 / (s2 * s2);
  const double u = std::log(a / b) / (a - b);
  return std::exp(-b * u) - std::exp(-a * u);
}

// Two round Gaussians of width s, centres +-h apart along a line: the maximum lies on that line at
// the root x in (0, s + h) of d/dx [exp(-(x-h)^2/2s^2) - exp(-(x+h)^2/2s^2)]; bisection.
double offset_delta(double s, double h) {
  auto f = [&](double x) { return std::exp(-(x - h) * (x - h) / (2 * s * s)) - std::exp(-(x + h) * (x + h) / (2 * s * s)); };
  auto df = [&](double x) {
    return -(x - h) * std::exp(-(x - h) * (x - h) / (2 * s * s)) + (x + h) * std::exp(-(x + h) * (x + h) / (2 * s * s));
  };
  double lo = 0.0, hi = s + h;  // df(lo) > 0 > df(hi)
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (df(mid) > 0 ? lo : hi) = mid;
  }
  return f(0.5 * (lo + hi));
}

}  // namespace

TEST(Mismatch, ConcentricRoundBeamsPeakNormalized) {
  for (double ratio : {1.001, 1.02, 1.3}) {
    const double f1 = 1.5 * pisco::deg, f2 = f1 * ratio;
    const auto m = pisco::beam_difference_maximum(round_beam(f1), round_beam(f2));
    const double expected = concentric_peak_delta(f1 * to_sigma, f2 * to_sigma);
    std::printf("concentric, FWHM ratio %.3f: delta %.15g, closed form %.15g\n", ratio, m.delta, expected);
    EXPECT_NEAR(m.delta, expected, 1e-14 + 1e-12 * expected);
    // On the ring r^2 = u*.
    const double a = 0.5 / std::pow(f1 * to_sigma, 2), b = 0.5 / std::pow(f2 * to_sigma, 2);
    EXPECT_NEAR(std::hypot(m.xi, m.eta), std::sqrt(std::log(a / b) / (a - b)), 1e-6 * f1);
  }
}

TEST(Mismatch, ConcentricRoundBeamsIntegralNormalized) {
  // Unit-integral Gaussians 1/(2 pi s^2) exp(-r^2/2s^2): the difference is largest on the axis,
  // 1/(2 pi s1^2) - 1/(2 pi s2^2), against the mean beam's peak: delta = 2 (s2^2 - s1^2) / (s1^2 + s2^2).
  for (double ratio : {1.001, 1.02, 1.3}) {
    const double s1 = 1.5 * pisco::deg * to_sigma, s2 = s1 * ratio;
    const auto m = pisco::beam_difference_maximum(round_beam(s1 / to_sigma), round_beam(s2 / to_sigma),
                                                  BeamNormalization::integral);
    const double expected = 2 * (s2 * s2 - s1 * s1) / (s1 * s1 + s2 * s2);
    EXPECT_NEAR(m.delta, expected, 1e-12 * expected);
    EXPECT_LT(std::hypot(m.xi, m.eta), 1e-9);
  }
}

TEST(Mismatch, OffsetRoundBeams) {
  const double fwhm = 1.5 * pisco::deg, s = fwhm * to_sigma;
  for (double d_arcsec : {1.0, 16.0, 600.0}) {
    const double d = d_arcsec / 3600 * pisco::deg;
    for (double dir : {0.0, 0.7, 2.5}) {
      const GaussianBeamShape a = round_beam(fwhm, 0.01 - 0.5 * d * std::cos(dir), -0.02 - 0.5 * d * std::sin(dir));
      const GaussianBeamShape b = round_beam(fwhm, 0.01 + 0.5 * d * std::cos(dir), -0.02 + 0.5 * d * std::sin(dir));
      const double expected = offset_delta(s, 0.5 * d);
      for (auto norm : {BeamNormalization::peak, BeamNormalization::integral}) {
        const auto m = pisco::beam_difference_maximum(a, b, norm);
        EXPECT_NEAR(m.delta, expected, 1e-12 * expected) << d_arcsec << " arcsec, direction " << dir;
      }
      // The small-offset limit: (d / s) exp(-1/2).
      if (d_arcsec <= 16.0) EXPECT_NEAR(expected, d / s * std::exp(-0.5), 1e-3 * expected);
    }
  }
  // The paper's delta_p = 0.42% for 1.5 deg beams is a pair offset of about this much:
  const double d = 0.0042 * s / std::exp(-0.5);
  std::printf("delta_p = 0.42%% with FWHM 1.5 deg: pair offset %.2f arcsec\n", d / pisco::deg * 3600);
}

TEST(Mismatch, EllipticalBeamsAtRightAngles) {
  // (fx, fy, 0) against (fx, fy, 90 deg): on circles of r^2 = p + q the difference
  // exp(-B s)[exp(-(A-B)p) - exp(-(A-B)q)] is largest on an axis, where it is the concentric case.
  const double fx = 1.55 * pisco::deg, fy = 1.45 * pisco::deg;
  for (double turn : {0.0, 0.4, -1.2}) {
    const GaussianBeamShape a{fx, fy, turn, 0, 0}, b{fx, fy, turn + pi / 2, 0, 0};
    const auto m = pisco::beam_difference_maximum(a, b);
    EXPECT_NEAR(m.delta, concentric_peak_delta(fy * to_sigma, fx * to_sigma), 1e-13);
  }
  // (fx, fy, t) and (fy, fx, t + 90 deg) are the same beam.
  const GaussianBeamShape a{fx, fy, 0.3, 0.01, 0.02}, b{fy, fx, 0.3 + pi / 2, 0.01, 0.02};
  EXPECT_LT(pisco::beam_difference_maximum(a, b).delta, 1e-15);
}

TEST(Mismatch, RotatingThePairChangesNothing) {
  const GaussianBeamShape a{1.52 * pisco::deg, 1.46 * pisco::deg, 0.2, 0.001, -0.0004};
  const GaussianBeamShape b{1.49 * pisco::deg, 1.55 * pisco::deg, -0.4, -0.0003, 0.0002};
  const double d0 = pisco::beam_difference_maximum(a, b).delta;
  for (double t : {0.3, 1.9, -2.8}) {
    auto turn = [t](GaussianBeamShape g) {
      const double x = g.xi, y = g.eta;
      g.xi = std::cos(t) * x - std::sin(t) * y;
      g.eta = std::sin(t) * x + std::cos(t) * y;
      g.angle += t;
      return g;
    };
    EXPECT_NEAR(pisco::beam_difference_maximum(turn(a), turn(b)).delta, d0, 1e-13);
  }
}

TEST(Mismatch, PairSplitsPointingFromBeam) {
  const double f = 1.5 * pisco::deg, d = 20.0 / 3600 * pisco::deg;
  // Pointing only.
  auto p = pisco::pair_mismatch(round_beam(f, 0, 0), round_beam(f, d, 0));
  EXPECT_DOUBLE_EQ(p.pointing, p.total);
  EXPECT_EQ(p.beam, 0.0);
  EXPECT_NEAR(p.pointing, offset_delta(f * to_sigma, 0.5 * d), 1e-15);
  // Shape only.
  auto b = pisco::pair_mismatch(round_beam(f), round_beam(1.02 * f));
  EXPECT_EQ(b.pointing, 0.0);
  EXPECT_DOUBLE_EQ(b.beam, b.total);
  EXPECT_NEAR(b.beam, concentric_peak_delta(f * to_sigma, 1.02 * f * to_sigma), 1e-14);
  // The mean beam: widths and centres averaged, the axis averaged modulo 180 deg.
  const auto m = pisco::mean_beam({1.0, 2.0, 170 * pisco::deg, 1, 2}, {3.0, 4.0, -10 * pisco::deg, 3, 4});
  EXPECT_DOUBLE_EQ(m.fwhm_x, 2.0);
  EXPECT_DOUBLE_EQ(m.fwhm_y, 3.0);
  EXPECT_NEAR(std::remainder(m.angle - 170 * pisco::deg, pi), 0.0, 1e-15);  // 170 and -10 deg are one axis
  EXPECT_NEAR(pisco::mean_beam({1, 1, 10 * pisco::deg, 0, 0}, {1, 1, 170 * pisco::deg, 0, 0}).angle, 0.0, 1e-15);
  EXPECT_DOUBLE_EQ(m.xi, 2.0);
  EXPECT_DOUBLE_EQ(m.eta, 3.0);
}

TEST(Mismatch, BadBeamsAreErrorsNamingTheKey) {
  try {
    pisco::beam_difference_maximum({-1.0, 1.0, 0, 0, 0}, round_beam(1.0));
    FAIL() << "no error";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("beam a: fwhm_x"), std::string::npos) << e.what();
  }
  EXPECT_THROW(pisco::beam_difference_maximum(round_beam(1.0), {1.0, NAN, 0, 0, 0}), pisco::Error);
  EXPECT_THROW(pisco::pair_mismatch(round_beam(1.0), {1.0, 1.0, 0, INFINITY, 0}), pisco::Error);
}
