// The ground through the far sidelobes (pisco/ground.hpp, docs/ground.md): the model map, the horizon
// frame of constant-elevation scans against the sky's, far sidelobes against their formula, the ground's
// TOD against a brute-force sum of the analytic beam over the ground, and a run with [ground]: its TOD
// is the ground engine's at the horizon pointing, the same at the same azimuth hours apart (the Earth
// carries the ground), and its maps and account.
#include <gtest/gtest.h>

#include <healpix_base.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/ground.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/scan.hpp"
#include "pisco/simulation.hpp"
#include "pisco/tod_file.hpp"
#include "pisco/units.hpp"
#include "support.hpp"

namespace {
namespace fs = std::filesystem;
using pisco::deg;
constexpr double pi = std::numbers::pi;
using V3 = std::array<double, 3>;

double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// The antenna basis (theta', phi', p') of a pointing (docs/physics.md): R_z(phi) R_y(theta) R_z(psi).
std::array<V3, 3> basis(double theta, double phi, double psi) {
  const double ct = std::cos(theta), st = std::sin(theta), cp = std::cos(phi), sp = std::sin(phi),
               cs = std::cos(psi), ss = std::sin(psi);
  return {V3{cp * ct * cs - sp * ss, sp * ct * cs + cp * ss, -st * cs},
          V3{-cp * ct * ss - sp * cs, -sp * ct * ss + cp * cs, st * ss}, V3{st * cp, st * sp, ct}};
}

TEST(Ground, TheModelIsItsHorizon) {
  pisco::GroundModel m;
  m.value = 3.0;
  m.horizon = {10 * deg, 30 * deg, 20 * deg, 0.0};  // at azimuths 0, 90, 180, 270 deg
  m.width = 4 * deg;
  const int nside = 64;
  const pisco::Sky g = pisco::ground_sky(nside, m, "K_RJ");
  EXPECT_EQ(g.units(), "K_RJ");
  const Healpix_Base base(nside, RING, SET_NSIDE);
  std::size_t below = 0, edge = 0;
  for (int p = 0; p < int(g.npix()); ++p) {
    const pointing at = base.pix2ang(p);
    const double el = pi / 2 - at.theta;
    double az = std::fmod(-at.phi, 2 * pi);
    if (az < 0) az += 2 * pi;
    // The horizon written out: linear between the four, periodic.
    const double x = az / (pi / 2);
    const int k = std::min(3, int(x));
    const double h = (1 - (x - k)) * m.horizon[std::size_t(k)] + (x - k) * m.horizon[std::size_t((k + 1) % 4)];
    const double d = el - h;
    const double expected = d <= -2 * deg ? 3.0 : d >= 2 * deg ? 0.0 : 1.5 * (1 - std::sin(pi * d / (4 * deg)));
    ASSERT_NEAR(g.I()[std::size_t(p)], expected, 1e-12) << "pixel " << p;
    below += expected == 3.0;
    edge += expected > 0 && expected < 3;
    EXPECT_EQ(g.Q()[std::size_t(p)], 0.0);
  }
  EXPECT_GT(below, g.npix() / 3);
  EXPECT_GT(edge, 100u);
  // Azimuth 90 deg (east) is longitude -90 deg: its horizon is the highest, 30 deg.
  EXPECT_EQ(g.I()[std::size_t(base.ang2pix(pointing(pi / 2 - 25 * deg, -pi / 2)))], 3.0);
  EXPECT_EQ(g.I()[std::size_t(base.ang2pix(pointing(pi / 2 - 25 * deg, pi / 2)))], 0.0);

  const auto refused = [&](pisco::GroundModel bad, const std::string& needle) {
    try {
      (void)pisco::ground_sky(8, bad, "K_RJ");
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const pisco::Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  pisco::GroundModel bad = m;
  bad.horizon = {};
  refused(bad, "at least one elevation");
  bad.horizon = {0.0, 95 * deg};
  refused(bad, "the horizon's elevation 1 is 95 deg");
  bad = m;
  bad.width = -1 * deg;
  refused(bad, "the horizon's width");
  bad = m;
  bad.value = std::nan("");
  refused(bad, "the brightness must be finite");
  EXPECT_THROW((void)pisco::ground_sky(3, m, "K"), pisco::Error);

  // Rayleigh-Jeans to the sky's units.
  EXPECT_EQ(pisco::rayleigh_jeans_in("K_RJ", 270.0, 0.0), 270.0);
  EXPECT_EQ(pisco::rayleigh_jeans_in("uK_RJ", 270.0, 0.0), 270e6);
  const double x = 6.62607015e-34 * 90e9 / (1.380649e-23 * 2.72548);
  EXPECT_NEAR(pisco::rayleigh_jeans_in("K_CMB", 1.0, 90.0), std::pow(std::expm1(x), 2) / (x * x * std::exp(x)), 1e-15);
  EXPECT_THROW((void)pisco::rayleigh_jeans_in("K_CMB", 1.0, 0.0), pisco::Error);
  EXPECT_THROW((void)pisco::rayleigh_jeans_in("MJy/sr", 1.0, 90.0), pisco::Error);
}

// CesScan::generate_horizon is generate()'s boresight seen in the horizon frame: the rotation that takes
// the horizon frame (x north, y west, z zenith) to the equatorial frame of date at each sample,
// columns (N, W, Z) from the site's latitude and local sidereal time, takes the horizon basis
// (theta', phi', p') onto the equatorial one, at every sample, boresight rotation and site.
TEST(Ground, TheHorizonPointingIsTheSkyPointingTurned) {
  for (const double latitude : {-22.96 * deg, 45.0 * deg, 89.0 * deg, -70.0 * deg}) {
    pisco::CesScan s;
    s.latitude = latitude;
    s.longitude = -67.79 * deg;
    s.elevation = 40 * deg;
    s.az_centre = 100 * deg;
    s.az_throw = 300 * deg;
    s.sample_rate = 0.05;
    s.start_unix = 1.7e9;
    s.boresight_angles = {-45 * deg, 0.0, 30 * deg};
    s.boresight_period = 4000.0;
    s.samples = 2000;
    pisco::Pointing sky, horizon;
    s.generate(0, s.samples, sky);
    s.generate_horizon(0, s.samples, horizon);
    double worst = 0;
    for (std::size_t i = 0; i < s.samples; ++i) {
      const double lst = s.local_sidereal_time(i), sl = std::sin(latitude), cl = std::cos(latitude);
      const V3 zenith{cl * std::cos(lst), cl * std::sin(lst), sl};
      const V3 north{-sl * std::cos(lst), -sl * std::sin(lst), cl};
      const V3 west{zenith[1] * north[2] - zenith[2] * north[1], zenith[2] * north[0] - zenith[0] * north[2],
                    zenith[0] * north[1] - zenith[1] * north[0]};
      const auto h = basis(horizon.theta[i], horizon.phi[i], horizon.psi[i]);
      const auto e = basis(sky.theta[i], sky.phi[i], sky.psi[i]);
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) {
          const double turned = north[std::size_t(c)] * h[std::size_t(a)][0] + west[std::size_t(c)] * h[std::size_t(a)][1] +
                                zenith[std::size_t(c)] * h[std::size_t(a)][2];
          worst = std::max(worst, std::abs(turned - e[std::size_t(a)][std::size_t(c)]));
        }
      // The horizon frame itself: colatitude 90 deg - elevation, longitude -azimuth.
      ASSERT_NEAR(horizon.theta[i], pi / 2 - s.elevation, 1e-15);
      ASSERT_NEAR(std::remainder(horizon.phi[i] + s.azimuth(i), 2 * pi), 0.0, 1e-12);
    }
    EXPECT_LT(worst, 1e-12) << "latitude " << latitude / deg;
  }
}

// A far sidelobe (docs/beams.md, "Far sidelobes"): the beam at points on the main lobe and on the ring
// against B = exp(-rho^2 / 2 s^2) + L exp(-(rho - r0)^2 / 2 w^2) (1 + a cos(sigma - s0)) / (1 + a); Omega~
// against a quadrature of that written out here; split or whole, the same beam; a ring made asymmetric
// keeps the split's band limit (the outer part's mean profile is the same); the errors.
TEST(Ground, FarSidelobesAreTheirFormula) {
  const double fwhm = 1.5 * deg, s = fwhm / std::sqrt(8 * std::log(2.0));
  pisco::BeamOptions o;
  o.rho_max = 80 * deg;
  o.far_sidelobe = {1e-4, 50 * deg, 6 * deg, pi, 0.8};
  const auto formula = [&](double rho, double sigma) {
    const double r = (rho - 50 * deg) / (6 * deg);
    return std::exp(-rho * rho / (2 * s * s)) + 1e-4 * std::exp(-0.5 * r * r) * (1 + 0.8 * std::cos(sigma - pi)) / 1.8;
  };
  pisco::BeamOptions split = o;
  split.split.rho_main = 8 * deg;
  const pisco::Beamsor whole = pisco::Beamsor::gaussian(fwhm, [&] {
    pisco::BeamOptions coarse = o;
    coarse.grid_step = 0.2 * deg;  // the whole 80 deg grid at the main beam's step would be 2 GB
    return coarse;
  }());
  const pisco::Beamsor parts = pisco::Beamsor::gaussian(fwhm, split);
  ASSERT_NE(parts.sidelobes(), nullptr);
  for (const auto& [rho, sigma] : std::vector<std::pair<double, double>>{
           {45 * deg, pi}, {50 * deg, pi}, {50 * deg, 0.3}, {56 * deg, 2.5}, {70 * deg, 3.0}, {30 * deg, pi}}) {
    const double x = std::sin(rho) * std::cos(sigma), y = std::sin(rho) * std::sin(sigma);
    const double expected = formula(rho, sigma);
    EXPECT_NEAR(parts.sidelobes()->at(x, y)[0][0], expected, 2e-3 * 1e-4) << rho / deg << ", " << sigma;
    EXPECT_NEAR(whole.at(x, y)[0][0], expected, 2e-3 * 1e-4) << rho / deg << ", " << sigma;
  }
  EXPECT_NEAR(parts.at(0.0, 0.0)[0][0], 1.0, 1e-4);  // the grid's interpolation at the peak
  // Omega~: the cap integral of the formula, Gauss-Legendre in rho (800 panels of 5 nodes, the nodes
  // and weights written out), 720 midpoints in sigma.
  const double gx[5] = {-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831, 0.9061798459386640};
  const double gw[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665, 0.2369268850561891};
  double omega = 0;
  const int panels = 800, ns = 720;
  for (int i = 0; i < panels; ++i) {
    const double a = i * o.rho_max / panels, h = o.rho_max / panels;
    for (int g = 0; g < 5; ++g) {
      const double rho = a + 0.5 * h * (1 + gx[g]);
      double ring = 0;
      for (int k = 0; k < ns; ++k) ring += formula(rho, (k + 0.5) * 2 * pi / ns);
      omega += 0.5 * h * gw[g] * ring * 2 * pi / ns * std::sin(rho);
    }
  }
  EXPECT_NEAR(parts.omega_tilde(), omega, 1e-6 * omega);
  EXPECT_NEAR(whole.omega_tilde(), omega, 1e-6 * omega);
  EXPECT_GT(omega, 1.08 * 2 * pi * s * s);  // the ring holds 8% of it
  // The split's band limit: the ring's, whether or not it is asymmetric.
  pisco::BeamOptions round = split;
  round.far_sidelobe.asymmetry = 0.0;
  const int band = pisco::Beamsor::gaussian(fwhm, round).sidelobe_band_limit();
  EXPECT_LT(band, 100);
  EXPECT_EQ(parts.sidelobe_band_limit(), band);
  EXPECT_EQ(pisco::Beamsor::elliptical_gaussian(fwhm, 1.0001 * fwhm, 0.3, round).sidelobe_band_limit(), band);

  for (const auto& [far, needle] : std::vector<std::pair<pisco::FarSidelobe, std::string>>{
           {{-1.0, 50 * deg, 6 * deg, 0, 0}, "far_sidelobe.level: expected a finite power ratio"},
           {{1e-4, 85 * deg, 6 * deg, 0, 0}, "far_sidelobe.radius: the ring's radius, 85 deg, must lie in (0, rho_max = 80 deg]"},
           {{1e-4, 50 * deg, 0.0, 0, 0}, "far_sidelobe.width: expected a positive width"},
           {{1e-4, 50 * deg, 6 * deg, 0, 1.5}, "far_sidelobe.asymmetry: expected a number in [0, 1]"}}) {
    pisco::BeamOptions b = split;
    b.far_sidelobe = far;
    try {
      (void)pisco::Beamsor::gaussian(fwhm, b);
      ADD_FAILURE() << needle;
    } catch (const pisco::Error& e) {
      EXPECT_NE(e.named().find(needle), std::string::npos) << e.named();
    }
  }
}

// The ground's TOD against a brute-force sum: a detector at 10 deg elevation with a 5 deg Gaussian beam
// and a far sidelobe ring, over a horizon that rises from 0 to 20 deg around the compass (3 deg across),
// summed by the engine (split at 12 deg: the main part on the NSIDE 128 ground map, the ring on its
// band-limited copy) and, here, over every pixel of that map within rho_max with the formula: gain/2
// (1 + eps) sum Omega_pix B G / Omega~.
TEST(Ground, TheGroundsTodIsTheBeamOverTheGround) {
  const double fwhm = 5 * deg, s = fwhm / std::sqrt(8 * std::log(2.0));
  pisco::BeamOptions o;
  o.rho_max = 60 * deg;
  o.split.rho_main = 12 * deg;
  o.far_sidelobe = {1e-3, 35 * deg, 5 * deg, pi, 1.0};
  const pisco::Beamsor beam = pisco::Beamsor::gaussian(fwhm, o);
  const auto formula = [&](double rho, double sigma) {
    const double r = (rho - 35 * deg) / (5 * deg);
    return std::exp(-rho * rho / (2 * s * s)) + 1e-3 * std::exp(-0.5 * r * r) * (1 + std::cos(sigma - pi)) / 2;
  };
  pisco::GroundModel m;
  m.value = 300.0;
  m.horizon = {0.0, 5 * deg, 20 * deg, 10 * deg, 2 * deg};
  m.width = 3 * deg;
  const pisco::Sky fine = pisco::ground_sky(128, m, "K_RJ");
  const pisco::Sky& coarse = fine;
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "d";
  fp.add(d);
  std::vector<double> az, psi;
  for (int k = 0; k < 12; ++k) {
    az.push_back(k * 30 * deg);
    psi.push_back(pi + (k % 3) * 0.4);
  }
  pisco::Pointing p;
  for (std::size_t k = 0; k < az.size(); ++k) p.push_back(pi / 2 - 10 * deg, std::fmod(2 * pi - az[k], 2 * pi), psi[k]);
  // The brute-force sum, once.
  std::vector<double> expected(az.size());
  const Healpix_Base base(128, RING, SET_NSIDE);
  const double area = 4 * pi / double(fine.npix());
  for (std::size_t k = 0; k < az.size(); ++k) {
    const auto b = basis(p.theta[k], p.phi[k], p.psi[k]);
    double sum = 0;
    for (std::size_t q = 0; q < fine.npix(); ++q) {
      if (fine.I()[q] == 0) continue;
      const vec3 v = base.pix2vec(int(q));
      const V3 u{v.x, v.y, v.z};
      const double x = dot(u, b[0]), y = dot(u, b[1]), z = dot(u, b[2]);
      const double rho = std::atan2(std::hypot(x, y), z);
      if (rho > o.rho_max) continue;
      sum += area * formula(rho, std::atan2(y, x)) * fine.I()[q];
    }
    expected[k] = 0.5 * sum / beam.omega_tilde();
  }
  // Every backend here: the float32 ones resolve the sum to about 1e-7 of the ground's 300 K
  // (docs/ground.md, "Precision"), 1e-5 of this pickup.
  for (const pisco::BackendInfo& b : pisco::Engine::backends()) {
    if (!b.available || b.name == "cuda") continue;
    pisco::EngineOptions eo;
    eo.backend = b.name;
    eo.quadrature = pisco::Quadrature::plain;  // the main part as the pixel sum above
    pisco::Engine engine(coarse, std::vector<pisco::Beamsor>{beam}, fp, eo);
    std::vector<double> tod(az.size());
    engine.convolve(0, p.view(), tod);
    double worst = 0, peak = 0;
    for (std::size_t k = 0; k < az.size(); ++k) {
      worst = std::max(worst, std::abs(tod[k] - expected[k]));
      peak = std::max(peak, std::abs(expected[k]));
      std::printf("%s, az %5.0f deg: engine %.6f K, brute force %.6f K\n", b.name.c_str(), az[k] / deg, tod[k],
                  expected[k]);
    }
    EXPECT_GT(peak, 1.0);
    EXPECT_LT(worst, 5e-5 * peak) << b.name;
  }
}

// The float32 backends' monopole (docs/vulkan.md, "Precision") is taken out only of maps it dominates:
// a sky bright over a cap and zero elsewhere (a ground below its horizon, a galaxy beside empty sky)
// convolved where the discs hold only zeros gives zero on every backend, where taking its mean out
// left 1e-8 of the cap's brightness in every sample; and the ground of a -80 dB far sidelobe is the
// reference's to 2e-7 on every backend (6e-2 on simd before).
TEST(Ground, BrightRegionsElsewhereLeaveNothingOnFloat32Backends) {
  const int nside = 64;
  pisco::Sky sky(nside);
  const Healpix_Base base(nside, RING, SET_NSIDE);
  for (int p = 0; p < int(sky.npix()); ++p)
    if (base.pix2ang(p).theta > 150 * deg) sky.I()[std::size_t(p)] = 1e6;
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "d";
  fp.add(d);
  pisco::BeamOptions o;
  o.rho_max = 8 * deg;
  const pisco::Beamsor round = pisco::Beamsor::gaussian(3 * deg, o);
  pisco::Pointing p;
  for (int k = 0; k < 40; ++k) p.push_back((20 + 2.5 * k) * deg, 7.5 * k * deg, 0.1 * k);
  pisco::GroundModel g;
  g.value = 1.0;
  g.horizon = {3 * deg, 6 * deg, 12 * deg, 9 * deg, 4 * deg, 2 * deg, 1 * deg, 2 * deg};
  g.width = 1 * deg;
  const pisco::Sky ground = pisco::ground_sky(64, g, "K_RJ");
  pisco::BeamOptions far;
  far.rho_max = 80 * deg;
  far.split.rho_main = 8 * deg;
  far.far_sidelobe = {1e-8, 50 * deg, 6 * deg, pi, 1.0};
  const pisco::Beamsor spill = pisco::Beamsor::gaussian(1.5 * deg, far);
  pisco::Pointing h;
  for (int k = 0; k < 18; ++k) h.push_back(45 * deg, 20 * k * deg, pi);
  std::vector<double> reference;
  for (const pisco::BackendInfo& b : pisco::Engine::backends()) {
    if (!b.available || b.name == "cuda") continue;
    pisco::EngineOptions eo;
    eo.backend = b.name;
    std::vector<double> tod(p.size());
    pisco::Engine(sky, std::vector<pisco::Beamsor>{round}, fp, eo).convolve(0, p.view(), tod);
    for (std::size_t k = 0; k < tod.size(); ++k) EXPECT_EQ(tod[k], 0.0) << b.name << ", sample " << k;
    std::vector<double> pickup(h.size());
    pisco::Engine(ground, std::vector<pisco::Beamsor>{spill}, fp, eo).convolve(0, h.view(), pickup);
    if (reference.empty()) reference = pickup;  // cpu, listed first
    double worst = 0, scale = 0;
    for (std::size_t k = 0; k < h.size(); ++k) {
      worst = std::max(worst, std::abs(pickup[k] - reference[k]));
      scale = std::max(scale, std::abs(reference[k]));
    }
    std::printf("%s: a -80 dB far sidelobe's ground, %.3e of the brightness, within %.2e of the reference\n",
                b.name.c_str(), scale, worst / scale);
    EXPECT_GT(scale, 1e-7);
    EXPECT_LT(worst, 2e-7 * scale) << b.name;
  }
}

class GroundRun : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = pisco_test::fresh_test_dir("ground"); }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path config(const std::string& name, const std::string& ground, const std::string& scan_extra = "") {
    const fs::path p = dir_ / (name + ".toml");
    std::ofstream(p) << "[sky]\nnside = 32\nlmax = 64\nseed = 3\n"
                        "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 70.0\nsidelobe_split_deg = 16\n"
                        "far_sidelobe_db = -40\nfar_sidelobe_deg = 50\nfar_sidelobe_width_deg = 6\n"
                        "far_sidelobe_angle_deg = 180\nfar_sidelobe_asymmetry = 0.5\n"
                        "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
                        "[[focal_plane.detectors]]\nname = \"o\"\nbeam = \"main\"\nzeta_deg = 20\nxi_deg = 3\neta_deg = -2\n"
                        "[scan]\ntype = \"ces\"\nelevation_deg = 35\naz_throw_deg = 90\naz_speed_deg_s = 1\n"
                        "sample_rate_hz = 1\nduration_hours = 3\nnside = 16\n"
                     << scan_extra
                     << "[engine]\nbackend = \"cpu\"\nnormalization = \"integral\"\nchunk_samples = 700\n"
                        "[output]\ndir = \""
                     << (dir_ / name).string() << "\"\nplots = false\nlmax = 32\ntod_pointing = true\n"
                     << ground;
    return p;
  }
  fs::path dir_;
};

