// Constant-elevation scans and focal-plane offsets (docs/config.md, "[scan]"), against geometric invariants computed
// independently: the distance to the zenith, the azimuth recovered by the inverse transform, the
// sidereal day, and distances and bearings in the boresight frame.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>
#include <random>

#include "kernel/contribution.hpp"
#include "pisco/pisco.hpp"
#include "pisco/scan.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;

pisco::CesScan class_like() {
  pisco::CesScan s;
  s.latitude = -22.96 * deg;
  s.longitude = -67.79 * deg;
  s.elevation = 45 * deg;
  s.az_centre = 180 * deg;
  s.az_throw = 720 * deg;
  s.az_speed = 1 * deg;
  s.sample_rate = 20;
  s.start_unix = 1559347200;  // 2019-06-01T00:00:00Z
  s.boresight_angles = {-45 * deg, -30 * deg, -15 * deg, 0, 15 * deg, 30 * deg, 45 * deg};
  s.samples = 3 * 86400 * 20;
  return s;
}

double angle_diff(double a, double b) { return std::remainder(a - b, 2 * pi); }

TEST(Ces, ElevationAzimuthAndUpAxis) {
  const pisco::CesScan s = class_like();
  pisco::Pointing p;
  const std::size_t step = 997;
  double worst_el = 0, worst_az = 0, worst_up = 0;
  for (std::size_t first = 0; first < s.samples; first += 86400 * 5) {
    s.generate(first, 20 * 3600, p);
    for (std::size_t j = 0; j < p.size(); j += step) {
      const std::size_t i = first + j;
      const double lst = s.local_sidereal_time(i);
      const double lat = s.latitude;
      const double zx = std::cos(lat) * std::cos(lst), zy = std::cos(lat) * std::sin(lst), zz = std::sin(lat);
      const double st = std::sin(p.theta[j]), ct = std::cos(p.theta[j]);
      const double kx = st * std::cos(p.phi[j]), ky = st * std::sin(p.phi[j]), kz = ct;
      // Elevation: the angle to the zenith is 90 deg - el.
      const double to_zenith = std::atan2(std::hypot(ky * zz - kz * zy, std::hypot(kz * zx - kx * zz, kx * zy - ky * zx)),
                                          kx * zx + ky * zy + kz * zz);
      worst_el = std::max(worst_el, std::abs(to_zenith - (pi / 2 - s.elevation)));
      // Azimuth from the inverse transform (hour angle H = LST - RA, declination).
      const double dec = pi / 2 - p.theta[j], H = lst - p.phi[j];
      const double az = std::atan2(-std::sin(H) * std::cos(dec),
                                   std::sin(dec) * std::cos(lat) - std::cos(dec) * std::sin(lat) * std::cos(H));
      worst_az = std::max(worst_az, std::abs(angle_diff(az, s.azimuth(i))));
      // theta' rotated back by the boresight angle points to the zenith: phi'(psi - boresight) . Z = 0.
      const std::size_t day = static_cast<std::size_t>(double(i) / s.sample_rate / s.boresight_period);
      const double psi0 = p.psi[j] - s.boresight_angles[day % s.boresight_angles.size()];
      const auto f = pisco::detail::make_frame(ct, st, std::cos(p.phi[j]), std::sin(p.phi[j]), std::cos(psi0),
                                               std::sin(psi0), 1.0, 0.0);
      worst_up = std::max(worst_up, std::abs(f.phi_p.x * zx + f.phi_p.y * zy + f.phi_p.z * zz));
      EXPECT_GT(f.theta_p.x * zx + f.theta_p.y * zy + f.theta_p.z * zz, 0.0);
    }
  }
  std::cout << "CES: max |distance to zenith - (90 - el)| " << worst_el << " rad, |azimuth error| " << worst_az
            << " rad, |phi' . zenith| " << worst_up << "\n";
  EXPECT_LT(worst_el, 1e-12);
  EXPECT_LT(worst_az, 1e-11);
  EXPECT_LT(worst_up, 1e-12);
}

