// Point sources evaluated per sample (pisco/sources.hpp, docs/sources.md): a source at a pixel's centre
// reads exactly as that pixel does in a plain pixel sum (round and elliptical beams, offsets, both
// plate placements, polarized sources, across a pole), a source's response against the truncated
// Gaussian's own value at its offset, a moving source against the same source fixed where its track
// puts it, and the errors for bad tracks and times.
#include <gtest/gtest.h>
#include <unistd.h>

#include <healpix_base.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/sources.hpp"
#include "pisco/units.hpp"

namespace {
using pisco::deg;
constexpr double pi = std::numbers::pi;

// Samples around direction (theta0, phi0): within 1.3 rho_max (some beyond the disc), random psi.
pisco::Pointing around(double theta0, double phi0, double rho_max, std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  const Healpix_Base base(1, RING, SET_NSIDE);
  const vec3 c = pointing(theta0, phi0).to_vec3();
  const vec3 e1 = std::abs(c.z) < 0.9 ? crossprod(c, vec3(0, 0, 1)).Norm() : crossprod(c, vec3(1, 0, 0)).Norm();
  const vec3 e2 = crossprod(c, e1);
  pisco::Pointing p;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = 1.3 * rho_max * std::sqrt(u(rng)), a = 2 * pi * u(rng);
    const vec3 v = c * std::cos(d) + (e1 * std::cos(a) + e2 * std::sin(a)) * std::sin(d);
    const pointing q(v);
    p.push_back(q.theta, q.phi, 2 * pi * u(rng));
  }
  return p;
}

// An engine on the float64 reference for one ideal detector "d" with a Gaussian beam of `fwhm` cut at
// `rho_max`, over an empty sky of `nside`.
pisco::Engine ideal_engine(int nside, double fwhm, double rho_max,
                           pisco::Normalization normalization = pisco::Normalization::integral) {
  pisco::BeamOptions o;
  o.rho_max = rho_max;
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "d";
  fp.add(d);
  pisco::EngineOptions eo;
  eo.backend = "cpu";
  eo.normalization = normalization;
  return pisco::Engine(pisco::Sky(nside), {pisco::Beamsor::gaussian(fwhm, o)}, fp, eo);
}

struct Case {
  std::string name;
  pisco::Beamsor beam;
  pisco::Detector detector;
};

std::vector<Case> cases(double fwhm) {
  pisco::BeamOptions o;
  o.rho_max = 2.5 * fwhm;
  std::vector<Case> out;
  pisco::Detector ideal;
  ideal.name = "d";
  out.push_back({"round beam", pisco::Beamsor::gaussian(fwhm, o), ideal});
  pisco::Detector offset = ideal;
  offset.zeta = 0.4;
  offset.epsilon = 0.02;
  offset.gain = 1.3;
  offset.set_offset(0.6 * deg, -0.4 * deg, 0.3);
  out.push_back({"elliptical beam, offset detector", pisco::Beamsor::elliptical_gaussian(fwhm, 0.7 * fwhm, 0.3, o), offset});
  pisco::Detector aperture = ideal;
  aperture.hwp = pisco::HalfWavePlate::ideal(0.2, pisco::HwpPlacement::aperture);
  out.push_back({"plate at the aperture", pisco::Beamsor::elliptical_gaussian(fwhm, 0.8 * fwhm, 1.0, o), aperture});
  pisco::Detector placed = offset;
  placed.hwp = pisco::HalfWavePlate::ideal(-0.1, pisco::HwpPlacement::detector);
  out.push_back({"plate before the detector", pisco::Beamsor::elliptical_gaussian(fwhm, 0.8 * fwhm, 1.0, o), placed});
  return out;
}