// A run with [ground] adds to each detector's TOD the ground engine's TOD at the scan's horizon
// pointing; that TOD repeats wherever the azimuth and boresight repeat, hours apart, while the sky's
// does not; the account's figures are its own; the maps of the ground's TOD alone are written.
TEST_F(GroundRun, TheGroundTurnsWithTheEarth) {
  const std::string ground = "[ground]\ntemperature_k = 270\nfrequency_ghz = 90\nhorizon_deg = [2, 8, 15, 4]\n"
                             "horizon_width_deg = 2\nnside = 32\n";
  const pisco::SimulationResult with = pisco::Simulation::from_file(config("with", ground)).run();
  (void)pisco::Simulation::from_file(config("without", "")).run();
  const pisco::SimulationConfig c = pisco::read_simulation_file(config("with", ground));
  EXPECT_TRUE(fs::exists(dir_ / "with" / "ground_maps.fits"));
  EXPECT_TRUE(fs::exists(dir_ / "with" / "ground_spectra.txt"));
  // The ground engine, written out: the model map, the run's beams, the horizon pointing.
  const pisco::Sky sky(32, "uK_CMB");
  const pisco::Sky gmap = pisco::make_ground_sky(c.ground, sky, c.source);
  EXPECT_NEAR(*std::max_element(gmap.I().begin(), gmap.I().end()), 270e6 * pisco::rayleigh_jeans_in("K_CMB", 1.0, 90.0),
              1e-6);
  const pisco::SimulationBeams made = pisco::make_beams(c);
  const pisco::FocalPlane fp(made.detectors);
  pisco::Engine ground_engine = pisco::make_engine(gmap, made.beams, fp, c);
  const pisco::CesScan& ces = c.scan.ces;
  pisco::Pointing horizon;
  ces.generate_horizon(0, ces.samples, horizon);
  double sum = 0, n = 0, variance = 0, peak = 0;
  for (std::size_t k = 0; k < fp.size(); ++k) {
    const std::vector<double> a = pisco::read_tod_signal(dir_ / "with" / "tod.h5", fp[k].name);
    const std::vector<double> b = pisco::read_tod_signal(dir_ / "without" / "tod.h5", fp[k].name);
    std::vector<double> g(ces.samples);
    ground_engine.convolve(k, horizon.view(), g);
    ASSERT_EQ(a.size(), g.size());
    double scale = 0, worst = 0, s1 = 0, s2 = 0;
    for (std::size_t i = 0; i < a.size(); ++i) scale = std::max(scale, std::abs(g[i]));
    for (std::size_t i = 0; i < a.size(); ++i) {
      worst = std::max(worst, std::abs((a[i] - b[i]) - g[i]));
      s1 += g[i];
      s2 += g[i] * g[i];
    }
    EXPECT_GT(scale, 1e3) << fp[k].name;  // microkelvin: the ring sees the ground
    EXPECT_LT(worst, 1e-9 * scale) << fp[k].name;
    // The same azimuth 3 sweeps (540 s) and 13 sweeps (2340 s) later: the same ground, another sky.
    double repeat = 0, sky_change = 0;
    for (std::size_t i = 0; i + 2340 < a.size(); i += 37) {
      repeat = std::max({repeat, std::abs(g[i + 540] - g[i]), std::abs(g[i + 2340] - g[i])});
      sky_change = std::max(sky_change, std::abs(b[i + 2340] - b[i]));
    }
    EXPECT_LT(repeat, 1e-9 * scale) << fp[k].name;
    EXPECT_GT(sky_change, 1.0) << fp[k].name;
    const double mean = s1 / double(a.size());
    sum += s1;
    n += double(a.size());
    variance += s2 / double(a.size()) - mean * mean;
    peak = std::max(peak, *std::max_element(g.begin(), g.end()) - *std::min_element(g.begin(), g.end()));
  }
  EXPECT_NEAR(with.ground_mean, sum / n, 1e-9 * std::abs(with.ground_mean));
  EXPECT_NEAR(with.ground_rms, std::sqrt(variance / double(fp.size())), 1e-6 * with.ground_rms);
  EXPECT_NEAR(with.ground_peak_to_peak, peak, 1e-9 * peak);
  EXPECT_GT(with.ground_rms, 1.0);

  // A ground map file is the model's map: the same TOD.
  gmap.write_fits(dir_ / "ground.fits");
  (void)pisco::Simulation::from_file(config("file", "[ground]\nfile = \"ground.fits\"\n")).run();
  for (std::size_t k = 0; k < fp.size(); ++k)
    EXPECT_EQ(pisco::read_tod_signal(dir_ / "file" / "tod.h5", fp[k].name),
              pisco::read_tod_signal(dir_ / "with" / "tod.h5", fp[k].name));
}

