// Half-wave plates on the float64 reference (docs/physics.md, "Half-wave plates";
// docs/validation.md, "H"): the ideal-plate identity, a generic plate in both placements against a
// brute-force evaluation of the plate equations, the angle streams, the map-maker's plate-modulated
// model, and errors.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>
#include <random>

#include <healpix_base.h>
#include <pointing.h>

#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/hwp.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/scan.hpp"
#include "backend_fixtures.hpp"
#include "support.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;
using Mat = pisco::Mueller;

Mat mul(const Mat& a, const Mat& b) {
  Mat c{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

// Lambda(-chi): the sky's Stokes vector in the detector's co-polar basis at the pixel.
Mat lambda_minus(double chi) {
  Mat m{};
  m[0][0] = m[3][3] = 1;
  m[1][1] = m[2][2] = std::cos(2 * chi);
  m[1][2] = std::sin(2 * chi);
  m[2][1] = -std::sin(2 * chi);
  return m;
}

// R(a) of hwp.hpp, written out: rows (1,0,0,0), (0,c,s,0), (0,-s,c,0), (0,0,0,1), c = cos 2a.
Mat stokes_rotation(double a) { return lambda_minus(a); }

Mat plate_at(const Mat& m0, double theta) {
  Mat rt = stokes_rotation(-theta);
  return mul(rt, mul(m0, stokes_rotation(theta)));
}

// The plate equations evaluated pixel by pixel with HEALPix query_disc and the paper's Appendix A
// angles: aperture d = sum_k Omega D(0) B_k M Lambda(-chi_k) S_k / Omega~, detector placement
// d = sum_k Omega D(0) M B_k Lambda(-chi_k) S_k / Omega~.
double brute_force(const pisco::Sky& sky, const pisco::Beamsor& beam, const pisco::Detector& det, double theta0,
                   double phi0, double psi0, const Mat& m, bool aperture) {
  const Healpix_Base base(sky.nside(), RING, SET_NSIDE);
  std::vector<int> pixels;
  base.query_disc(pointing(theta0, phi0), beam.rho_max()).toVector(pixels);
  const double d0[4] = {det.gain / 2 * (1 + det.epsilon), det.gain / 2 * (1 - det.epsilon), 0, 0};
  double d = 0;
  for (int p : pixels) {
    const ::pointing ang = base.pix2ang(p);
    const double dphi = ang.phi - phi0;
    const double st = std::sin(ang.theta), ct = std::cos(ang.theta), st0 = std::sin(theta0), ct0 = std::cos(theta0);
    const double cos_rho = ct * ct0 + st * st0 * std::cos(dphi);
    const double sin_rho = std::sqrt(std::max(0.0, 1 - cos_rho * cos_rho));
    const double alpha = std::atan2(st * std::sin(dphi), ct * st0 - st * ct0 * std::cos(dphi));
    const double sigma = pi - psi0 - alpha;
    const double beta = std::atan2(st0 * std::sin(dphi), ct0 * st - st0 * ct * std::cos(dphi));
    const double chi = beta + det.zeta - sigma;
    const Mat B = beam.at(sin_rho * std::cos(sigma), sin_rho * std::sin(sigma));
    const Mat chain = aperture ? mul(B, mul(m, lambda_minus(chi))) : mul(m, mul(B, lambda_minus(chi)));
    const double S[4] = {sky.I()[p], sky.Q()[p], sky.U()[p], sky.V()[p]};
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) d += sky.pixel_area() * d0[i] * chain[i][j] * S[j] / beam.omega_tilde();
  }
  return d;
}

pisco::Sky random_sky(int nside, std::uint64_t seed) {
  pisco::Sky sky(nside);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  for (std::size_t i = 0; i < sky.npix(); ++i) {
    sky.I()[i] = 10 + g(rng);
    sky.Q()[i] = g(rng);
    sky.U()[i] = g(rng);
    sky.V()[i] = 0.3 * g(rng);
  }
  return sky;
}

pisco::Pointing random_pointing(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing p;
  for (std::size_t i = 0; i < n; ++i) p.push_back(std::acos(1 - 2 * u(rng)), 2 * pi * u(rng), 2 * pi * u(rng) - pi);
  for (std::size_t i = 0; i < n / 10; ++i) p.push_back(u(rng) * 5 * deg, 2 * pi * u(rng), 2 * pi * u(rng));
  return p;
}

// A plate with all 16 entries non-zero (a non-ideal HWP with leakage everywhere).
using pisco_test::generic_plate;

double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / double(v.size()));
}