// A source of flux F at a pixel's centre against that pixel at F / Omega in a plain pixel sum, on
// the float64 reference: the same arithmetic, so the same value to rounding.
TEST(Sources, ASourceAtAPixelCentreReadsAsThatPixel) {
  const int nside = 64;
  const double fwhm = 6.0 * std::sqrt(pi / 3) / nside;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const double area = 4 * pi / double(base.Npix());
  // A pixel in the belt, and one on the first ring of the north cap (the pole within the disc).
  for (const int pixel : {base.ang2pix(pointing(1.1, 2.0)), 1}) {
    const pointing at = base.pix2ang(pixel);
    const double I = 2.0, Q = 0.3, U = -0.5, V = 0.1;
    pisco::Sky sky(nside);
    sky.I()[std::size_t(pixel)] = I;
    sky.Q()[std::size_t(pixel)] = Q;
    sky.U()[std::size_t(pixel)] = U;
    sky.V()[std::size_t(pixel)] = V;
    const std::vector<pisco::SourceTrack> sources{
        pisco::SourceTrack::fixed("s", at.theta, at.phi, I * area, Q * area, U * area, V * area)};
    for (const Case& c : cases(fwhm)) {
      pisco::FocalPlane fp;
      fp.add(c.detector);
      pisco::EngineOptions o;
      o.backend = "cpu";
      o.quadrature = pisco::Quadrature::plain;
      pisco::Engine engine(sky, {c.beam}, fp, o);
      const pisco::Pointing p = around(at.theta, at.phi, 2.5 * fwhm, 300, 7);
      std::vector<double> hwp(c.detector.hwp ? p.size() : 0);
      for (std::size_t i = 0; i < hwp.size(); ++i) hwp[i] = 0.37 * double(i);
      std::vector<double> map(p.size()), src(p.size(), 0.0), time(p.size(), 0.0);
      engine.convolve(0, p, map, false, hwp);
      engine.add_sources(0, p, time, sources, src, hwp);
      double peak = 0.0, worst = 0.0;
      for (std::size_t i = 0; i < p.size(); ++i) {
        peak = std::max(peak, std::abs(map[i]));
        worst = std::max(worst, std::abs(src[i] - map[i]));
      }
      EXPECT_GT(peak, 0.0) << c.name;
      EXPECT_LE(worst, 1e-12 * peak) << c.name << ", pixel " << pixel;
      // The sources are the host's float64 arithmetic on whichever backend: the same bits.
      for (const char* backend : {"simd", "vulkan"}) {
        o.backend = backend;
        try {
          pisco::Engine other(sky, {c.beam}, fp, o);
          std::vector<double> again(p.size(), 0.0);
          other.add_sources(0, p, time, sources, again, hwp);
          EXPECT_EQ(again, src) << c.name << " on " << backend;
        } catch (const pisco::Error& e) {
          if (e.kind() != pisco::ErrorKind::unavailable) throw;
        }
      }
    }
  }
}

// An unpolarized source at offset rho from an ideal detector's line of sight: (1/2) F B(rho) / Omega~,
// Omega~ the truncated Gaussian's integral over its disc (docs/physics.md, "Normalization").
TEST(Sources, AnUnpolarizedSourceReadsTheBeamAtItsOffset) {
  const int nside = 128;
  const double fwhm = 1.0 * deg, rho_max = 2.5 * fwhm, s = fwhm / std::sqrt(8 * std::log(2.0));
  const pisco::Engine engine = ideal_engine(nside, fwhm, rho_max);
  double omega = 0.0;  // Simpson's rule over [0, rho_max] of 2 pi sin(rho) B(rho)
  const int n = 20000;
  for (int k = 0; k <= n; ++k) {
    const double rho = rho_max * k / n;
    omega += (k == 0 || k == n ? 1.0 : k % 2 ? 4.0 : 2.0) * rho_max / n / 3 * 2 * pi * std::sin(rho) * std::exp(-rho * rho / (2 * s * s));
  }
  const double F = 3.0;
  // The source on the meridian of a sample at colatitude 40 deg, at offsets 0 to 2.4 FWHM.
  for (const double offset : {0.0, 0.3, 1.0, 1.7, 2.4}) {
    const std::vector<pisco::SourceTrack> sources{pisco::SourceTrack::fixed("s", 40 * deg + offset * fwhm, 1.0, F)};
    pisco::Pointing p;
    p.push_back(40 * deg, 1.0, 0.7);
    std::vector<double> tod(1, 0.0), time(1, 0.0);
    engine.add_sources(0, p, time, sources, tod);
    const double rho = offset * fwhm, want = 0.5 * F * std::exp(-rho * rho / (2 * s * s)) / omega;
    EXPECT_NEAR(tod[0], want, 2e-6 * 0.5 * F / omega) << offset << " FWHM";
  }
}

