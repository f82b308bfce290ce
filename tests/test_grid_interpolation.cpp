// Beams on a grid at their default step (docs/physics.md, "Interpolation on the grid"; docs/validation.md,
// "K.4"): the interpolation is exact for quadratics and of third order, and an elliptical beam's TOD at
// the default step is within 1e-4 of the converged beam's (the same beam on a grid five times finer, on
// the float64 reference) at every sample, on every backend present: samples across both poles and at
// random over the sphere, on a polarized sky and on the same sky with a monopole and a dipole.
#include <gtest/gtest.h>

#include <healpix_base.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "backend_fixtures.hpp"
#include "support.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/units.hpp"

namespace {

using pisco::deg;
constexpr double pi = std::numbers::pi;

// A field whose B_TT is f(x, y) in the grid's orthographic coordinates (x, y) = sin(rho) (cos, sin)(sigma).
pisco::Beamsor::Field scalar_field(double (*f)(double, double)) {
  return [f](double rho, double sigma) {
    pisco::Mueller m{};
    m[0][0] = f(std::sin(rho) * std::cos(sigma), std::sin(rho) * std::sin(sigma));
    return m;
  };
}

double quadratic(double x, double y) { return 1.0 + 3 * x - 2 * y + 40 * x * x - 25 * x * y + 60 * y * y; }
double gaussian(double x, double y) { return std::exp(-(x * x / (2 * 0.01 * 0.01) + y * y / (2 * 0.007 * 0.007))); }

// The largest |at(x, y) - f(x, y)| over points at random within x^2 + y^2 <= within^2.
double worst_error(const pisco::Beamsor& b, double (*f)(double, double), double within) {
  std::mt19937_64 g(5);
  std::uniform_real_distribution<double> u(-within, within);
  double worst = 0.0;
  for (int k = 0; k < 20000; ++k) {
    const double x = u(g), y = u(g);
    if (x * x + y * y > within * within) continue;
    worst = std::max(worst, std::abs(b.at(x, y)[0][0] - f(x, y)));
  }
  return worst;
}

TEST(GridInterpolation, QuadraticsAreExactAndTheErrorIsOfThirdOrder) {
  // Within cells whose edges' second differences are all interior (a step from the border).
  const double rho_max = 3 * deg, a = std::sin(rho_max);
  const pisco::Beamsor q = pisco::Beamsor::from_field(scalar_field(quadratic), rho_max, a / 10, "quadratic", 0, false);
  // (Bilinear interpolation alone misses it by up to h^2 / 8 of its second derivative, 4e-4 here.)
  EXPECT_LE(worst_error(q, quadratic, 0.7 * a), 1e-12) << "a quadratic is interpolated exactly";
  // A Gaussian: halving the step divides the worst error by about 8 (bilinear: 4).
  double previous = 0.0;
  for (const double step : {0.002, 0.001, 0.0005}) {
    const pisco::Beamsor b = pisco::Beamsor::from_field(scalar_field(gaussian), rho_max, step, "gaussian", 0.01, false);
    const double e = worst_error(b, gaussian, 0.03);
    std::printf("step %.4f: worst error %.2e of the peak\n", b.grid_step(), e);
    if (previous > 0) EXPECT_GT(previous / e, 6.0) << "step " << step;
    previous = e;
  }
  // Continuity: on a cell's edge both cells give the same value.
  const pisco::Beamsor b = pisco::Beamsor::from_field(scalar_field(gaussian), rho_max, 0.002, "gaussian", 0.01, false);
  const double s = b.grid_step(), x0 = -b.grid_half_width();
  for (int i = 20; i < 40; ++i) {
    const double x = x0 + i * s, y = 0.0123;
    EXPECT_NEAR(b.at(std::nextafter(x, -1.0), y)[0][0], b.at(std::nextafter(x, 1.0), y)[0][0], 1e-13) << i;
  }
}

// Each colatitude (deg) at 8 longitudes, then random samples over the sphere.
pisco::Pointing sphere_pointing(std::size_t random_samples) {
  std::mt19937_64 g(17);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing p;
  for (const double c : {0.0, 0.3, 1.0, 3.0, 177.0, 179.0, 179.7, 180.0})
    for (int k = 0; k < 8; ++k) p.push_back(c * deg, 2 * pi * k / 8 + 0.1, 2 * pi * u(g) - pi);
  for (std::size_t i = 0; i < random_samples; ++i)
    p.push_back(std::acos(2 * u(g) - 1), 2 * pi * u(g), 2 * pi * u(g) - pi);
  return p;
}

class GridBeams : public ::testing::TestWithParam<std::string> {};

TEST_P(GridBeams, TheDefaultStepIsWithin1e4OfTheConvergedBeam) {
  const std::string backend = GetParam();
  const std::string why = pisco_test::backend_unavailable(backend);
  if (!why.empty()) GTEST_SKIP() << backend << ": " << why;
  const int nside = 256;  // 13.7 arcmin pixels: 5.3 and 7.9 pixels per FWHM along the beam's axes
  pisco::Sky sky = pisco_test::cmb_like_sky(nside, 31);
  pisco::Sky with_monopole = sky;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  for (std::size_t i = 0; i < sky.npix(); ++i) {
    const vec3 v = base.pix2vec(int(i));
    with_monopole.I()[i] += 2.725 + 3.36e-3 * (0.3 * v.x - 0.5 * v.y + 0.81 * v.z);
  }
  // An elliptical Gaussian (the 2D grid, w_I and w_Q) and one with a quadrupole cross-polar field and
  // Mueller leakage (w_U too); two detectors at different angles each.
  pisco::BeamOptions e;
  e.rho_max = 4.5 * deg;
  pisco::BeamOptions x = e;
  x.cross_polar = 0.05;
  x.cross_polar_pattern = pisco::CrossPolarPattern::quadrupole;
  x.mueller[1][0] = 0.01;
  x.mueller[2][0] = -0.004;
  auto beams = [&](double step_fraction) {
    pisco::BeamOptions a = e, b = x;
    a.grid_step = 1.2 * deg * step_fraction;
    b.grid_step = 1.3 * deg * step_fraction;
    return std::vector<pisco::Beamsor>{pisco::Beamsor::elliptical_gaussian(1.8 * deg, 1.2 * deg, 0.3, a),
                                       pisco::Beamsor::elliptical_gaussian(1.6 * deg, 1.3 * deg, -0.7, b)};
  };
  const std::vector<pisco::Beamsor> defaults = beams(0.0), converged = beams(1.0 / 80);
  pisco::FocalPlane fp;
  fp.add({"a0", 0.0, 0.0, 1.0, 0});
  fp.add({"a45", 45 * deg, 0.0, 1.0, 0});
  fp.add({"x20", 20 * deg, 0.01, 1.0, 1});
  fp.add({"x110", 110 * deg, 0.0, 1.0, 1});
  const pisco::Pointing p = sphere_pointing(backend == "cpu" ? 700 : 1500);
  // The polarized sky with the engine's default normalization (the integral), held to 1e-4 of the TOD's
  // RMS; the sky with a 2.725 K monopole and a dipole, where a sample's gain error meets the monopole:
  // held to 5e-5 of the monopole with the integral normalization, and to 1e-4 of the TOD's RMS with
  // per-sample normalization, which divides the gain out (docs/physics.md, "Interpolation on the grid").
  struct Case {
    const pisco::Sky* sky;
    pisco::Normalization normalization;
    const char* name;
  };
  for (const Case c : {Case{&sky, pisco::Normalization::integral, "polarized sky"},
                       Case{&with_monopole, pisco::Normalization::integral, "monopole + dipole + polarized sky"},
                       Case{&with_monopole, pisco::Normalization::per_sample,
                            "monopole + dipole + polarized sky, per-sample normalization"}}) {
    pisco::EngineOptions ref_options;
    ref_options.backend = "cpu";
    ref_options.normalization = c.normalization;
    pisco::EngineOptions options = ref_options;
    options.backend = backend;
    pisco::Engine reference(*c.sky, converged, fp, ref_options);
    pisco::Engine engine(*c.sky, defaults, fp, options);
    const bool gain = c.sky == &with_monopole && c.normalization == pisco::Normalization::integral;
    for (std::size_t d = 0; d < fp.size(); ++d) {
      std::vector<double> ref(p.size()), got(p.size());
      reference.convolve(d, p, ref);
      engine.convolve(d, p, got);
      const double scale = gain ? 2.725 : pisco_test::rms_about_mean(ref);
      double worst = 0.0, sum = 0.0;
      for (std::size_t i = 0; i < p.size(); ++i) {
        const double err = std::abs(got[i] - ref[i]) / scale;
        worst = std::max(worst, err);
        sum += err * err;
      }
      std::printf("%s, %s, %s: worst %.2e, RMS %.2e of the %s\n", backend.c_str(), fp[d].name.c_str(), c.name, worst,
                  std::sqrt(sum / double(p.size())), gain ? "monopole" : "TOD's RMS");
      EXPECT_LE(worst, gain ? 5e-5 : 1e-4) << fp[d].name << ", " << c.name;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, GridBeams, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

}  // namespace