// H1: an ideal plate before a round beam rotates the polarization by twice its angle:
// d(psi0, h) = plate-less d(psi0 + 2 (h - gamma)), for continuous and stepped streams, a PSB pair and
// detectors whose gamma is not zero.
TEST(Hwp, IdealPlateIsARotationOfThePolarization) {
  const pisco::Sky sky = random_sky(64, 3);
  pisco::BeamOptions o;
  o.rho_max = 7 * deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(3 * deg, o)};
  pisco::FocalPlane plain;
  plain.add_pair("p", 20 * deg, 0, 0, 0.05, 1.1, 0.9);
  plain.add({"s", -35 * deg, 0.02, 1.3, 0});
  std::vector<pisco::Detector> with = plain.detectors();
  const double gammas[] = {0.0, 0.7, -1.9};
  for (std::size_t i = 0; i < with.size(); ++i) with[i].hwp = pisco::HalfWavePlate::ideal(gammas[i]);
  pisco::Engine a(sky, beams, pisco::FocalPlane(with), {.backend = "cpu", .settings = {{"threads", 2LL}}});
  pisco::Engine b(sky, beams, plain, {.backend = "cpu", .settings = {{"threads", 2LL}}});
  const pisco::Pointing p = random_pointing(400, 5);
  pisco::HwpAngleStream continuous;
  continuous.frequency_hz = 1.3;
  continuous.phase = 0.4;
  continuous.sample_rate = 19;
  pisco::HwpAngleStream stepped;
  stepped.kind = pisco::HwpAngleStream::Kind::stepped;
  stepped.steps = {0.0, 22.5 * deg, 45 * deg, 67.5 * deg};
  stepped.step_seconds = 0.5;
  stepped.sample_rate = 10;
  for (const auto* stream : {&continuous, &stepped}) {
    std::vector<double> h;
    stream->generate(0, p.size(), h);
    for (std::size_t d = 0; d < with.size(); ++d) {
      std::vector<double> got(p.size(), NAN), want(p.size(), NAN);
      a.convolve(d, p, got, false, h);
      pisco::Pointing turned = p;
      for (std::size_t i = 0; i < p.size(); ++i) turned.psi[i] += 2 * (h[i] - gammas[d]);
      b.convolve(d, turned, want);
      double worst = 0;
      for (std::size_t i = 0; i < p.size(); ++i) worst = std::max(worst, std::abs(got[i] - want[i]));
      std::cout << with[d].name << (stream == &stepped ? " (stepped)" : " (continuous)")
                << ": max |d_plate - d(psi + 2 theta)| / rms " << worst / rms(want) << "\n";
      EXPECT_LT(worst, 1e-13 * rms(want)) << with[d].name;
    }
  }
}

