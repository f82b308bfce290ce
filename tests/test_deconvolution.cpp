// The beam-deconvolving map-maker (docs/physics.md, "Map-making with the beams"; docs/validation.md,
// "M"): on a survey whose TOD is exactly A s (no noise), conjugate gradients on the normal equations
// recover the sky s itself wherever the survey constrains it, with mismatched beams, offsets and a
// plate; progress is reported; bad options are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "backend_fixtures.hpp"
#include "pisco/deconvolution.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/spectra.hpp"

#include <alm.h>
#include <alm_healpix_tools.h>
#include <healpix_map.h>
#include <xcomplex.h>
#include "support.hpp"

namespace {

using pisco::deg;

struct Survey {
  pisco::Pointing pointing;
  std::vector<double> hwp;
};

// Every pixel of an NSIDE 16 sky seen many times at random angles (a sky-wide random scan).
Survey random_survey(std::size_t n) {
  Survey s;
  s.pointing = pisco_test::random_pointing(n, 21);
  for (std::size_t i = 0; i < n; ++i) s.hwp.push_back(0.61 * double(i));
  return s;
}

// The sky smoothed by a circular Gaussian as the map-maker reconvolves (HEALPix map2alm, 3 iterations,
// to 3 NSIDE - 1).
pisco::Sky smoothed(const pisco::Sky& sky, double fwhm) {
  const int nside = sky.nside(), lmax = 3 * nside - 1;
  Healpix_Map<double> t(nside, RING, SET_NSIDE), q(nside, RING, SET_NSIDE), u(nside, RING, SET_NSIDE);
  for (int p = 0; p < t.Npix(); ++p) t[p] = sky.I()[p], q[p] = sky.Q()[p], u[p] = sky.U()[p];
  Alm<xcomplex<double>> at(lmax, lmax), ae(lmax, lmax), ab(lmax, lmax);
  map2alm_pol_iter(t, q, u, at, ae, ab, 3);
  const std::vector<double> wt = pisco::gaussian_beam_window(fwhm, lmax, false), wp = pisco::gaussian_beam_window(fwhm, lmax, true);
  for (int m = 0; m <= lmax; ++m)
    for (int l = m; l <= lmax; ++l) at(l, m) *= wt[l], ae(l, m) *= wp[l], ab(l, m) *= wp[l];
  alm2map_pol(at, ae, ab, t, q, u);
  pisco::Sky out(nside);
  for (int p = 0; p < t.Npix(); ++p) out.I()[p] = t[p], out.Q()[p] = q[p], out.U()[p] = u[p];
  return out;
}

// A CMB-like sky band-limited to 2 NSIDE (C_l ~ 1/l^2 for T, E and B). Without a monopole or a
// dipole: their hundredfold dynamic range over the anisotropies would need as many more iterations
// of a solver whose relative residual counts them (as CMB analyses do, remove them first).
pisco::Sky band_limited_sky(int nside) {
  pisco::Spectra cls;
  const int lmax = 2 * nside;
  for (auto* v : {&cls.TT, &cls.EE, &cls.BB, &cls.TE, &cls.EB, &cls.TB}) v->assign(std::size_t(lmax) + 1, 0.0);
  for (int l = 2; l <= lmax; ++l) {
    cls.TT[std::size_t(l)] = 1e-10 / (l * (l + 1.0));
    cls.EE[std::size_t(l)] = 1e-12 / (l * (l + 1.0));
    cls.BB[std::size_t(l)] = 3e-13 / (l * (l + 1.0));
  }
  pisco::Sky sky = pisco::synthesize_sky(cls, nside, 17);
  const Healpix_Base base(nside, RING, SET_NSIDE);
  (void)base;
  return sky;
}

class Deconvolution : public ::testing::TestWithParam<std::string> {};

TEST_P(Deconvolution, RecoversTheSkyFromMismatchedBeams) {
  const std::string why = pisco_test::backend_unavailable(GetParam());
  if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
  const int nside = 16;
  // A pair with mismatched elliptical beams (with cross-polar response) and offsets, and a detector
  // behind a generic plate, with beams of 1.5 to 2 NSIDE 16 pixels (FWHM 5.5 to 7 deg).
  pisco_test::Scene scene{band_limited_sky(nside), {}, {}};
  pisco::BeamOptions bo;
  bo.rho_max = 12 * deg;
  bo.cross_polar = 0.02;
  scene.beams.push_back(pisco::Beamsor::elliptical_gaussian(6.5 * deg, 5.5 * deg, 20 * deg, bo));
  scene.beams.push_back(pisco::Beamsor::elliptical_gaussian(6.0 * deg, 5.8 * deg, -30 * deg, bo));
  scene.beams.push_back(pisco::Beamsor::elliptical_gaussian(7.0 * deg, 6.0 * deg, 60 * deg, bo));
  pisco::FocalPlane fp;
  fp.add_pair("pair", 22.5 * deg, 0, 1, 0.01, 1.0, 0.98);
  pisco::Detector a = fp[0], b = fp[1];
  a.set_offset(0.01, 0.0, 0.0);
  b.set_offset(0.0103, 0.0004, 0.0);
  fp = pisco::FocalPlane();
  fp.add(a);
  fp.add(b);
  pisco::Detector h{"plated", 10 * deg, 0.0, 1.0, 2};
  h.hwp = pisco::HalfWavePlate{pisco_test::generic_plate(), pisco::HwpPlacement::aperture, 0.0};
  fp.add(h);
  const Survey survey = random_survey(30000);
  pisco::EngineOptions o;
  o.backend = GetParam();
  // The plain quadrature: the corrected one sums the samples near the poles on the sky's polar copy,
  // band-limited to 2 NSIDE, whose directions above that band the model cannot see there (a null
  // space the minimum-norm solution leaves out, unlike the sky). The adjoint of the polar copy itself
  // is tested in test_adjoint.cpp.
  o.quadrature = pisco::Quadrature::plain;
  pisco::Engine engine(scene.sky, scene.beams, fp, o);
  const std::size_t chunk = 7000;
  const auto replay = [&](const std::function<void(const pisco::SurveyChunk&)>& visit) {
    for (std::size_t d = 0; d < fp.size(); ++d)
      for (std::size_t first = 0; first < survey.pointing.size(); first += chunk) {
        const std::size_t n = std::min(chunk, survey.pointing.size() - first);
        pisco::SurveyChunk c;
        c.detector = d;
        c.angles = survey.pointing.view().subspan(first, n);
        if (fp[d].hwp) c.hwp_angle = std::span<const double>(survey.hwp).subspan(first, n);
        visit(c);
      }
  };
  pisco::DeconvolutionOptions opt;
  opt.tolerance = 1e-9;
  opt.max_iterations = 60;
  opt.target_fwhm = 7 * deg;
  pisco::DeconvolvingMapmaker maker(engine, opt);
  std::vector<double> tod;
  replay([&](const pisco::SurveyChunk& c) {
    tod.resize(c.size());
    engine.convolve(c.detector, c.angles, tod, false, c.hwp_angle);
    maker.add(c, tod);
  });
  int reports = 0;
  const pisco::DeconvolvedMaps m = maker.solve(replay, [&](const pisco::DeconvolutionProgress& p) {
    ++reports;
    EXPECT_EQ(p.iteration, reports);
  });
  std::cout << GetParam() << ": " << m.iterations << " iterations, residual " << m.residuals.back() << ", "
            << m.seconds_per_iteration << " s an iteration\n";
  EXPECT_EQ(m.iterations, opt.max_iterations);
  EXPECT_LT(m.residuals.back(), 3e-4);
  EXPECT_EQ(reports, m.iterations);
  for (std::size_t k = 1; k < m.residuals.size(); ++k) EXPECT_LT(m.residuals[k], 1.0);
  // The solution reconvolved with the target beam against the sky smoothed the same way: what a
  // deconvolving map-maker promises (the modes the beams suppress most converge last, and the target
  // beam suppresses them again).
  const pisco::Sky want = smoothed(scene.sky, opt.target_fwhm);
  double err[3] = {0, 0, 0}, ref[3] = {0, 0, 0};
  for (std::size_t p = 0; p < scene.sky.npix(); ++p) {
    ASSERT_FALSE(pisco::is_unseen(m.I[p])) << "pixel " << p;
    const double w[3] = {want.I()[p], want.Q()[p], want.U()[p]};
    const double got[3] = {m.smoothed_I[p], m.smoothed_Q[p], m.smoothed_U[p]};
    for (int c = 0; c < 3; ++c) {
      err[c] += (got[c] - w[c]) * (got[c] - w[c]);
      ref[c] += w[c] * w[c];
    }
  }
  for (int c = 0; c < 3; ++c) {
    std::cout << "IQU"[c] << ": relative RMS error of the reconvolved maps " << std::sqrt(err[c] / ref[c]) << "\n";
    // Measured after 60 iterations: 1.7e-4 (I), 2.6e-3 (Q), 2.2e-3 (U); the binned maps of the same
    // survey are off by the beams' whole difference from the target.
    EXPECT_LT(std::sqrt(err[c] / ref[c]), c == 0 ? 1e-3 : 1e-2) << "IQU"[c];
  }
  ASSERT_EQ(m.smoothed_I.size(), scene.sky.npix());
}

// The solver on the simd backend (the reference's adjoint is exact, test_adjoint.cpp; its 0.7 s an
// iteration here would make this test a minute long).
INSTANTIATE_TEST_SUITE_P(Backends, Deconvolution, ::testing::Values("simd"),
                         [](const auto& info) { return info.param; });

TEST(DeconvolutionErrors, BadOptionsAndNoData) {
  pisco_test::Scene scene = pisco_test::backend_scene(16);
  pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane);
  pisco::DeconvolutionOptions o;
  o.max_iterations = 0;
  pisco_test::expect_error([&] { pisco::DeconvolvingMapmaker(engine, o); }, "max_iterations = 0");
  o = {};
  o.tolerance = 2;
  pisco_test::expect_error([&] { pisco::DeconvolvingMapmaker(engine, o); }, "tolerance");
  pisco::DeconvolvingMapmaker maker(engine);
  pisco_test::expect_error([&] { maker.solve([](const auto&) {}); }, "no TOD was added");
}

}  // namespace
