// Satellite scans (spin, precession, yearly motion of the anti-sun direction), against geometric
// invariants computed from the public vectors only: the opening angles, the phases of the boresight
// about the spin axis and of the spin axis about the anti-sun direction, the ecliptic longitude of
// the anti-sun direction, the orientation of the boresight's frame against the scan, and the fixed
// frame rotations against published coordinates of the ecliptic poles and the galactic centre.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>
#include <string>
#include <vector>

#include "pisco/pisco.hpp"
#include "pisco/scan.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;
using V = std::array<double, 3>;
using Frame = pisco::SatelliteScan::Frame;

double dot(const V& a, const V& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V cross(const V& a, const V& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double length(const V& a) { return std::sqrt(dot(a, a)); }
V unit(const V& a) {
  const double n = length(a);
  return {a[0] / n, a[1] / n, a[2] / n};
}
// The angle between two vectors, accurate at every size.
double angle(const V& a, const V& b) { return std::atan2(length(cross(a, b)), dot(a, b)); }
// The azimuth of v about the unit axis `axis`, from the part of `ref` perpendicular to it towards
// axis x ref.
double azimuth(const V& v, const V& axis, const V& ref) {
  const double r = dot(ref, axis);
  const V x = unit({ref[0] - r * axis[0], ref[1] - r * axis[1], ref[2] - r * axis[2]});
  const V y = cross(axis, x);
  return std::atan2(dot(v, y), dot(v, x));
}
double angle_diff(double a, double b) { return std::remainder(a - b, 2 * pi); }

pisco::SatelliteScan litebird(Frame frame = Frame::ecliptic) {
  pisco::SatelliteScan s;  // the defaults are LiteBIRD's: alpha 45, beta 50 deg, 192.348 and 20 min
  s.start_time = 1.0e6;
  s.precession_phase = 0.7;
  s.spin_phase = -2.1;
  s.frame = frame;
  s.samples = static_cast<std::size_t>(s.year * s.sample_rate);  // a year
  return s;
}

// Sample indices spread over a year, with a few near its start.
std::vector<std::size_t> samples_of(const pisco::SatelliteScan& s) {
  std::vector<std::size_t> idx{0, 1, 2, 1000};
  for (std::size_t i = 7; i < s.samples; i += s.samples / 997 + 13) idx.push_back(i);
  return idx;
}

V boresight(const pisco::SatelliteScan& s, std::size_t i, V* theta_p = nullptr, V* phi_p = nullptr) {
  std::vector<pisco::Quat> q;
  s.generate(i, 1, q);
  if (theta_p) *theta_p = pisco::rotate(q[0], {1, 0, 0});
  if (phi_p) *phi_p = pisco::rotate(q[0], {0, 1, 0});
  return pisco::rotate(q[0], {0, 0, 1});
}

TEST(Satellite, OpeningAnglesAndUnitQuaternions) {
  for (Frame frame : {Frame::ecliptic, Frame::equatorial, Frame::galactic}) {
    const pisco::SatelliteScan s = litebird(frame);
    double worst_beta = 0, worst_alpha = 0, worst_norm = 0;
    std::vector<pisco::Quat> q;
    for (std::size_t i : samples_of(s)) {
      s.generate(i, 3, q);
      ASSERT_EQ(q.size(), 3u);
      for (const pisco::Quat& r : q) worst_norm = std::max(worst_norm, std::abs(pisco::norm(r) - 1));
      const V b = pisco::rotate(q[0], {0, 0, 1}), spin = s.spin_axis(i), sun = s.anti_sun(i);
      EXPECT_NEAR(length(spin), 1.0, 1e-15);
      EXPECT_NEAR(length(sun), 1.0, 1e-15);
      worst_beta = std::max(worst_beta, std::abs(angle(b, spin) - s.spin_boresight_angle));
      worst_alpha = std::max(worst_alpha, std::abs(angle(spin, sun) - s.spin_sun_angle));
    }
    std::cout << "satellite frame " << int(frame) << ": max |angle(boresight, spin) - beta| " << worst_beta
              << ", |angle(spin, anti-sun) - alpha| " << worst_alpha << " rad, | |q| - 1 | " << worst_norm << "\n";
    EXPECT_LT(worst_beta, 1e-12);
    EXPECT_LT(worst_alpha, 1e-12);
    EXPECT_LT(worst_norm, 1e-14);
  }
}

TEST(Satellite, AntiSunAlongTheEcliptic) {
  const pisco::SatelliteScan s = litebird();
  double worst_plane = 0, worst_longitude = 0;
  for (std::size_t i : samples_of(s)) {
    const V a = s.anti_sun(i);
    worst_plane = std::max(worst_plane, std::abs(a[2]));
    // Ecliptic longitude 2 pi t / year, 0 at t = 0.
    worst_longitude = std::max(worst_longitude, std::abs(angle_diff(std::atan2(a[1], a[0]), 2 * pi * s.time(i) / s.year)));
  }
  EXPECT_LT(worst_plane, 1e-15);
  EXPECT_LT(worst_longitude, 1e-10);
  // A quarter of a year turns it by 90 deg towards +y (prograde); a year brings it back.
  pisco::SatelliteScan t = s;
  t.start_time = 0;
  t.sample_rate = 1;
  const std::size_t year = static_cast<std::size_t>(t.year);
  EXPECT_NEAR(t.anti_sun(0)[0], 1.0, 1e-15);
  const V quarter = t.anti_sun(year / 4);
  EXPECT_NEAR(quarter[0], 0.0, 1e-12);
  EXPECT_NEAR(quarter[1], 1.0, 1e-12);
  const V back = t.anti_sun(year);
  EXPECT_NEAR(back[0], 1.0, 1e-15);
  EXPECT_NEAR(back[1], 0.0, 1e-12);
  // start_time = L / (2 pi) year puts the anti-sun direction at longitude L.
  t.start_time = 100.0 / 360 * t.year;
  const V l100 = t.anti_sun(0);
  EXPECT_NEAR(std::atan2(l100[1], l100[0]), 100 * deg, 1e-12);
}

TEST(Satellite, SpinAndPrecessionPhases) {
  for (Frame frame : {Frame::ecliptic, Frame::galactic}) {
    const pisco::SatelliteScan s = litebird(frame);
    // The north ecliptic pole in the output frame.
    const V pole = pisco::rotate(pisco::SatelliteScan::ecliptic_to(frame), {0, 0, 1});
    double worst_spin = 0, worst_precession = 0, worst_spin_period = 0, worst_precession_period = 0;
    // The spin and precession periods in whole samples, and the phase that the rounding adds.
    const std::size_t spin_samples = static_cast<std::size_t>(std::llround(s.spin_period * s.sample_rate));
    const std::size_t precession_samples = static_cast<std::size_t>(std::llround(s.precession_period * s.sample_rate));
    const double spin_extra = 2 * pi * (double(spin_samples) / s.sample_rate - s.spin_period) / s.spin_period;
    const double precession_extra =
        2 * pi * (double(precession_samples) / s.sample_rate - s.precession_period) / s.precession_period;
    for (std::size_t i : samples_of(s)) {
      const double t = s.time(i);
      const V b = boresight(s, i), spin = s.spin_axis(i), sun = s.anti_sun(i);
      // The boresight's azimuth about the spin axis, from the anti-sun side, is the spin angle.
      const double spin_phase = azimuth(b, spin, sun);
      worst_spin = std::max(worst_spin, std::abs(angle_diff(spin_phase, 2 * pi * t / s.spin_period + s.spin_phase)));
      // The spin axis's azimuth about the anti-sun direction, from the ecliptic north, is the
      // precession angle.
      const double precession_phase = azimuth(spin, sun, pole);
      worst_precession = std::max(
          worst_precession, std::abs(angle_diff(precession_phase, 2 * pi * t / s.precession_period + s.precession_phase)));
      // One spin period later the spin phase is back, one precession period later the precession
      // phase (the axes themselves have moved on meanwhile).
      const std::size_t j = i + spin_samples, k = i + precession_samples;
      worst_spin_period = std::max(
          worst_spin_period,
          std::abs(angle_diff(azimuth(boresight(s, j), s.spin_axis(j), s.anti_sun(j)), spin_phase + spin_extra)));
      worst_precession_period =
          std::max(worst_precession_period,
                   std::abs(angle_diff(azimuth(s.spin_axis(k), s.anti_sun(k), pole), precession_phase + precession_extra)));
    }
    std::cout << "satellite frame " << int(frame) << ": spin phase error " << worst_spin << ", precession phase error "
              << worst_precession << ", after a period " << worst_spin_period << ", " << worst_precession_period
              << " rad\n";
    EXPECT_LT(worst_spin, 1e-10);
    EXPECT_LT(worst_precession, 1e-10);
    EXPECT_LT(worst_spin_period, 1e-10);
    EXPECT_LT(worst_precession_period, 1e-10);
  }
  // Half a spin later the boresight is on the other side of the spin axis, 2 beta from where it was
  // (with the precession and the year stopped, nearly).
  pisco::SatelliteScan slow = litebird();
  slow.precession_period = slow.year = 1e30;
  const std::size_t half = static_cast<std::size_t>(slow.spin_period * slow.sample_rate / 2);
  EXPECT_NEAR(angle(boresight(slow, 5), boresight(slow, 5 + half)), 2 * slow.spin_boresight_angle, 1e-12);
}

TEST(Satellite, FirstSampleByHand) {
  // t = 0, phases 0, ecliptic: q = R_y(pi/2 - alpha + beta); the spin axis at (cos a, 0, sin a).
  pisco::SatelliteScan s;
  const double a = s.spin_sun_angle, b = s.spin_boresight_angle;
  V theta_p, phi_p;
  const V p = boresight(s, 0, &theta_p, &phi_p);
  const V expect_p{std::cos(a - b), 0, std::sin(a - b)}, expect_theta{std::sin(a - b), 0, -std::cos(a - b)};
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(p[c], expect_p[c], 1e-15);
    EXPECT_NEAR(theta_p[c], expect_theta[c], 1e-15);
    EXPECT_NEAR(phi_p[c], c == 1 ? 1.0 : 0.0, 1e-15);
  }
  const V spin = s.spin_axis(0);
  EXPECT_NEAR(spin[0], std::cos(a), 1e-15);
  EXPECT_NEAR(spin[1], 0.0, 1e-15);
  EXPECT_NEAR(spin[2], std::sin(a), 1e-15);
}

TEST(Satellite, ScanDirectionAndOrientation) {
  // The documented frame: theta' in the plane of the spin axis and the line of sight, away from the
  // spin axis; phi' along spin axis x line of sight, which is where the boresight moves.
  for (Frame frame : {Frame::ecliptic, Frame::equatorial, Frame::galactic}) {
    const pisco::SatelliteScan s = litebird(frame);
    double worst_plane = 0, worst_phi = 0, worst_motion = 1;
    for (std::size_t i : samples_of(s)) {
      V theta_p, phi_p;
      const V b = boresight(s, i, &theta_p, &phi_p), spin = s.spin_axis(i);
      const V along = unit(cross(spin, b));
      worst_plane = std::max(worst_plane, std::abs(dot(theta_p, along)));
      EXPECT_NEAR(dot(theta_p, spin), -std::sin(s.spin_boresight_angle), 1e-12) << "sample " << i;
      worst_phi = std::max(worst_phi, std::abs(dot(phi_p, along) - 1));
      // The motion over one sample, mostly the spin's (the precession adds up to ~14% across).
      const V next = boresight(s, i + 1);
      const V step = unit({next[0] - b[0], next[1] - b[1], next[2] - b[2]});
      worst_motion = std::min(worst_motion, dot(step, phi_p));
      EXPECT_GT(dot(step, phi_p), 0.95) << "sample " << i;
      EXPECT_LT(std::abs(dot(step, theta_p)), 0.3) << "sample " << i;
    }
    std::cout << "satellite frame " << int(frame) << ": |theta' . (s x p)| " << worst_plane << ", |phi' . (s x p) - 1| "
              << worst_phi << ", min cos(motion, phi') " << worst_motion << "\n";
    EXPECT_LT(worst_plane, 1e-12);
    EXPECT_LT(worst_phi, 1e-12);
  }
}

TEST(Satellite, ChunksEqualOneGeneration) {
  for (Frame frame : {Frame::ecliptic, Frame::galactic}) {
    const pisco::SatelliteScan s = litebird(frame);
    const std::size_t first = 123456789, n = 5000;
    std::vector<pisco::Quat> whole, part{pisco::Quat{}, pisco::Quat{}};  // part starts non-empty
    s.generate(first, n, whole);
    ASSERT_EQ(whole.size(), n);
    for (std::size_t off = 0; off < n; off += 1237) {
      const std::size_t m = std::min<std::size_t>(1237, n - off);
      s.generate(first + off, m, part);
      ASSERT_EQ(part.size(), m);
      for (std::size_t j = 0; j < m; ++j) {
        EXPECT_EQ(part[j].x, whole[off + j].x);
        EXPECT_EQ(part[j].y, whole[off + j].y);
        EXPECT_EQ(part[j].z, whole[off + j].z);
        EXPECT_EQ(part[j].w, whole[off + j].w);
      }
    }
  }
}

TEST(Satellite, FrameRotations) {
  auto lonlat = [](const V& v, double& lon, double& lat) {
    lon = std::atan2(v[1], v[0]);
    if (lon < 0) lon += 2 * pi;
    lat = std::atan2(v[2], std::hypot(v[0], v[1]));
  };
  double lon, lat;
  // The north ecliptic pole: RA 270 deg, Dec 90 deg - 23.4392911 deg (J2000).
  lonlat(pisco::rotate(pisco::SatelliteScan::ecliptic_to(Frame::equatorial), {0, 0, 1}), lon, lat);
  EXPECT_NEAR(lon / deg, 270.0, 1e-10);
  EXPECT_NEAR(lat / deg, 66.5607089, 1e-9);
  // ... and in galactic coordinates the textbook formula's l and b of RA 270 deg, Dec 66.5607089 deg
  // (from the galactic pole's RA and Dec and the celestial pole's l, below; published: 96.38, 29.81).
  const double aG = 192.85948 * deg, dG = 27.12825 * deg, lN = 122.93192 * deg;
  const auto textbook = [&](double a, double d, double& l, double& b) {
    b = std::asin(std::sin(d) * std::sin(dG) + std::cos(d) * std::cos(dG) * std::cos(a - aG));
    l = lN - std::atan2(std::cos(d) * std::sin(a - aG),
                        std::sin(d) * std::cos(dG) - std::cos(d) * std::sin(dG) * std::cos(a - aG));
  };
  lonlat(pisco::rotate(pisco::SatelliteScan::ecliptic_to(Frame::galactic), {0, 0, 1}), lon, lat);
  double l_pole, b_pole;
  textbook(270 * deg, 66.5607089 * deg, l_pole, b_pole);
  std::cout << "north ecliptic pole: l " << lon / deg << " deg, b " << lat / deg << " deg (textbook: " << l_pole / deg
            << ", " << b_pole / deg << ")\n";
  EXPECT_NEAR(lon, l_pole, 1e-9);
  EXPECT_NEAR(lat, b_pole, 1e-9);
  EXPECT_NEAR(lon / deg, 96.38, 0.005);
  EXPECT_NEAR(lat / deg, 29.81, 0.005);
  // The galactic centre (l = b = 0) at RA 266.40499 deg, Dec -28.93617 deg (ICRS); the north
  // galactic pole at RA 192.85948 deg, Dec 27.12825 deg; the north celestial pole at l 122.93192 deg.
  const pisco::Quat ecl_to_equ = pisco::SatelliteScan::ecliptic_to(Frame::equatorial);
  const pisco::Quat equ_to_gal = pisco::SatelliteScan::ecliptic_to(Frame::galactic) * pisco::conjugate(ecl_to_equ);
  lonlat(pisco::rotate(pisco::conjugate(equ_to_gal), {1, 0, 0}), lon, lat);
  EXPECT_NEAR(lon / deg, 266.40499, 1e-4);
  EXPECT_NEAR(lat / deg, -28.93617, 1e-4);
  lonlat(pisco::rotate(pisco::conjugate(equ_to_gal), {0, 0, 1}), lon, lat);
  EXPECT_NEAR(lon / deg, 192.85948, 1e-9);
  EXPECT_NEAR(lat / deg, 27.12825, 1e-9);
  lonlat(pisco::rotate(equ_to_gal, {0, 0, 1}), lon, lat);
  EXPECT_NEAR(lon / deg, 122.93192, 1e-9);
  EXPECT_NEAR(lat / deg, 27.12825, 1e-9);
  // The textbook formula (sin b = sin d sin d_G + cos d cos d_G cos(a - a_G), ...) at many points.
  double worst = 0;
  for (double a = 0.1; a < 2 * pi; a += 0.37)
    for (double d = -1.5; d < 1.5; d += 0.29) {
      const V v = pisco::rotate(equ_to_gal, {std::cos(d) * std::cos(a), std::cos(d) * std::sin(a), std::sin(d)});
      double l, b;
      textbook(a, d, l, b);
      const V expect{std::cos(b) * std::cos(l), std::cos(b) * std::sin(l), std::sin(b)};
      worst = std::max(worst, angle(v, expect));
    }
  EXPECT_LT(worst, 1e-12);
  // The scan in the galactic and equatorial frames is the ecliptic one turned by the fixed rotation.
  const pisco::SatelliteScan ecl = litebird(Frame::ecliptic);
  for (Frame frame : {Frame::equatorial, Frame::galactic}) {
    const pisco::SatelliteScan other = litebird(frame);
    const pisco::Quat r = pisco::SatelliteScan::ecliptic_to(frame);
    std::vector<pisco::Quat> qe, qo;
    double worst_q = 0;
    for (std::size_t i : samples_of(ecl)) {
      ecl.generate(i, 1, qe);
      other.generate(i, 1, qo);
      for (const V& axis : {V{1, 0, 0}, V{0, 1, 0}, V{0, 0, 1}})
        worst_q = std::max(worst_q, angle(pisco::rotate(qo[0], axis), pisco::rotate(r, pisco::rotate(qe[0], axis))));
    }
    EXPECT_LT(worst_q, 1e-14);
  }
}

TEST(Satellite, BadParametersAreNamed) {
  auto expect_named = [](pisco::SatelliteScan s, const std::string& field) {
    std::vector<pisco::Quat> q;
    try {
      s.generate(0, 1, q);
      ADD_FAILURE() << field << ": no error";
    } catch (const pisco::Error& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  const pisco::SatelliteScan good = litebird();
  EXPECT_NO_THROW(good.check());
  pisco::SatelliteScan s = good;
  s.spin_sun_angle = -0.1;
  expect_named(s, "spin_sun_angle");
  s = good;
  s.spin_sun_angle = std::nan("");
  expect_named(s, "spin_sun_angle");
  s = good;
  s.spin_boresight_angle = 0;
  expect_named(s, "spin_boresight_angle");
  s = good;
  s.spin_boresight_angle = pi;
  expect_named(s, "spin_boresight_angle");
  s = good;
  s.precession_period = 0;
  expect_named(s, "precession_period");
  s = good;
  s.spin_period = std::nan("");
  expect_named(s, "spin_period");
  s = good;
  s.sample_rate = -19;
  expect_named(s, "sample_rate");
  s = good;
  s.start_time = INFINITY;
  expect_named(s, "start_time");
  s = good;
  s.precession_phase = std::nan("");
  expect_named(s, "precession_phase");
  s = good;
  s.spin_phase = -INFINITY;
  expect_named(s, "spin_phase");
  s = good;
  s.year = 0;
  expect_named(s, "year");
  // The edges that are allowed: the spin axis along the anti-sun direction (Planck-like) or opposite.
  s = good;
  s.spin_sun_angle = 0;
  EXPECT_NO_THROW(s.check());
  s.spin_sun_angle = pi;
  EXPECT_NO_THROW(s.check());
}

}  // namespace
