// Beams that turn with a half-wave plate (Detector::plate_beams; docs/changing.md, "Beams that turn
// with the plate"): the optics and the plate simulated together at N plate angles, combined per
// sample by the trigonometric interpolant in the sample's plate angle.
//
// Brute force: an analytic beam whose shape and polarization turn with the plate, its ellipticity's
// axis and its polarization angle at 2 theta (harmonics 0 and 4 theta), at plate angles theta on and
// between the nodes, built directly as a field for each theta and convolved as a fixed beam, against
// the plate beams of 5 nodes over the plate's period pi (exact to harmonic 4 theta); with 3 nodes
// (exact to 2 theta) the 4 theta part aliases, which the comparison sees. Then the ideal plate at the
// aperture as beams (a beam times the plate's Mueller matrix at each node's angle) against the engine's
// own plate model; the adjoint's dot-product identity; the errors.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "backend_fixtures.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/hwp.hpp"

namespace {

using pisco::Beamsor;
using pisco::deg;
using pisco::Mueller;
constexpr double pi = std::numbers::pi;
constexpr double rho_max = 6 * deg, step = 0.1 * deg;

// A 2 deg Gaussian made elliptical along 2 theta (a cos(2 (sigma - 2 theta)) term) and polarized at
// 2 theta: its T row T(1 + e cos(2 sigma - 4 theta)), its Q, U block turned by 4 theta; every entry
// holds harmonics 0 and 4 theta alone.
Mueller turning_field(double rho, double sigma, double theta) {
  const double s = 2.0 * deg / std::sqrt(8 * std::log(2.0));
  const double g = std::exp(-rho * rho / (2 * s * s));
  const double e = 0.15, p = 0.97;
  const double c = std::cos(4 * theta), sn = std::sin(4 * theta);
  Mueller m{};
  m[0][0] = g * (1 + e * std::cos(2 * sigma - 4 * theta));
  m[1][1] = p * g * c;
  m[1][2] = p * g * sn;
  m[2][1] = -p * g * sn;
  m[2][2] = p * g * c;
  m[3][3] = p * g;
  return m;
}

Beamsor turning_beam(double theta) {
  return Beamsor::from_field([theta](double r, double sg) { return turning_field(r, sg, theta); }, rho_max, step,
                             "turning at " + std::to_string(theta));
}

class PlateBeams : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    const std::string why = pisco_test::backend_unavailable(GetParam());
    if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
    options.backend = GetParam();
    pisco_test::set_taken(options, "threads", 2LL);
  }
  double bar() const { return GetParam() == "cpu" ? 1e-11 : 1e-7; }
  pisco::EngineOptions options;
};

// The plate beams of `n` nodes over [0, pi) against the field built at each plate angle.
double worst_against_brute_force(const pisco::EngineOptions& options, std::size_t n, const char* backend) {
  const pisco::Sky sky = pisco_test::cmb_like_sky(64, 3, 10.0);
  std::vector<Beamsor> beams;
  pisco::Detector d;
  d.name = "turning";
  d.zeta = 0.4;
  d.set_offset(2 * deg, -1 * deg, 0.2);
  pisco::PlateBeams p;
  for (std::size_t k = 0; k < n; ++k) {
    beams.push_back(turning_beam(pi * double(k) / double(n)));
    p.beams.push_back(k);
  }
  d.plate_beams = p;
  pisco::Engine engine(sky, beams, pisco::FocalPlane({d}), options);
  const pisco::Pointing pointing = pisco_test::random_pointing(100, 7);
  double worst = 0;
  for (const double theta : {0.0, 0.2, pi / 5, 1.0, 2.0, 2.9, 4.0, -0.7}) {
    pisco::Detector fixed = d;
    fixed.plate_beams.reset();
    std::vector<double> want(pointing.size()), got(pointing.size());
    pisco::Engine(sky, {turning_beam(theta)}, pisco::FocalPlane({fixed}), options).convolve(0, pointing, want);
    const std::vector<double> h(pointing.size(), theta);
    engine.convolve(0, pointing, got, false, h);
    double w = 0, norm = 0;
    for (std::size_t i = 0; i < pointing.size(); ++i) {
      w = std::max(w, std::abs(got[i] - want[i]));
      norm += want[i] * want[i];
    }
    norm = std::sqrt(norm / double(pointing.size()));
    std::printf("%s, %zu beams, plate at %.3f rad: worst difference %.2e of the TOD's RMS\n", backend, n, theta, w / norm);
    worst = std::max(worst, w / norm);
  }
  return worst;
}

TEST_P(PlateBeams, MatchTheTurningBeamBuiltAtEachAngle) {
  EXPECT_LE(worst_against_brute_force(options, 5, GetParam().c_str()), bar());
  // Three beams hold harmonics up to 2 theta: the beam's 4 theta part is lost, which the test sees.
  if (GetParam() == "cpu") EXPECT_GT(worst_against_brute_force(options, 3, "cpu"), 1e-2);
}

