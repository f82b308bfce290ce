// VALIDATION D (paper 6.2) at test scale: a Gaussian r = 0 CMB sky at NSIDE 256 observed at every
// NSIDE 128 pixel centre at psi = 0, 45, 90 deg by one detector with a 1.5 deg Gaussian beam; binned
// maps; spectra divided by the Gaussian beam window, compared with the spectra of the input maps.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <numbers>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <alm_powspec_tools.h>
#include <healpix_map.h>
#include <xcomplex.h>

#include "pisco/pisco.hpp"

namespace {

constexpr double deg = std::numbers::pi / 180;

// The harmonic image of the same observation: the input maps smoothed by HEALPix C++ and evaluated
// at the output pixel centres. Its spectra carry the estimator's own floor (E -> B of map2alm on an
// NSIDE 128 map near l = 2 NSIDE, amplified by the beam deconvolution), which PISCO's must match.
pisco::Spectra harmonic_reference(const pisco::Sky& sky, double fwhm, int nside_out, int lmax_in, int lmax_out) {
  Healpix_Map<double> t(sky.nside(), RING, SET_NSIDE), q(sky.nside(), RING, SET_NSIDE), u(sky.nside(), RING, SET_NSIDE);
  for (int p = 0; p < t.Npix(); ++p) {
    t[p] = sky.I()[p];
    q[p] = sky.Q()[p];
    u[p] = sky.U()[p];
  }
  Alm<xcomplex<double>> at(lmax_in, lmax_in), ag(lmax_in, lmax_in), ac(lmax_in, lmax_in);
  arr<double> weight(2 * sky.nside(), 1.0);
  map2alm_pol_iter(t, q, u, at, ag, ac, 3, weight);
  smoothWithGauss(at, ag, ac, fwhm);
  Healpix_Map<double> to(nside_out, RING, SET_NSIDE), qo(nside_out, RING, SET_NSIDE), uo(nside_out, RING, SET_NSIDE);
  alm2map_pol(at, ag, ac, to, qo, uo);
  std::vector<double> I(to.Npix()), Q(to.Npix()), U(to.Npix());
  for (int p = 0; p < to.Npix(); ++p) {
    I[p] = to[p];
    Q[p] = qo[p];
    U[p] = uo[p];
  }
  return pisco::anafast(I, Q, U, nside_out, lmax_out, 3);
}

TEST(IdealCmb, ResidualSpectraWithinThePapersBars) {
  const int nside_sky = 256, nside_out = 128, lmax_cmp = 250;
  const double fwhm = 1.5 * deg;
  const auto t0 = std::chrono::steady_clock::now();
  const pisco::Spectra cls = pisco::read_cl_table(pisco::default_cl_file(), 2 * nside_sky, true);
  const pisco::Sky sky = pisco::synthesize_sky(cls, nside_sky, 2019);

  pisco::BeamOptions o;
  o.rho_max = 5 * deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(fwhm, o)};
  pisco::FocalPlane fp;
  fp.add({"det", 0.0, 0.0, 1.0, 0});
  pisco::Engine engine(sky, beams, fp);
  const pisco::Pointing scan = pisco::pixel_centre_scan(nside_out, {0.0, 45 * deg, 90 * deg});
  pisco::BinnedMapmaker mapper(nside_out);
  // Stream the TOD in chunks into the map-maker, as a long run would.
  const std::size_t chunk = 20000;
  std::vector<double> tod(chunk);
  const auto t1 = std::chrono::steady_clock::now();
  for (std::size_t off = 0; off < scan.size(); off += chunk) {
    const std::size_t n = std::min(chunk, scan.size() - off);
    const pisco::PointingView v = scan.view().subspan(off, n);
    engine.convolve(0, v, std::span<double>(tod).first(n));
    mapper.add(fp[0], v, std::span<const double>(tod).first(n));
  }
  const double conv_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  const pisco::BinnedMaps maps = mapper.solve();
  for (std::size_t p = 0; p < maps.I.size(); ++p) ASSERT_NE(maps.I[p], pisco::unseen) << "pixel " << p;

