// The deconvolving map-maker never amplifies noise into its maps (docs/physics.md, "Map-making with
// the beams": what the solver leaves out): a Stokes parameter the beams do not respond to (a GRASP-like
// beam whose V response is rounding), polarization that one angle per pixel cannot constrain (a b_lm
// beam), and the edge of a partial coverage are left out, or marked unseen, and said so; a solve that
// does not reach its tolerance says that it did not converge. Noise-free TOD throughout: any value far
// beyond the sky's is amplification, not noise.
#include <gtest/gtest.h>
#include <healpix_base.h>
#include <pointing.h>
#include <vec3.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "backend_fixtures.hpp"
#include "beam_file_writers.hpp"
#include "pisco/deconvolution.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/spectra.hpp"
#include "support.hpp"

namespace {

using pisco::deg;
constexpr double pi = std::numbers::pi;

// A polarized sky band-limited to 2 NSIDE, I of order 1 with a monopole of 1.
pisco::Sky polarized_sky(int nside) {
  pisco::Spectra cls;
  const int lmax = 2 * nside;
  for (auto* v : {&cls.TT, &cls.EE, &cls.BB, &cls.TE, &cls.EB, &cls.TB}) v->assign(std::size_t(lmax) + 1, 0.0);
  for (int l = 2; l <= lmax; ++l) {
    cls.TT[std::size_t(l)] = 1.0 / (l * (l + 1.0));
    cls.EE[std::size_t(l)] = 0.1 / (l * (l + 1.0));
    cls.BB[std::size_t(l)] = 0.03 / (l * (l + 1.0));
  }
  pisco::Sky sky = pisco::synthesize_sky(cls, nside, 23);
  for (double& v : sky.I()) v += 1.0;
  return sky;
}

double max_abs(const std::vector<double>& m) {
  double worst = 0;
  for (double v : m)
    if (!pisco::is_unseen(v)) worst = std::max(worst, std::abs(v));
  return worst;
}

std::size_t seen(const std::vector<double>& m) {
  return std::size_t(std::count_if(m.begin(), m.end(), [](double v) { return !pisco::is_unseen(v); }));
}

struct Solved {
  pisco::DeconvolvedMaps maps;
  double sky_p = 0;  // the sky's largest |Q|, |U|
};

// The TOD of `pointing` for every detector of `fp` (exactly A s), then the solve without regularization.
Solved deconvolve(const pisco::Sky& sky, const std::vector<pisco::Beamsor>& beams, const pisco::FocalPlane& fp,
               const pisco::Pointing& pointing, int iterations, double tolerance = 1e-9) {
  pisco::EngineOptions o;
  o.backend = pisco_test::backend_unavailable("simd").empty() ? "simd" : "cpu";
  o.quadrature = pisco::Quadrature::plain;
  pisco::Engine engine(sky, beams, fp, o);
  const auto replay = [&](const std::function<void(const pisco::SurveyChunk&)>& visit) {
    for (std::size_t d = 0; d < fp.size(); ++d) {
      pisco::SurveyChunk c;
      c.detector = d;
      c.angles = pointing.view();
      visit(c);
    }
  };
  pisco::DeconvolutionOptions opt;
  opt.max_iterations = iterations;
  opt.tolerance = tolerance;
  pisco::DeconvolvingMapmaker maker(engine, opt);
  std::vector<double> tod;
  replay([&](const pisco::SurveyChunk& c) {
    tod.resize(c.size());
    engine.convolve(c.detector, c.angles, tod);
    maker.add(c, tod);
  });
  Solved r;
  r.maps = maker.solve(replay);
  r.sky_p = std::max(max_abs({sky.Q().begin(), sky.Q().end()}), max_abs({sky.U().begin(), sky.U().end()}));
  for (const auto& line : r.maps.left_out) std::cout << "left out " << line << "\n";
  std::cout << r.maps.iterations << " iterations, residual " << r.maps.residuals.back() << "; max |I| "
            << max_abs(r.maps.I) << ", |Q| " << max_abs(r.maps.Q) << ", |U| " << max_abs(r.maps.U) << ", |V| "
            << max_abs(r.maps.V) << " (sky |P| up to " << r.sky_p << ")\n";
  return r;
}

pisco::FocalPlane pair() {
  pisco::FocalPlane fp;
  fp.add_pair("p", 0.0, 0, 0);
  return fp;
}

// A GRASP-like beam: an elliptical Gaussian whose circular response V is rounding, 1e-14 of I (as
// |co|^2 - |cx|^2 products leave it), not zero. Unregularized, V's diagonal is 1e-28 of I's: the
// solver once divided by it and returned V of 1e11 and more.
TEST(DeconvolutionLimits, AStokesParameterTheBeamsDoNotSeeIsLeftOut) {
  const int nside = 16;
  const pisco::Sky sky = polarized_sky(nside);
  const double sx = 6.5 * deg / std::sqrt(8 * std::log(2.0)), sy = 5.5 * deg / std::sqrt(8 * std::log(2.0));
  const pisco::Beamsor beam = pisco::Beamsor::from_field(
      [&](double rho, double sigma) {
        const double x = rho * std::cos(sigma - 0.3), y = rho * std::sin(sigma - 0.3);
        const double t = std::exp(-0.5 * (x * x / (sx * sx) + y * y / (sy * sy)));
        return pisco::Beamsor::stokes_mueller(t, t, 0.0, 1e-14 * t * std::cos(3 * sigma));
      },
      12 * deg, 0.5 * deg, "GRASP-like elliptical Gaussian, V at rounding");
  const Solved r = deconvolve(sky, {beam}, pair(), pisco_test::random_pointing(20000, 3), 30);
  ASSERT_FALSE(r.maps.left_out.empty());
  EXPECT_TRUE(pisco_test::contains(r.maps.left_out[0], "V everywhere")) << r.maps.left_out[0];
  EXPECT_EQ(max_abs(r.maps.V), 0.0);
  EXPECT_LT(max_abs(r.maps.Q), 3 * r.sky_p);
  EXPECT_LT(max_abs(r.maps.U), 3 * r.sky_p);
  EXPECT_LT(r.maps.residuals.back(), 1e-2);
  EXPECT_FALSE(r.maps.polarization_unconstrained);
}

// One polarization angle per pixel (every NSIDE 16 pixel centre at psi = 0, a pair at 0 and 90 deg)
// through a b_lm beam: Q and U are degenerate at every pixel, and the solver once filled U with values
// 10^4 times the sky's. Now they are left out, said so, and unseen; I is solved.
TEST(DeconvolutionLimits, OneAngleLeavesPolarizationOut) {
  const int nside = 16;
  const pisco::Sky sky = polarized_sky(nside);
  const pisco::HarmonicBeam blm = pisco_test::gaussian_blm(6 * deg, 3 * nside);
  pisco::FileBeamOptions fo;
  fo.rho_max = 12 * deg;
  const pisco::Beamsor beam = pisco::Beamsor::from_harmonic(blm, fo);
  pisco::Pointing scan;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  for (int p = 0; p < base.Npix(); ++p) {
    const ::pointing ang = base.pix2ang(p);
    scan.push_back(ang.theta, ang.phi, 0.0);
  }
  const Solved r = deconvolve(sky, {beam}, pair(), scan, 30);
  EXPECT_TRUE(r.maps.polarization_unconstrained);
  EXPECT_EQ(r.maps.polarization_pixels, 0u);
  EXPECT_EQ(seen(r.maps.Q), 0u);
  EXPECT_EQ(seen(r.maps.U), 0u);
  EXPECT_EQ(seen(r.maps.I), sky.npix());
  EXPECT_LT(max_abs(r.maps.I), 3 * max_abs({sky.I().begin(), sky.I().end()}));
  ASSERT_FALSE(r.maps.left_out.empty());
  EXPECT_TRUE(pisco_test::contains(r.maps.left_out.back(), "Q and U everywhere")) << r.maps.left_out.back();
}

// A scan of the pixel centres within 25 deg of a point, at three angles: beyond the scan's edge the
// beams reach pixels from one side only. The maps' polarization stays within a few times the sky's
// (it once reached 8 times the interior's error at the edge), and what is cut is said.
TEST(DeconvolutionLimits, TheEdgeOfAPartialCoverageIsNotAmplified) {
  const int nside = 32;
  const pisco::Sky sky = polarized_sky(nside);
  pisco::BeamOptions bo;
  bo.rho_max = 12 * deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::elliptical_gaussian(6.2 * deg, 5.8 * deg, 20 * deg, bo)};
  pisco::Pointing scan;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const vec3 centre = ::pointing(60 * deg, 30 * deg).to_vec3();
  for (int p = 0; p < base.Npix(); ++p) {
    const ::pointing ang = base.pix2ang(p);
    if (dotprod(ang.to_vec3(), centre) < std::cos(25 * deg)) continue;
    for (double psi : {0.0, pi / 4, pi / 2}) scan.push_back(ang.theta, ang.phi, psi);
  }
  const Solved r = deconvolve(sky, beams, pair(), scan, 40);
  EXPECT_FALSE(r.maps.polarization_unconstrained);
  EXPECT_GT(seen(r.maps.Q), 500u);
  // Measured: |Q| and |U| up to 0.93 and 0.84 of the sky's largest (2.2 and 2.0 before the edge was cut).
  EXPECT_LT(max_abs(r.maps.Q), 1.5 * r.sky_p);
  EXPECT_LT(max_abs(r.maps.U), 1.5 * r.sky_p);
  // |I| up to 0.76 of the sky's largest (1.7 before the edge was cut).
  EXPECT_LT(max_abs(r.maps.I), 1.2 * max_abs({sky.I().begin(), sky.I().end()}));
  bool said = false;
  for (const auto& line : r.maps.left_out) said = said || pisco_test::contains(line, "Q and U from the maps");
  EXPECT_TRUE(said);
}

// Not reaching the tolerance is reported: converged false, and the residuals say where it stopped.
TEST(DeconvolutionLimits, ASolveThatStopsShortIsNotConverged) {
  const int nside = 8;
  const pisco::Sky sky = polarized_sky(nside);
  pisco::BeamOptions bo;
  bo.rho_max = 20 * deg;
  const Solved r = deconvolve(sky, {pisco::Beamsor::gaussian(10 * deg, bo)}, pair(), pisco_test::random_pointing(5000, 4), 2);
  EXPECT_FALSE(r.maps.converged);
  EXPECT_EQ(r.maps.iterations, 2);
  EXPECT_GT(r.maps.residuals.back(), 1e-9);
}

}  // namespace