// H2: a generic plate (16 non-zero entries), elliptical beams with cross-polar response and Mueller
// leakage, both placements, against the plate equations evaluated pixel by pixel.
TEST(Hwp, GenericPlateMatchesBruteForceInBothPlacements) {
  const pisco::Sky sky = random_sky(64, 7);
  pisco::BeamOptions o;
  o.rho_max = 8 * deg;
  o.cross_polar = 0.05;
  o.cross_polar_pattern = pisco::CrossPolarPattern::quadrupole;
  o.mueller[1][0] = 0.003;
  o.mueller[3][3] = 0.5;
  o.mueller[2][3] = 0.02;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::elliptical_gaussian(3.0 * deg, 2.2 * deg, 25 * deg, o)};
  o.cross_polar_pattern = pisco::CrossPolarPattern::uniform;
  beams.push_back(pisco::Beamsor::gaussian(2.5 * deg, o));
  const Mat m0 = generic_plate();
  pisco::FocalPlane fp;
  for (int placement = 0; placement < 2; ++placement)
    for (std::size_t beam = 0; beam < beams.size(); ++beam) {
      pisco::Detector d{"d" + std::to_string(placement) + std::to_string(beam), (15.0 + 40 * double(beam)) * deg,
                        0.03, 1.1, beam};
      d.hwp = pisco::HalfWavePlate{m0, placement == 0 ? pisco::HwpPlacement::aperture : pisco::HwpPlacement::detector,
                                   0.3 * double(beam)};
      fp.add(d);
    }
  pisco::Engine engine(sky, beams, fp, {.backend = "cpu", .settings = {{"threads", 2LL}}, .quadrature = pisco::Quadrature::plain});
  const pisco::Pointing p = random_pointing(60, 9);
  std::vector<double> h(p.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = 0.37 * double(i);
  double worst = 0;
  for (std::size_t d = 0; d < fp.size(); ++d) {
    std::vector<double> tod(p.size(), NAN);
    engine.convolve(d, p, tod, false, h);
    for (std::size_t i = 0; i < p.size(); ++i) {
      const Mat m = plate_at(m0, h[i] - fp[d].hwp->gamma);
      const double ref = brute_force(sky, beams[fp[d].beam], fp[d], p.theta[i], p.phi[i], p.psi[i], m,
                                     fp[d].hwp->placement == pisco::HwpPlacement::aperture);
      worst = std::max(worst, std::abs(tod[i] - ref) / std::abs(ref));
    }
  }
  std::cout << "generic plate, both placements, elliptical and round beams: max relative difference from the "
               "brute force "
            << worst << "\n";
  EXPECT_LT(worst, 1e-12);
}

TEST(Hwp, AngleStreams) {
  pisco::HwpAngleStream s;
  s.frequency_hz = 2.0;
  s.phase = 0.25;
  s.sample_rate = 100;
  s.start_time = 10.0;
  std::vector<double> a, b;
  s.generate(0, 500, a);
  for (std::size_t i = 0; i < a.size(); ++i)
    EXPECT_NEAR(std::remainder(a[i] - (2 * pi * 2.0 * (10.0 + double(i) / 100) + 0.25), 2 * pi), 0.0, 1e-12);
  s.generate(137, 50, b);  // chunks: the same angles
  for (std::size_t i = 0; i < b.size(); ++i) EXPECT_EQ(b[i], a[137 + i]);
  pisco::HwpAngleStream st;
  st.kind = pisco::HwpAngleStream::Kind::stepped;
  st.steps = {0.1, 0.2, 0.3};
  st.step_seconds = 2.0;
  st.sample_rate = 1.0;
  st.generate(0, 13, a);
  const double want[] = {0.1, 0.1, 0.2, 0.2, 0.3, 0.3, 0.1, 0.1, 0.2, 0.2, 0.3, 0.3, 0.1};
  for (int i = 0; i < 13; ++i) EXPECT_EQ(a[i], want[i]);
  st.steps.clear();
  pisco_test::expect_error([&] { st.check(); }, "at least one angle");
  st.steps = {0.0};
  st.step_seconds = 0;
  pisco_test::expect_error([&] { st.check(); }, "step_seconds");
  s.sample_rate = -1;
  pisco_test::expect_error([&] { s.check(); }, "sample_rate");
}