// A source moving on a great circle and brightening linearly: at each sample's time, the same as a
// fixed source where the track puts it (the interpolation written out here); beyond the track, an
// error naming the source and the sample.
TEST(Sources, AMovingSourceIsWhereItsTrackPutsIt) {
  const double fwhm = 0.5 * deg;
  const pisco::Engine engine = ideal_engine(64, fwhm, 2.5 * fwhm);
  pisco::SourceTrack jupiter;
  jupiter.name = "jupiter";
  jupiter.time = {0.0, 10.0, 25.0};
  jupiter.theta = {1.0, 1.0 + 1.0 * deg, 1.0 + 1.5 * deg};
  jupiter.phi = {2.0, 2.0 + 0.5 * deg, 2.0 + 2.0 * deg};
  jupiter.I = {1.0, 2.0, 2.5};
  const auto unit = [](double t, double p) { return vec3(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)); };
  for (int k = 0; k <= 50; ++k) {
    const double t = 0.5 * k;
    const int seg = t < 10.0 ? 0 : 1;
    const double u = (t - jupiter.time[seg]) / (jupiter.time[seg + 1] - jupiter.time[seg]);
    const vec3 a = unit(jupiter.theta[seg], jupiter.phi[seg]), b = unit(jupiter.theta[seg + 1], jupiter.phi[seg + 1]);
    const double om = std::acos(dotprod(a, b));
    const pointing where(a * (std::sin((1 - u) * om) / std::sin(om)) + b * (std::sin(u * om) / std::sin(om)));
    const double flux = jupiter.I[seg] + u * (jupiter.I[seg + 1] - jupiter.I[seg]);
    pisco::Pointing p;
    p.push_back(where.theta + 0.3 * fwhm, where.phi, 0.0);
    std::vector<double> moving(1, 0.0), fixed(1, 0.0), time{t};
    engine.add_sources(0, p, time, {jupiter}, moving);
    engine.add_sources(0, p, time, {pisco::SourceTrack::fixed("f", where.theta, where.phi, flux)}, fixed);
    EXPECT_NEAR(moving[0], fixed[0], 1e-12 * std::abs(fixed[0])) << "t = " << t;
    EXPECT_GT(fixed[0], 0.0);
  }
  pisco::Pointing p;
  p.push_back(1.0, 2.0, 0.0);
  p.push_back(1.0, 2.0, 0.0);
  std::vector<double> tod(2, 0.0), late{1.0, 26.0};
  try {
    engine.add_sources(0, p, late, {jupiter}, tod);
    FAIL() << "a time beyond the track";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("add_sources: detector 'd': source 'jupiter': sample 1 is at time 26"), std::string::npos) << e.what();
  }
  EXPECT_EQ(tod, std::vector<double>(2, 0.0));  // sample 0, within the track, was not added either
}

