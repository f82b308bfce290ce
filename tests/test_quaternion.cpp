// Quaternion pointing (include/pisco/quaternion.hpp, pointing.hpp): the ZYZ angles and their inverse,
// the two spellings of a detector offset, and the host-side expansion of boresight quaternions
// against the expansion of the same pointing given as angles.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <random>

#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/units.hpp"
#include "support.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;
using V = std::array<double, 3>;

V theta_hat(double t, double p) { return {std::cos(t) * std::cos(p), std::cos(t) * std::sin(p), -std::sin(t)}; }
V phi_hat(double p) { return {-std::sin(p), std::cos(p), 0.0}; }
V direction(double t, double p) { return {std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)}; }
double distance(const V& a, const V& b) { return std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]); }

// The difference of two angles, wrapped into (-pi, pi].
double angle_diff(double a, double b) { return std::remainder(a - b, 2 * pi); }

TEST(Quaternion, ZyzAnglesMapTheAxesOntoTheAntennaBasis) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 2000; ++i) {
    const double t = std::acos(1 - 2 * u(rng)), p = 2 * pi * u(rng), s = 2 * pi * u(rng) - pi;
    const pisco::Quat q = pisco::quat_from_pointing(t, p, s);
    EXPECT_NEAR(pisco::norm(q), 1.0, 1e-15);
    const V th = theta_hat(t, p), ph = phi_hat(p);
    const V want_x{std::cos(s) * th[0] + std::sin(s) * ph[0], std::cos(s) * th[1] + std::sin(s) * ph[1],
                   std::cos(s) * th[2] + std::sin(s) * ph[2]};
    EXPECT_LT(distance(pisco::rotate(q, {0, 0, 1}), direction(t, p)), 1e-15);
    EXPECT_LT(distance(pisco::rotate(q, {1, 0, 0}), want_x), 1e-15);
    double t2, p2, s2;
    pisco::quat_to_pointing(q, t2, p2, s2);
    EXPECT_NEAR(t2, t, 1e-13);
    EXPECT_NEAR(angle_diff(p2, p), 0.0, 1e-12 / std::max(std::sin(t), 1e-3));
    EXPECT_NEAR(angle_diff(s2, s), 0.0, 1e-12 / std::max(std::sin(t), 1e-3));
    EXPECT_GE(p2, 0.0);
    EXPECT_LT(p2, 2 * pi);
  }
}

TEST(Quaternion, ProductComposesRotations) {
  const pisco::Quat a = pisco::quat_from_axis_angle({0, 0, 1}, 0.7), b = pisco::quat_from_axis_angle({0, 1, 0}, -0.4);
  const V v{0.3, -0.5, 0.8};
  const V ab = pisco::rotate(a * b, v), a_of_b = pisco::rotate(a, pisco::rotate(b, v));
  EXPECT_LT(distance(ab, a_of_b), 1e-15);
  const pisco::Quat id = a * pisco::conjugate(a);
  EXPECT_NEAR(id.w, 1.0, 1e-16);
  pisco_test::expect_error([] { pisco::normalized({0, 0, 0, 0}); }, "cannot be normalized");
}

TEST(Quaternion, OffsetSpellingsAgree) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 2000; ++i) {
    const double xi = 20 * deg * u(rng), eta = 20 * deg * u(rng), gamma = pi * u(rng);
    const pisco::Quat q = pisco::offset_quat(xi, eta, gamma);
    // The line of sight at distance r towards atan2(eta, xi) from theta' (x^) towards phi' (y^).
    const double r = std::hypot(xi, eta), a = std::atan2(eta, xi);
    EXPECT_LT(distance(pisco::rotate(q, {0, 0, 1}), {std::sin(r) * std::cos(a), std::sin(r) * std::sin(a), std::cos(r)}),
              1e-15);
    double xi2, eta2, gamma2;
    pisco::offset_from_quat(q, xi2, eta2, gamma2);
    EXPECT_NEAR(xi2, xi, 1e-14);
    EXPECT_NEAR(eta2, eta, 1e-14);
    EXPECT_NEAR(angle_diff(gamma2, gamma), 0.0, 1e-13);
    pisco::Detector d;
    d.set_offset(xi, eta, gamma);
    EXPECT_TRUE(d.has_offset());
    d.offset_xi_eta_gamma(xi2, eta2, gamma2);
    EXPECT_NEAR(xi2, xi, 1e-14);
  }
  // gamma alone turns theta' about the line of sight.
  const pisco::Quat g = pisco::offset_quat(0, 0, 30 * deg);
  EXPECT_LT(distance(pisco::rotate(g, {1, 0, 0}), {std::cos(30 * deg), std::sin(30 * deg), 0}), 1e-15);
  EXPECT_FALSE(pisco::Detector{}.has_offset());
}

// A boresight given as quaternions and as the same pointing in angles: one expansion, for detectors
// on and off the boresight, within 1e-13 rad (line of sight) and 1e-12 rad (orientation).
TEST(Quaternion, ExpansionOfQuaternionsEqualsExpansionOfAngles) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing b;
  for (int i = 0; i < 3000; ++i) b.push_back(std::acos(1 - 2 * u(rng)), 2 * pi * u(rng), 2 * pi * u(rng) - pi);
  for (int i = 0; i < 200; ++i) b.push_back(u(rng) * 2 * deg, 2 * pi * u(rng), 2 * pi * u(rng));  // near a pole
  std::vector<pisco::Quat> q;
  for (std::size_t i = 0; i < b.size(); ++i) q.push_back(pisco::quat_from_pointing(b.theta[i], b.phi[i], b.psi[i]));
  for (const pisco::Quat offset : {pisco::Quat{}, pisco::offset_quat(3 * deg, -1.5 * deg, 0.4),
                                   pisco::offset_quat(-12 * deg, 7 * deg, -2.0)}) {
    pisco::Pointing from_angles, from_quats;
    pisco::detector_pointing(b.view(), offset, from_angles);
    pisco::detector_pointing(pisco::QuatPointingView{q}, offset, from_quats);
    ASSERT_EQ(from_angles.size(), b.size());
    double worst_los = 0, worst_psi = 0;
    for (std::size_t i = 0; i < b.size(); ++i) {
      const double t = from_angles.theta[i], p = from_angles.phi[i];
      worst_los = std::max(worst_los, distance(direction(t, p), direction(from_quats.theta[i], from_quats.phi[i])));
      if (std::sin(t) > 1e-3) worst_psi = std::max(worst_psi, std::abs(angle_diff(from_angles.psi[i], from_quats.psi[i])));
    }
    EXPECT_LT(worst_los, 1e-13);
    EXPECT_LT(worst_psi, 1e-11);
  }
}

TEST(Quaternion, BadQuaternionsAreNamed) {
  std::vector<pisco::Quat> q(10);
  q[4] = {0, 0, 0, 1.1};
  pisco_test::expect_error([&] { pisco::check_pointing(pisco::QuatPointingView{q}, "boresight"); }, "sample 4");
  q[4] = {NAN, 0, 0, 1};
  pisco_test::expect_error([&] { pisco::check_pointing(pisco::QuatPointingView{q}, "boresight"); }, "non-finite");
}

}  // namespace