TEST(Hwp, ErrorsNameTheDetectorAndSample) {
  const pisco::Sky sky = random_sky(16, 1);
  pisco::BeamOptions o;
  o.rho_max = 10 * deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(5 * deg, o)};
  pisco::FocalPlane fp;
  fp.add({"plain", 0, 0, 1, 0});
  pisco::Detector h{"plated", 0, 0, 1, 0};
  h.hwp = pisco::HalfWavePlate::ideal();
  fp.add(h);
  pisco::Engine engine(sky, beams, fp);
  const pisco::Pointing p = random_pointing(20, 2);
  std::vector<double> tod(p.size()), angles(p.size(), 0.1);
  pisco_test::expect_error([&] { engine.convolve(1, p, tod); }, "'plated' has a half-wave plate");
  pisco_test::expect_error([&] { engine.convolve(0, p, tod, false, angles); }, "'plain' has no half-wave plate");
  angles[7] = NAN;
  pisco_test::expect_error([&] { engine.convolve(1, p, tod, false, angles); }, "sample 7");
  std::vector<pisco::Detector> bad = fp.detectors();
  bad[1].hwp->mueller[2][1] = INFINITY;
  pisco_test::expect_error([&] { pisco::Engine(sky, beams, pisco::FocalPlane(bad)); }, "'plated'");
}

// The map-maker's plate-modulated model: a scan through an ideal plate recovers the sky's smoothed
// I, Q, U as well as the plate-less scan does (the same maps, to rounding, for a round beam whose
// polarization angles the plate merely permutes), and a plate angle without a plate is an error.
TEST(Hwp, MapMakerUsesThePlateModulatedWeights) {
  const pisco::Sky sky = random_sky(32, 11);
  pisco::BeamOptions o;
  o.rho_max = 8 * deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(4 * deg, o)};
  pisco::FocalPlane plain;
  plain.add({"d", 0.3, 0.0, 1.0, 0});
  std::vector<pisco::Detector> with = plain.detectors();
  with[0].hwp = pisco::HalfWavePlate::ideal(0.2);
  const pisco::FocalPlane plated(with);
  pisco::Engine a(sky, beams, plated), b(sky, beams, plain);
  // Every NSIDE 8 pixel centre at psi = 0 only, the plate at three angles 30 deg apart: the plate
  // alone makes the polarization angles that the plate-less scan gets from psi = 0, 60, 120 deg.
  const pisco::Pointing centres = pisco::pixel_centre_scan(8, {0.0});
  pisco::Pointing p, q;
  std::vector<double> h;
  for (int k = 0; k < 3; ++k)
    for (std::size_t i = 0; i < centres.size(); ++i) {
      p.push_back(centres.theta[i], centres.phi[i], 0.0);
      h.push_back(0.2 + k * 30 * deg);
      q.push_back(centres.theta[i], centres.phi[i], 2 * k * 30 * deg);
    }
  std::vector<double> ta(p.size()), tb(q.size());
  a.convolve(0, p, ta, false, h);
  b.convolve(0, q, tb);
  pisco::BinnedMapmaker ma(8), mb(8);
  ma.add(plated[0], p, ta, h);
  mb.add(plain[0], q, tb);
  const pisco::BinnedMaps xa = ma.solve(), xb = mb.solve();
  double worst = 0, scale = 0;
  for (std::size_t i = 0; i < xa.I.size(); ++i) {
    ASSERT_NE(xa.I[i], pisco::unseen);
    worst = std::max({worst, std::abs(xa.I[i] - xb.I[i]), std::abs(xa.Q[i] - xb.Q[i]), std::abs(xa.U[i] - xb.U[i])});
    scale = std::max(scale, std::abs(xb.Q[i]));
  }
  std::cout << "maps through the plate vs plate-less maps: max difference " << worst << " (max |Q| " << scale << ")\n";
  EXPECT_LT(worst, 1e-11 * scale);
  pisco_test::expect_error([&] { mb.add(plain[0], q, tb, h); }, "no half-wave plate");
  pisco_test::expect_error([&] { ma.add(plated[0], p, ta); }, "expected");
}

}  // namespace