// Boresight quaternions give what angles give; a beam split into a main part and sidelobes gives what
// the whole beam gives (the two parts' weights sum to it), inside the split and beyond it.
TEST(Sources, QuaternionsAndSplitBeamsAgree) {
  const double fwhm = 2.0 * deg;
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "d";
  d.zeta = 0.3;
  d.set_offset(0.5 * deg, 0.2 * deg, 0.1);
  fp.add(d);
  pisco::EngineOptions eo;
  eo.backend = "cpu";
  const auto field = [&](double rho, double) {
    const double s = fwhm / std::sqrt(8 * std::log(2.0)), b = std::exp(-rho * rho / (2 * s * s)) + 1e-3 * std::exp(-rho / (4 * deg));
    pisco::Mueller m{};
    for (int i = 0; i < 4; ++i) m[i][i] = b;
    return m;
  };
  const pisco::Beamsor whole = pisco::Beamsor::from_field(field, 12 * deg, 0.1 * deg, "whole");
  pisco::SidelobeSplit split;
  split.rho_main = 4 * deg;
  const pisco::Beamsor parted = pisco::Beamsor::from_field(field, 12 * deg, 0.1 * deg, "parted", 0.0, false, split);
  pisco::Engine one(pisco::Sky(64), {whole}, fp, eo), two(pisco::Sky(64), {parted}, fp, eo);
  const std::vector<pisco::SourceTrack> sources{pisco::SourceTrack::fixed("s", 1.0, 2.0, 1e-3, 2e-4, -1e-4)};
  pisco::Pointing p;
  std::vector<pisco::Quat> quats;
  for (int k = 0; k < 40; ++k) {
    const double theta = 1.0 + 0.2 * deg * k, phi = 2.0 + 0.002 * k, psi = 0.3 * k;
    p.push_back(theta, phi, psi);
    quats.push_back(pisco::quat_from_pointing(theta, phi, psi));
  }
  std::vector<double> a(p.size(), 0.0), b(p.size(), 0.0), c(p.size(), 0.0), time(p.size(), 0.0);
  one.add_sources(0, p, time, sources, a);
  one.add_sources(0, pisco::QuatPointingView{quats}, time, sources, b);
  two.add_sources(0, p, time, sources, c);
  double peak = 0.0;
  for (const double x : a) peak = std::max(peak, std::abs(x));
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_NEAR(b[i], a[i], 1e-12 * peak) << "sample " << i;
    EXPECT_NEAR(c[i], a[i], 1e-4 * peak) << "sample " << i;  // two grids' interpolation
  }
  EXPECT_GT(std::abs(a.back()), 0.0);  // the last samples are beyond the split, within the sidelobes
}

TEST(Sources, BadTracksAndCallsAreRefusedByName) {
  pisco::SourceTrack s = pisco::SourceTrack::fixed("mars", 1.0, 2.0, 1.0);
  s.time = {0.0, 1.0};
  EXPECT_THROW(s.check("here"), pisco::Error);  // sizes differ
  s.theta = {1.0, 1.1};
  s.phi = {2.0, 2.1};
  s.I = {1.0, 1.0};
  s.Q = s.U = s.V = {};
  EXPECT_NO_THROW(s.check("here"));
  s.time = {1.0, 1.0};
  try {
    s.check("sources.toml");
    FAIL();
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("sources.toml: source 'mars', point 1: the time 1 does not follow 1"),
              std::string::npos)
        << e.what();
  }
  s.time = {0.0, 1.0};
  s.theta = {1.0, 4.0};
  EXPECT_THROW(s.check("here"), pisco::Error);
  s.theta = {0.5, pi - 0.5};
  s.phi = {0.0, pi};
  EXPECT_THROW(s.check("here"), pisco::Error);  // opposite directions: no great circle

  const pisco::Engine engine = ideal_engine(64, 1 * deg, 2 * deg, pisco::Normalization::per_sample);
  pisco::Pointing p;
  p.push_back(1.0, 2.0, 0.0);
  std::vector<double> tod(1), time(1, 0.0);
  EXPECT_THROW(engine.add_sources(0, p, time, {pisco::SourceTrack::fixed("s", 1.0, 2.0, 1.0)}, tod), pisco::Error);
}