TEST_F(GroundRun, MistakesAreNamed) {
  const auto refused = [&](const std::string& name, const std::string& ground, const std::string& scan_extra,
                           const std::string& needle) {
    try {
      pisco::Simulation::from_file(config(name, ground, scan_extra)).run();
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const pisco::Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  refused("cmb", "[ground]\ntemperature_k = 270\n", "", "[ground] temperature_k: ground: a ground temperature in uK_CMB needs the frequency");
  refused("edge", "[ground]\nhorizon_deg = [0, 95]\nfrequency_ghz = 90\n", "", "[ground] horizon_deg: expected elevations within (-90, 90) deg, got 95");
  refused("width", "[ground]\nhorizon_width_deg = -1\nfrequency_ghz = 90\n", "", "[ground] horizon_width_deg");
  refused("nside", "[ground]\nnside = 3\nfrequency_ghz = 90\n", "", "[ground] nside: expected a power of two");
  refused("both", "[ground]\nfile = \"both.toml\"\nnside = 8\n", "", "[ground] nside: a ground map file (file) takes no model keys");
  refused("missing", "[ground]\nfile = \"nowhere.fits\"\n", "", "[ground] file: ");
  refused("typo", "[ground]\ntemperature = 270\nfrequency_ghz = 90\n", "", "unknown key 'temperature'");
  std::ofstream(dir_ / "rj.fits");
  pisco::Sky rj(8, "K_RJ");
  rj.write_fits(dir_ / "rj.fits");
  refused("units", "[ground]\nfile = \"rj.fits\"\n", "", "is in 'K_RJ', the sky in 'uK_CMB'");
  const fs::path sat = dir_ / "sat.toml";
  std::ofstream(sat) << "[sky]\nnside = 8\n[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 10.0\nrho_max_deg = 20.0\n"
                        "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
                        "[scan]\ntype = \"satellite\"\nduration_hours = 0.01\n[ground]\n";
  try {
    (void)pisco::read_simulation_file(sat);
    ADD_FAILURE() << "a satellite's ground";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("[ground]: the ground is seen from constant-elevation scans"), std::string::npos)
        << e.what();
  }
}

}  // namespace