// A plate at the aperture, as beams: a round Gaussian times the plate's Mueller matrix at each node's
// plate angle (the plate in front of the optics: the beam's weights times M(theta), in the beam's
// frame, whose x axis is the detector's polarization axis), N = 5 over pi, from the detector's plate
// gamma; against the same Gaussian with the engine's own plate (Detector::hwp), whose matrix holds
// harmonics 0, 2 and 4 theta alone. The ideal plate with the beams' mean Omega~; a plate with losses
// and leakage in every entry with the Gaussian's own Omega~ (PlateBeams::omega), which keeps its
// transmission (0.98) in the TOD as the plate model does; with the mean instead the TOD is 1 / 0.98 of
// the plate model's.
void plate_as_beams(const pisco::EngineOptions& options, const Mueller& m0, bool own_omega, double bar) {
  const pisco::Sky sky = pisco_test::cmb_like_sky(64, 5, 10.0);
  const double s = 2.0 * deg / std::sqrt(8 * std::log(2.0));
  const auto gauss = [s](double rho, double) {
    const double g = std::exp(-rho * rho / (2 * s * s));
    return Beamsor::stokes_mueller(g, 0.98 * g, 0.0, 0.0);
  };
  pisco::HalfWavePlate plate = pisco::HalfWavePlate::ideal();
  plate.mueller = m0;
  std::vector<Beamsor> beams;
  pisco::PlateBeams p;
  for (int k = 0; k < 5; ++k) {
    const Mueller m = pisco::rotated_mueller(m0, pi * k / 5.0);
    beams.push_back(Beamsor::from_field(
        [&](double r, double sg) {
          const Mueller b = gauss(r, sg);
          Mueller out{};
          for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
              for (int l = 0; l < 4; ++l) out[i][j] += b[i][l] * m[l][j];
          return out;
        },
        rho_max, step, "with the plate"));
    p.beams.push_back(std::size_t(k));
  }
  beams.push_back(Beamsor::from_field(gauss, rho_max, step, "without"));
  if (own_omega) p.omega = beams.back().omega_tilde();
  // A detector turned (zeta) and offset (with its own gamma): the plate's angle from the detector's
  // axis, h - gamma with gamma its polarization angle in the focal plane, for both.
  pisco::Detector as_beams;
  as_beams.name = "as beams";
  as_beams.zeta = 0.5;
  as_beams.set_offset(1.5 * deg, 0.5 * deg, 0.3);
  p.gamma = pisco::default_hwp_gamma(as_beams);
  as_beams.plate_beams = p;
  pisco::Detector modelled = as_beams;
  modelled.name = "modelled";
  modelled.plate_beams.reset();
  modelled.beam = 5;
  plate.gamma = pisco::default_hwp_gamma(as_beams);
  modelled.hwp = plate;
  pisco::Engine engine(sky, beams, pisco::FocalPlane({as_beams, modelled}), options);
  const pisco::Pointing pointing = pisco_test::random_pointing(300, 4);
  std::vector<double> h(pointing.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = 0.37 * double(i);
  std::vector<double> a(pointing.size()), b(pointing.size());
  engine.convolve(0, pointing, a, false, h);
  engine.convolve(1, pointing, b, false, h);
  double worst = 0, norm = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, std::abs(a[i] - b[i]));
    norm += b[i] * b[i];
  }
  norm = std::sqrt(norm / double(a.size()));
  std::printf("%s: the plate (M00 %.2f) as five beams, %s, against the plate model: %.2e of the TOD's RMS\n",
              options.backend.c_str(), m0[0][0], own_omega ? "the beam's own Omega~" : "their mean Omega~",
              worst / norm);
  if (bar > 0) EXPECT_LE(worst, bar * norm);
  else EXPECT_NEAR(worst / norm, 1 / m0[0][0] - 1, 2e-3);  // the mean transmission calibrated away
}

TEST_P(PlateBeams, APlateAsBeamsIsThePlateModel) {
  const double bar = GetParam() == "cpu" ? 1e-11 : 1e-5;
  plate_as_beams(options, pisco::ideal_hwp_mueller(), false, bar);
  const Mueller lossy{{{0.98, 0.005, 0.008, 0.0}, {0.006, 0.95, 0.03, 0.01}, {-0.004, 0.02, -0.94, 0.02}, {0.0, 0.01, -0.02, -0.93}}};
  plate_as_beams(options, lossy, true, bar);
  if (GetParam() == "cpu") plate_as_beams(options, lossy, false, 0.0);
}