  const int lmax_out = 3 * nside_out - 1;
  const pisco::Spectra out = pisco::anafast(maps.I, maps.Q, maps.U, nside_out, lmax_out, 3);
  const pisco::Spectra in = pisco::anafast(sky.I(), sky.Q(), sky.U(), nside_sky, lmax_out, 3);
  const auto bt = pisco::gaussian_beam_window(fwhm, lmax_out, false);
  const auto bp = pisco::gaussian_beam_window(fwhm, lmax_out, true);
  const pisco::Spectra dec = pisco::deconvolve_windows(out, bt, bp, {}, {});
  const pisco::Spectra ref = pisco::deconvolve_windows(
      harmonic_reference(sky, fwhm, nside_out, 2 * nside_sky, lmax_out), bt, bt, {}, {});
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  double max_tt = 0, max_ee = 0, max_bb = 0, max_te = 0, max_eb = 0, max_bb_vs_ref = 0, max_bb_ref = 0,
         max_ee_vs_ref = 0, max_ee_ref = 0;
  auto dl = [](int l, double cl) { return l * (l + 1.0) * cl / (2 * std::numbers::pi); };
  std::printf("D residual D_l (uK^2), NSIDE %d sky, NSIDE %d pointing, 2 <= l <= %d:\n", nside_sky, nside_out, lmax_cmp);
  std::printf("%5s %12s %12s %12s %12s %12s %12s\n", "l", "TT_in", "dTT", "EE_in", "dEE", "BB_out", "dBB");
  for (int l = 2; l <= lmax_cmp; ++l) {
    const double dtt = dl(l, dec.TT[l] - in.TT[l]), dee = dl(l, dec.EE[l] - in.EE[l]);
    const double dbb = dl(l, dec.BB[l] - in.BB[l]);
    max_tt = std::max(max_tt, std::abs(dtt));
    max_ee = std::max(max_ee, std::abs(dee));
    max_bb = std::max(max_bb, std::abs(dbb));
    max_te = std::max(max_te, std::abs(dl(l, dec.TE[l] - in.TE[l])));
    max_eb = std::max(max_eb, std::abs(dl(l, dec.EB[l])));
    max_bb_vs_ref = std::max(max_bb_vs_ref, std::abs(dl(l, dec.BB[l] - ref.BB[l])));
    max_bb_ref = std::max(max_bb_ref, std::abs(dl(l, ref.BB[l] - in.BB[l])));
    max_ee_vs_ref = std::max(max_ee_vs_ref, std::abs(dl(l, dec.EE[l] - ref.EE[l])));
    max_ee_ref = std::max(max_ee_ref, std::abs(dl(l, ref.EE[l] - in.EE[l])));
    if (l % 25 == 0 || l == 2)
      std::printf("%5d %12.4g %12.4g %12.4g %12.4g %12.4g %12.4g\n", l, dl(l, in.TT[l]), dtt, dl(l, in.EE[l]), dee,
                  dl(l, dec.BB[l]), dbb);
  }
  std::printf("D max |residual D_l|: TT %.3g (paper's bar 8), EE %.3g (bar 4e-3), BB %.3g (bar 2e-6) uK^2; "
              "TE %.3g, EB %.3g uK^2\n", max_tt, max_ee, max_bb, max_te, max_eb);
  std::printf("D wall time %.1f s (convolution %.1f s, %zu samples, %.0f pixels per disc); paper: < 25 s on a GTX 1080 "
              "at NSIDE 512 / 128\n", wall, conv_s, scan.size(), engine.mean_disc_pixels());
  std::printf("D BB against the harmonic image of the same observation: max |BB_pisco - BB_harmonic| %.3g uK^2 "
              "(the harmonic image itself differs from the input by up to %.3g: the estimator's floor)\n",
              max_bb_vs_ref, max_bb_ref);
  std::printf("D EE against the harmonic image: max |EE_pisco - EE_harmonic| %.3g uK^2 (harmonic image vs input: %.3g)\n",
              max_ee_vs_ref, max_ee_ref);
  EXPECT_LT(max_tt, 8.0);
  // EE and BB: the paper's bars (4e-3, 2e-6 uK^2) are of the size of the anafast floor of an NSIDE 128
  // map at l = 250 (the harmonic image of the observation already differs from the input by that
  // much). PISCO must stay within the bars of the harmonic image, and within floor + bar of the input.
  EXPECT_LT(max_ee_vs_ref, 4e-3);
  EXPECT_LT(max_ee, max_ee_ref + 4e-3);
  // The paper's 2e-6 bar for BB lies below the anafast floor of an NSIDE 128 map at l = 250; PISCO's
  // BB must stay within 2e-6 of that floor (the harmonic image), and within the floor's own size of
  // the input.
  EXPECT_LT(max_bb_vs_ref, 2e-6);
  EXPECT_LT(max_bb, max_bb_ref + 2e-6);
}

}  // namespace