TEST(Ces, AzimuthSweepSiderealDayAndSchedule) {
  const pisco::CesScan s = class_like();
  double lo = 1e9, hi = -1e9;
  for (std::size_t i = 0; i < 2 * 1440 * 20; ++i) {
    lo = std::min(lo, s.azimuth(i));
    hi = std::max(hi, s.azimuth(i));
  }
  EXPECT_NEAR(lo, (180 - 360) * deg, 1e-9);
  EXPECT_NEAR(hi, (180 + 360) * deg, 1e-9);
  EXPECT_NEAR(s.azimuth(20) - s.azimuth(0), 1 * deg, 1e-12);  // 1 deg/s at 20 Hz
  // One sidereal day later the sky is back: LST advances by 2 pi in 86164.0905 s.
  pisco::CesScan t = s;
  t.sample_rate = 1;
  const double d = angle_diff(t.local_sidereal_time(86164) + 0.0905 * 2 * pi / 86164.0905, t.local_sidereal_time(0));
  EXPECT_LT(std::abs(d), 2e-6);
  // Earth rotation angle at J2000.0 (2000-01-01T12:00:00) is 0.7790572732640 turns.
  pisco::CesScan j2000;
  j2000.start_unix = 946728000;
  j2000.sample_rate = 1;
  EXPECT_NEAR(j2000.local_sidereal_time(0), 2 * pi * 0.7790572732640, 1e-9);
  // The boresight angle is held for a day, then the next one: against the same scan without rotation.
  pisco::CesScan fixed = s;
  fixed.boresight_angles = {0.0};
  pisco::Pointing a, b;
  for (std::size_t i : {std::size_t(0), std::size_t(86400 * 20 - 1), std::size_t(86400 * 20), std::size_t(2 * 86400 * 20 + 5)}) {
    s.generate(i, 1, a);
    fixed.generate(i, 1, b);
    const double expected = s.boresight_angles[i / (86400 * 20)];
    EXPECT_NEAR(angle_diff(a.psi[0] - b.psi[0], expected), 0.0, 1e-12) << "sample " << i;
  }
}

TEST(Ces, ChunksEqualOneGeneration) {
  const pisco::CesScan s = class_like();
  pisco::Pointing whole, part;
  s.generate(1000, 5000, whole);
  for (std::size_t off = 0; off < 5000; off += 1237) {
    s.generate(1000 + off, std::min<std::size_t>(1237, 5000 - off), part);
    for (std::size_t j = 0; j < part.size(); ++j) {
      EXPECT_EQ(part.theta[j], whole.theta[off + j]);
      EXPECT_EQ(part.psi[j], whole.psi[off + j]);
    }
  }
}

TEST(Ces, BadParametersAreNamed) {
  pisco::CesScan s = class_like();
  s.elevation = 95 * deg;
  pisco::Pointing p;
  try {
    s.generate(0, 1, p);
    FAIL();
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("elevation"), std::string::npos);
  }
}

TEST(Offsets, DistanceBearingAndRotation) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing b;
  for (int i = 0; i < 2000; ++i) b.push_back(std::acos(1 - 2 * u(rng)), 2 * pi * u(rng), 2 * pi * u(rng));
  pisco::Pointing same, det, rotated;
  pisco::offset_pointing(b, 0, 0, 0, same);
  const double xi = 2.3 * deg, eta = -1.1 * deg, gamma = 0.4;
  pisco::offset_pointing(b, xi, eta, 0, det);
  pisco::offset_pointing(b, xi, eta, gamma, rotated);
  double worst_same = 0, worst_dist = 0, worst_bearing = 0, worst_gamma = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    worst_same = std::max({worst_same, std::abs(same.theta[i] - b.theta[i]),
                           std::abs(angle_diff(same.phi[i], b.phi[i])) * std::sin(b.theta[i]),
                           std::abs(angle_diff(same.psi[i], b.psi[i]))});
    const auto f = pisco::detail::make_frame(std::cos(b.theta[i]), std::sin(b.theta[i]), std::cos(b.phi[i]),
                                             std::sin(b.phi[i]), std::cos(b.psi[i]), std::sin(b.psi[i]), 1.0, 0.0);
    const pisco::detail::Vec3<double> k{std::sin(det.theta[i]) * std::cos(det.phi[i]),
                                        std::sin(det.theta[i]) * std::sin(det.phi[i]), std::cos(det.theta[i])};
    const auto g = pisco::detail::pixel_geometry(f, k);
    worst_dist = std::max(worst_dist, std::abs(std::atan2(std::hypot(g.x, g.y), g.z) - std::hypot(xi, eta)));
    worst_bearing = std::max(worst_bearing, std::abs(angle_diff(std::atan2(g.y, g.x), std::atan2(eta, xi))));
    worst_gamma = std::max(worst_gamma, std::abs(angle_diff(rotated.psi[i] - det.psi[i], gamma)));
  }
  std::cout << "offsets: identity " << worst_same << ", distance " << worst_dist << ", bearing " << worst_bearing
            << ", gamma " << worst_gamma << " rad\n";
  EXPECT_LT(worst_same, 1e-12);
  EXPECT_LT(worst_dist, 1e-12);
  EXPECT_LT(worst_bearing, 1e-10);
  EXPECT_LT(worst_gamma, 1e-10);
}

}  // namespace