// Track files (docs/formats.md, "Source tracks"): a track written and read back is the same track (to
// a rounding of its angles through degrees), a file a spreadsheet or a person writes (a byte-order mark,
// comments, columns in any order, Q, U, V left out) reads as its table says, and every mistake is
// refused naming the file, the line and the column.
TEST(Sources, TrackFilesReadWhatTheySay) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("pisco-tracks-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  pisco::SourceTrack s{"jupiter", {0.0, 60.0, 120.5}, {1.0, 1.001, 1.0025}, {2.0, 2.002, 2.0031},
                       {1e-6, 1.1e-6, 1.2e-6}, {}, {3e-9, 0.0, -1e-9}, {}};
  s.write_csv(dir / "jupiter.csv");
  const pisco::SourceTrack r = pisco::SourceTrack::read_csv(dir / "jupiter.csv", "jupiter");
  EXPECT_EQ(r.name, "jupiter");
  ASSERT_EQ(r.time.size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(r.time[k], s.time[k]);
    EXPECT_NEAR(r.theta[k], s.theta[k], 1e-15);
    EXPECT_NEAR(r.phi[k], s.phi[k], 1e-15);
    EXPECT_EQ(r.I[k], s.I[k]);
    EXPECT_EQ(r.Q[k], 0.0);
    EXPECT_EQ(r.U[k], s.U[k]);
    EXPECT_EQ(r.V[k], 0.0);
  }

  const auto write = [&](const std::string& text) {
    std::ofstream(dir / "t.csv", std::ios::binary) << text;
    return dir / "t.csv";
  };
  const pisco::SourceTrack hand = pisco::SourceTrack::read_csv(
      write("\xEF\xBB\xBF# Mars, by hand\n\n I , phi_deg,theta_deg ,time_s\r\n2.5, 90, 45, 0\r\n# a pause\n2.5,91,45,10\n"), "mars");
  ASSERT_EQ(hand.time.size(), 2u);
  EXPECT_EQ(hand.time[1], 10.0);
  EXPECT_DOUBLE_EQ(hand.theta[0], 45 * deg);
  EXPECT_DOUBLE_EQ(hand.phi[1], 91 * deg);
  EXPECT_EQ(hand.I[0], 2.5);
  EXPECT_TRUE(hand.Q.empty());

  const auto refused = [&](const std::string& text) {
    try {
      (void)pisco::SourceTrack::read_csv(write(text), "x");
    } catch (const pisco::Error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const std::string file = (dir / "t.csv").string();
  const auto says = [&](const std::string& text, const std::string& expected) {
    const std::string what = refused(text);
    EXPECT_NE(what.find(expected), std::string::npos) << what;
  };
  const std::string head = "time_s,theta_deg,phi_deg,I\n";
  says("time_s,theta_deg,phi_deg,I,flux\n", file + ":1: unknown column 'flux'");
  says("time_s,theta_deg,I\n0,1,2\n", file + ":1: the header needs a 'phi_deg' column");
  says("time_s,theta_deg,phi_deg,I,I\n", file + ":1: column 'I' appears twice");
  says(head + "0,10,20,1\n1,10,20\n", file + ":3: expected 4 fields, got 3");
  says(head + "0,10,20,1\n1,10,20,1,\n", file + ":3: expected 4 fields, got 5");
  says(head + "0,10,20,1\n1,10,twenty,1\n", file + ":3: column 'phi_deg': expected a finite number, got 'twenty'");
  says(head + "0,10,20,nan\n", file + ":2: column 'I': expected a finite number, got 'nan'");
  says(head + "0,10,20,1e999\n", file + ":2: column 'I': expected a finite number");
  says(head + "0,190,20,1\n", file + ":2: column 'theta_deg': 190 is outside [0, 180]");
  says(head + "0,10,20,1\n5,10,20,1\n5,10,21,1\n", file + ":4: column 'time_s': 5 does not follow");
  says(head + "# nothing\n", file + ": no rows after the header");
  says("# only a comment\n", file + ": no header");
  says("", file + ": no header");
  says(head + "0,30,0,1\n1,150,180,1\n", "the direction is opposite the previous point's");
  try {
    (void)pisco::SourceTrack::read_csv(dir / "absent.csv", "x");
    FAIL();
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("absent.csv: no such file (expected a source track"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
