// The kernels' float64 sine, cosine and arctangent (src/kernel/fp64.glsl, compiled here as C++) against
// the C library, over the arguments the kernels give them: within 2 ulp, most exactly equal.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

using std::floor;
#include "fp64_host.hpp"  // src/kernel/fp64.glsl

namespace {

double ulps(double got, double want) {
  if (got == want) return 0;
  return std::abs(got - want) / (std::nextafter(std::abs(want), INFINITY) - std::abs(want));
}

TEST(Fp64, SineAndCosineWithinTwoUlp) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-4 * std::numbers::pi, 4 * std::numbers::pi);
  double worst_sin = 0, worst_cos = 0;
  std::size_t exact = 0;
  const std::size_t n = 2000000;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = i < 1000 ? double(i) * std::numbers::pi / 8 : u(rng);
    const double s = pisco_sin(x), c = pisco_cos(x);
    // Near the zeros the result is tiny and only the absolute error is meaningful.
    if (std::abs(std::sin(x)) > 1e-3) worst_sin = std::max(worst_sin, ulps(s, std::sin(x)));
    if (std::abs(std::cos(x)) > 1e-3) worst_cos = std::max(worst_cos, ulps(c, std::cos(x)));
    EXPECT_LE(std::abs(s - std::sin(x)), 4e-16) << x;
    EXPECT_LE(std::abs(c - std::cos(x)), 4e-16) << x;
    exact += (s == std::sin(x)) + (c == std::cos(x));
  }
  std::cout << "worst sin " << worst_sin << " ulp, cos " << worst_cos << " ulp; "
            << double(exact) / double(2 * n) * 100 << "% bit-identical\n";
  EXPECT_LE(worst_sin, 2.0);
  EXPECT_LE(worst_cos, 2.0);
}

TEST(Fp64, ArcTangentWithinTwoUlp) {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1, 1);
  double worst = 0;
  std::size_t exact = 0;
  const std::size_t n = 2000000;
  for (std::size_t i = 0; i < n; ++i) {
    const double y = std::abs(u(rng)) * std::pow(10.0, 3 * u(rng));
    const double x = u(rng) * std::pow(10.0, 3 * u(rng));
    const double got = pisco_atan2_nonneg_y(y, x), want = std::atan2(y, x);
    worst = std::max(worst, ulps(got, want));
    exact += got == want;
  }
  for (double x : {0.4375, 0.6875, 1.1875, 2.4375, 1.0, 0.0, -1.0})
    EXPECT_LE(ulps(pisco_atan2_nonneg_y(x < 0 ? -x : 1.0, x), std::atan2(x < 0 ? -x : 1.0, x)), 2.0) << x;
  EXPECT_EQ(pisco_atan2_nonneg_y(0.0, 1.0), 0.0);
  EXPECT_EQ(pisco_atan2_nonneg_y(1.0, 0.0), std::numbers::pi / 2);
  std::cout << "worst atan2 " << worst << " ulp; " << double(exact) / double(n) * 100 << "% bit-identical\n";
  EXPECT_LE(worst, 2.0);
}

}  // namespace