// <A s, d> = <s, A^T d> at random plate angles.
TEST_P(PlateBeams, TheirAdjointIsTheirTranspose) {
  const int nside = 32;
  const pisco::Sky sky = pisco_test::cmb_like_sky(nside, 6, 5.0);
  std::vector<Beamsor> beams;
  pisco::Detector d;
  d.name = "turning";
  d.zeta = -0.3;
  pisco::PlateBeams p;
  p.gamma = 0.25;
  for (std::size_t k = 0; k < 4; ++k) {  // an even count: the Nyquist term
    beams.push_back(turning_beam(pi * double(k) / 4.0));
    p.beams.push_back(k);
  }
  d.plate_beams = p;
  pisco::Engine engine(sky, beams, pisco::FocalPlane({d}), options);
  const pisco::Pointing pointing = pisco_test::random_pointing(300, 2);
  std::mt19937 g(3);
  std::uniform_real_distribution<double> angle(0, 2 * pi);
  std::normal_distribution<double> n(0, 1);
  std::vector<double> h(pointing.size()), tod(pointing.size()), dd(pointing.size());
  for (double& x : h) x = angle(g);
  engine.convolve(0, pointing, tod, false, h);
  double forward = 0, t2 = 0, d2 = 0;
  for (std::size_t i = 0; i < tod.size(); ++i) {
    dd[i] = n(g);
    forward += tod[i] * dd[i];
    t2 += tod[i] * tod[i];
    d2 += dd[i] * dd[i];
  }
  pisco::Sky at(nside);
  engine.adjoint(0, pointing, dd, h);
  engine.take_adjoint({at.I(), at.Q(), at.U(), at.V()});
  double back = 0;
  for (int c = 0; c < 4; ++c)
    for (std::size_t q = 0; q < sky.npix(); ++q)
      back += sky.stokes(pisco::StokesIndex(c))[q] * at.stokes(pisco::StokesIndex(c))[q];
  const double scale = std::sqrt(t2 * d2);
  std::printf("%s: <A s, d> = %.15e, <s, A^T d> = %.15e, difference / (|A s| |d|) = %.2e\n", GetParam().c_str(),
              forward, back, std::abs(forward - back) / scale);
  EXPECT_LT(std::abs(forward - back) / scale, GetParam() == "cpu" ? 1e-12 : 1e-5);
  EXPECT_GT(std::abs(forward), 1e-3 * scale);
}

INSTANTIATE_TEST_SUITE_P(Backends, PlateBeams, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

TEST(PlateBeamsErrors, NameTheDetectorAndWhatIsWrong) {
  const pisco::Sky sky = pisco_test::cmb_like_sky(16, 1, 0.0);
  std::vector<Beamsor> beams{Beamsor::gaussian(5 * deg), Beamsor::gaussian(6 * deg)};
  const auto message = [&](const pisco::Detector& d, pisco::EngineOptions o = {}) {
    try {
      pisco::Engine(sky, beams, pisco::FocalPlane({d}), o);
    } catch (const pisco::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  pisco::Detector d;
  d.name = "turning";
  d.plate_beams = pisco::PlateBeams{{0, 1}};
  d.hwp = pisco::HalfWavePlate::ideal();
  EXPECT_NE(message(d).find("detector 'turning': has both plate_beams (beams with the plate in them) and a half-wave "
                            "plate (hwp), which would count the plate twice"),
            std::string::npos)
      << message(d);
  d.hwp.reset();
  d.plate_beams = pisco::PlateBeams{{0}};
  EXPECT_NE(message(d).find("plate_beams has 1 beams; a beam that turns with the plate needs two or more"),
            std::string::npos);
  d.plate_beams = pisco::PlateBeams{{0, 2}};
  EXPECT_NE(message(d).find("plate_beams beam 1: index 2 but only 2 beamsors"), std::string::npos);
  d.plate_beams = pisco::PlateBeams{{0, 1}, 0.0};
  EXPECT_NE(message(d).find("plate_beams period = 0 rad; expected a positive period"), std::string::npos) << message(d);
  d.plate_beams = pisco::PlateBeams{{0, 1}, pi, 0.0, -1.0};
  EXPECT_NE(message(d).find("plate_beams omega = -1 sr; expected 0"), std::string::npos) << message(d);
  d.plate_beams = pisco::PlateBeams{{0, 1}};
  pisco::EngineOptions per_sample;
  per_sample.normalization = pisco::Normalization::per_sample;
  EXPECT_NE(message(d, per_sample).find("plate_beams need the integral normalization"), std::string::npos);

  pisco::Engine engine(sky, beams, pisco::FocalPlane({d}), {});
  const pisco::Pointing p = pisco_test::random_pointing(4, 1);
  std::vector<double> tod(4, 5.0);
  try {
    engine.convolve(0, p, tod);
    FAIL() << "no plate angles";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("detector 'turning' has a half-wave plate: expected 4 plate angles"),
              std::string::npos)
        << e.what();
  }
  for (const double v : tod) EXPECT_EQ(v, 5.0);
  const std::vector<double> h{0.0, 1.0, 2.0, 3.0};
  EXPECT_NO_THROW(engine.convolve(0, p, tod, false, h));
}

}  // namespace
