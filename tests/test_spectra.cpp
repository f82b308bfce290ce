// C_l tables, sky synthesis, anafast and the beam and pixel windows (docs/physics.md,
// "Map-making and spectra").
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <random>
#include <string>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <healpix_map.h>
#include <xcomplex.h>

#include "support.hpp"
#include "pisco/error.hpp"
#include "pisco/spectra.hpp"
#include "pisco/units.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;

using pisco_test::expect_error;

std::filesystem::path write_file(const std::string& name, const std::string& text) {
  const std::filesystem::path file = std::filesystem::path(::testing::TempDir()) / name;
  std::ofstream(file) << text;
  return file;
}

// Amplitude A of a measured spectrum against the expected one (measured = A expected + cosmic
// variance), the inverse-variance weighted estimate over [lmin, lmax], and its standard deviation
// for a full-sky Gaussian field. var_l is the variance of one measured multipole times (2l + 1).
struct Amplitude {
  double value, sigma;
};

template <class Var>
Amplitude amplitude(const std::vector<double>& measured, const std::vector<double>& expected,
                    int lmin, int lmax, Var var_l) {
  double num = 0, den = 0;
  for (int l = lmin; l <= lmax; ++l) {
    const double w = (2 * l + 1) * expected[l] / var_l(l);
    num += w * measured[l];
    den += w * expected[l];
  }
  return {num / den, 1.0 / std::sqrt(den)};
}

TEST(Spectra, ReadsTheCambTable) {
  const std::filesystem::path file = pisco::default_cl_file();
  std::cout << "C_l table: " << file << "\n";
  const pisco::Spectra cl = pisco::read_cl_table(file, 2500, false);
  ASSERT_EQ(cl.lmax(), 2500);
  // Rows of totcls.dat: "2 0.17261E+04 0.67367E-01 0.27107E-01 0.36347E+01" and
  // "3 0.15364E+04 0.10453E+00 0.31381E-01 0.36945E+01".
  const double tt2 = 2 * pi * 1726.1 / 6, ee2 = 2 * pi * 0.067367 / 6, bb2 = 2 * pi * 0.027107 / 6;
  const double te3 = 2 * pi * 3.6945 / 12;
  std::cout << "C_2^TT " << cl.TT[2] << " (expected " << tt2 << "), C_2^EE " << cl.EE[2]
            << ", C_2^BB " << cl.BB[2] << ", C_3^TE " << cl.TE[3] << " uK^2\n";
  EXPECT_NEAR(cl.TT[2], tt2, 1e-12 * tt2);
  EXPECT_NEAR(cl.EE[2], ee2, 1e-12 * ee2);
  EXPECT_NEAR(cl.BB[2], bb2, 1e-12 * bb2);
  EXPECT_NEAR(cl.TE[3], te3, 1e-12 * te3);
  for (int l = 0; l < 2; ++l) EXPECT_EQ(cl.TT[l], 0.0);
  // The table stops at l = 2000; beyond it C_l is zero.
  EXPECT_GT(cl.TT[2000], 0.0);
  EXPECT_EQ(cl.TT[2001], 0.0);
  for (int l = 0; l <= 2500; ++l) {
    ASSERT_EQ(cl.EB[l], 0.0);
    ASSERT_EQ(cl.TB[l], 0.0);
  }

  const pisco::Spectra r0 = pisco::read_cl_table(file, 300, true);
  ASSERT_EQ(r0.lmax(), 300);
  for (int l = 0; l <= 300; ++l) ASSERT_EQ(r0.BB[l], 0.0) << l;
  EXPECT_EQ(r0.TT[2], cl.TT[2]);
}

TEST(Spectra, MalformedTablesNameFileAndLine) {
  const auto bad_value = write_file("pisco_bad_value.dat", "0 0 0 0 0\n1 0 0 0 0\n2 1.0 abc 0 0\n");
  expect_error([&] { pisco::read_cl_table(bad_value, 10, false); }, "pisco_bad_value.dat:3");
  const auto short_row = write_file("pisco_short_row.dat", "# l TT EE BB TE\n\n2 1.0 0.1 0.01\n");
  expect_error([&] { pisco::read_cl_table(short_row, 10, false); }, "pisco_short_row.dat:3");
  const auto bad_l = write_file("pisco_bad_l.dat", "2.5 1 1 1 1\n");
  expect_error([&] { pisco::read_cl_table(bad_l, 10, false); }, "pisco_bad_l.dat:1");
  const auto nan_value = write_file("pisco_nan.dat", "2 1 1 1 1\n3 nan 1 1 1\n");
  expect_error([&] { pisco::read_cl_table(nan_value, 10, false); }, "pisco_nan.dat:2");
  const auto empty = write_file("pisco_empty.dat", "# nothing\n");
  expect_error([&] { pisco::read_cl_table(empty, 10, false); }, "pisco_empty.dat");
  expect_error([] { pisco::read_cl_table("/nonexistent/pisco_cls.dat", 10, false); },
               "/nonexistent/pisco_cls.dat");
  expect_error([] { pisco::read_cl_table(pisco::default_cl_file(), -1, false); }, "lmax");
  try {
    pisco::read_cl_table(bad_value, 10, false);
  } catch (const pisco::Error& e) {
    std::cout << "malformed table message: " << e.what() << "\n";
  }
}

TEST(Spectra, SynthesizedSkyHasTheInputSpectra) {
  const int nside = 64, lmin = 2, lmax = 128;
  const pisco::Spectra in = pisco::read_cl_table(pisco::default_cl_file(), 3 * nside - 1, true);
  const pisco::Sky sky = pisco::synthesize_sky(in, nside, 20240601);
  EXPECT_EQ(sky.nside(), nside);
  EXPECT_EQ(sky.units(), "uK_CMB");
  for (double v : sky.V()) ASSERT_EQ(v, 0.0);

  const pisco::Spectra out = pisco::anafast(sky.I(), sky.Q(), sky.U(), nside, 3 * nside - 1);
  // Cosmic variance of one multipole: 2 C_l^2 / (2l+1) for auto spectra,
  // (C_l^TT C_l^EE + (C_l^TE)^2) / (2l+1) for TE.
  const Amplitude tt =
      amplitude(out.TT, in.TT, lmin, lmax, [&](int l) { return 2 * in.TT[l] * in.TT[l]; });
  const Amplitude ee =
      amplitude(out.EE, in.EE, lmin, lmax, [&](int l) { return 2 * in.EE[l] * in.EE[l]; });
  const Amplitude te = amplitude(out.TE, in.TE, lmin, lmax, [&](int l) {
    return in.TT[l] * in.EE[l] + in.TE[l] * in.TE[l];
  });
  double bb = 0, ee_sum = 0;
  for (int l = lmin; l <= lmax; ++l) bb += out.BB[l], ee_sum += out.EE[l];
  std::cout << "NSIDE 64 synthesis, l = 2..128, measured/input amplitude: TT " << tt.value
            << " +- " << tt.sigma << ", EE " << ee.value << " +- " << ee.sigma << ", TE "
            << te.value << " +- " << te.sigma << "; sum BB / sum EE (input BB = 0) "
            << bb / ee_sum << "\n";
  // Within 4 sigma (sigma is about 1%); a flipped TE sign convention would give -1.
  EXPECT_NEAR(tt.value, 1.0, 4 * tt.sigma);
  EXPECT_NEAR(ee.value, 1.0, 4 * ee.sigma);
  EXPECT_NEAR(te.value, 1.0, 4 * te.sigma);
  EXPECT_LT(bb / ee_sum, 1e-6);
}

TEST(Spectra, SynthesisIsDeterminedByTheSeed) {
  const pisco::Spectra in = pisco::read_cl_table(pisco::default_cl_file(), 47, false);
  const pisco::Sky a = pisco::synthesize_sky(in, 16, 7), b = pisco::synthesize_sky(in, 16, 7);
  const pisco::Sky c = pisco::synthesize_sky(in, 16, 8);
  EXPECT_TRUE(std::equal(a.I().begin(), a.I().end(), b.I().begin()));
  EXPECT_TRUE(std::equal(a.U().begin(), a.U().end(), b.U().begin()));
  std::size_t differ = 0;
  for (std::size_t p = 0; p < a.npix(); ++p) differ += a.Q()[p] != c.Q()[p];
  std::cout << "seed 7 vs 8: " << differ << " of " << a.npix() << " Q pixels differ; I[0] = "
            << a.I()[0] << " vs " << c.I()[0] << " uK\n";
  EXPECT_EQ(differ, a.npix());
}

TEST(Spectra, PureEModeHasNoB) {
  // A band-limited E-only field made directly with HEALPix, then analysed.
  const int nside = 64, lmax = 128;
  Alm<xcomplex<double>> almT(lmax, lmax), almE(lmax, lmax), almB(lmax, lmax);
  almT.SetToZero();
  almB.SetToZero();
  almE.SetToZero();
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n;
  for (int l = 2; l <= lmax; ++l)
    for (int m = 0; m <= l; ++m)
      almE(l, m) = xcomplex<double>(n(rng), m == 0 ? 0.0 : n(rng)) / double(l);
  Healpix_Map<double> T(nside, RING, SET_NSIDE), Q(nside, RING, SET_NSIDE), U(nside, RING, SET_NSIDE);
  alm2map_pol(almT, almE, almB, T, Q, U);
  const std::vector<double> I(T.Npix(), 0.0);
  const std::vector<double> q(Q.Map().begin(), Q.Map().end()), u(U.Map().begin(), U.Map().end());

  const pisco::Spectra s = pisco::anafast(I, q, u, nside, lmax);
  double worst = 0, worst_te = 0;
  for (int l = 2; l <= lmax; ++l) {
    worst = std::max(worst, s.BB[l] / s.EE[l]);
    worst_te = std::max({worst_te, std::abs(s.EB[l]) / s.EE[l], std::abs(s.TE[l]) / s.EE[l]});
  }
  std::cout << "pure E, NSIDE 64, l <= 128: max BB/EE " << worst << ", max |EB|,|TE| / EE "
            << worst_te << "\n";
  EXPECT_LT(worst, 1e-6);
  EXPECT_LT(worst_te, 1e-3);
}

TEST(Spectra, UnseenPixelsCountAsZero) {
  const int nside = 8;
  const pisco::Spectra in = pisco::read_cl_table(pisco::default_cl_file(), 23, false);
  pisco::Sky sky = pisco::synthesize_sky(in, nside, 3);
  std::vector<double> I(sky.I().begin(), sky.I().end()), zeroed = I;
  for (std::size_t p = 0; p < I.size(); p += 5) I[p] = -1.6375e30, zeroed[p] = 0.0;
  const pisco::Spectra a = pisco::anafast(I, sky.Q(), sky.U(), nside, 23);
  const pisco::Spectra b = pisco::anafast(zeroed, sky.Q(), sky.U(), nside, 23);
  EXPECT_EQ(a.TT, b.TT);
  EXPECT_EQ(a.TE, b.TE);
  std::vector<double> nan_map = zeroed;
  nan_map[17] = std::nan("");
  expect_error([&] { pisco::anafast(nan_map, sky.Q(), sky.U(), nside, 23); }, "pixel 17");
  expect_error([&] { pisco::anafast(std::span<const double>(I).first(100), sky.Q(), sky.U(), nside, 23); },
               "I map has 100 pixels");
  expect_error([&] { pisco::anafast(I, sky.Q(), sky.U(), 6, 23); }, "anafast: NSIDE = 6");
}

TEST(Spectra, GaussianBeamWindow) {
  const double fwhm = 1.5 * deg;
  const double sigma = fwhm / std::sqrt(8 * std::log(2.0));
  const std::vector<double> bt = pisco::gaussian_beam_window(fwhm, 250, false);
  const std::vector<double> bp = pisco::gaussian_beam_window(fwhm, 250, true);
  ASSERT_EQ(bt.size(), 251u);
  ASSERT_EQ(bp.size(), 251u);
  for (int l : {0, 1, 2, 10, 100, 250}) {
    const double t = std::exp(-0.5 * l * (l + 1) * sigma * sigma);
    const double p = std::exp(-0.5 * (l * (l + 1) - 4) * sigma * sigma);
    EXPECT_NEAR(bt[l], t, 1e-15);
    EXPECT_NEAR(bp[l], p, 1e-15);
  }
  // healpy.gauss_beam(radians(1.5), lmax=4, pol=True): T and E columns at l = 0 and 4.
  std::cout << "beam 1.5 deg: B_0^T " << bt[0] << ", B_0^P " << bp[0] << ", B_4^T " << bt[4]
            << ", B_4^P " << bp[4] << ", B_250^T " << bt[250] << "\n";
  EXPECT_NEAR(bp[0], 1.00024723, 1e-8);
  EXPECT_NEAR(bt[4], 0.99876475, 1e-8);
  EXPECT_NEAR(bp[4], 0.99901168, 1e-8);
  // A zero-width beam is no beam.
  EXPECT_EQ(pisco::gaussian_beam_window(0.0, 5, true), std::vector<double>(6, 1.0));
  expect_error([] { pisco::gaussian_beam_window(-1.0, 10, false); }, "fwhm");
  expect_error([] { pisco::gaussian_beam_window(0.01, -1, false); }, "lmax");
}

TEST(Spectra, PixelWindowFromHealpyData) {
  const std::vector<double> t = pisco::pixel_window(64, 191, false);
  const std::vector<double> p = pisco::pixel_window(64, 191, true);
  ASSERT_EQ(t.size(), 192u);
  // The healpy-data files go to l = 4 NSIDE.
  EXPECT_EQ(pisco::pixel_window(64, 256, false).size(), 257u);
  std::cout << "pixel window NSIDE 64: W_0 " << t[0] << ", W_1 " << t[1] << ", W_128 " << t[128]
            << ", W_191 " << t[191] << "; polarization W_0 " << p[0] << ", W_2 " << p[2] << "\n";
  EXPECT_NEAR(t[0], 1.0, 1e-12);  // the file stores 1 + 8e-15
  for (int l = 1; l <= 191; ++l) ASSERT_LT(t[l], t[l - 1]) << l;
  // healpy.pixwin(64, pol=True): the spin-2 window is zero below l = 2.
  EXPECT_NEAR(t[1], 0.99997725, 1e-8);
  EXPECT_EQ(p[0], 0.0);
  EXPECT_EQ(p[1], 0.0);
  EXPECT_NEAR(p[2], 0.99997725, 1e-8);
  expect_error([] { pisco::pixel_window(64, 257, false); }, "pixel_window_n0064.fits");
  expect_error([] { pisco::pixel_window(3, 10, false); }, "pixel_window: NSIDE = 3");
}

TEST(Spectra, DeconvolveWindowsAndDl) {
  const int lmax = 10;
  pisco::Spectra s;
  for (auto* v : {&s.TT, &s.EE, &s.BB, &s.TE, &s.EB, &s.TB}) v->assign(lmax + 1, 1.0);
  const auto bt = pisco::gaussian_beam_window(2 * deg, lmax, false);
  const auto bp = pisco::gaussian_beam_window(2 * deg, lmax, true);
  const auto pt = pisco::pixel_window(16, lmax, false);
  const auto pp = pisco::pixel_window(16, lmax, true);
  const pisco::Spectra d = pisco::deconvolve_windows(s, bt, bp, pt, pp);
  for (int l = 0; l <= lmax; ++l) {
    const double wt = bt[l] * pt[l], wp = bp[l] * pp[l];
    EXPECT_DOUBLE_EQ(d.TT[l], 1.0 / (wt * wt));
    // The polarization pixel window is zero at l = 0, 1: those multipoles stay zero.
    EXPECT_DOUBLE_EQ(d.EE[l], l < 2 ? 0.0 : 1.0 / (wp * wp));
    EXPECT_DOUBLE_EQ(d.BB[l], d.EE[l]);
    EXPECT_DOUBLE_EQ(d.EB[l], d.EE[l]);
    EXPECT_DOUBLE_EQ(d.TE[l], l < 2 ? 0.0 : 1.0 / (wt * wp));
    EXPECT_DOUBLE_EQ(d.TB[l], d.TE[l]);
  }
  std::cout << "deconvolved NSIDE 16, 2 deg beam, l = 10: TT " << d.TT[10] << ", EE " << d.EE[10]
            << ", TE " << d.TE[10] << "\n";
  // Empty windows are skipped.
  const pisco::Spectra beam_only = pisco::deconvolve_windows(s, bt, bp, {}, {});
  EXPECT_DOUBLE_EQ(beam_only.TT[10], 1.0 / (bt[10] * bt[10]));
  EXPECT_DOUBLE_EQ(beam_only.EE[0], 1.0 / (bp[0] * bp[0]));
  EXPECT_EQ(pisco::deconvolve_windows(s, {}, {}, {}, {}).TE, s.TE);
  expect_error([&] { pisco::deconvolve_windows(s, std::span<const double>(bt).first(5), bp, pt, pp); },
               "temperature beam");

  const std::vector<double> dl = pisco::to_dl(std::vector<double>{3.0, 3.0, 2 * pi, pi});
  EXPECT_EQ(dl[0], 0.0);
  EXPECT_DOUBLE_EQ(dl[1], 3.0 / pi);
  EXPECT_DOUBLE_EQ(dl[2], 6.0);
  EXPECT_DOUBLE_EQ(dl[3], 6.0);
  // read_cl_table then to_dl gives back the table's D_l.
  const pisco::Spectra cl = pisco::read_cl_table(pisco::default_cl_file(), 3, false);
  EXPECT_NEAR(pisco::to_dl(cl.TT)[2], 1726.1, 1e-9);
}

}  // namespace

TEST(Spectra, RadialBeamWindow) {
  // exp(kappa cos theta) over the whole sphere has b_l = I_{l+1/2}(kappa) / I_{1/2}(kappa) exactly.
  const double kappa = 100.0;
  const auto vmf = pisco::radial_beam_window([&](double t) { return std::exp(kappa * (std::cos(t) - 1.0)); },
                                             std::numbers::pi, 200, 20000);
  double worst = 0;
  for (int l = 0; l <= 200; ++l)
    worst = std::max(worst, std::abs(vmf[l] - std::cyl_bessel_i(l + 0.5, kappa) / std::cyl_bessel_i(0.5, kappa)));
  std::printf("radial window of exp(kappa cos theta), l <= 200: max error %.2e\n", worst);
  EXPECT_LT(worst, 1e-10);
  // A 1.5 deg round Gaussian cut at 5 deg against the flat-sky window exp(-l(l+1) s^2 / 2): they differ
  // by O(s^2) only.
  const double fwhm = 1.5 * pisco::deg;
  const auto g = pisco::radial_beam_window(
      [&](double t) { return pisco::elliptical_gaussian_radial_profile(fwhm, fwhm, t); }, 5 * pisco::deg, 256);
  const auto ref = pisco::gaussian_beam_window(fwhm, 256, false);
  for (int l = 0; l <= 256; l += 16) EXPECT_NEAR(g[l], ref[l], 2e-4 * (1 + l * l * 1e-4)) << l;
  // The elliptical profile is the azimuthal mean of the elliptical Gaussian (trapezoid rule in phi,
  // exact to rounding for this periodic integrand).
  const double fx = 1.55 * pisco::deg, fy = 1.45 * pisco::deg, s = 1.0 / std::sqrt(8 * std::log(2.0));
  for (double t : {0.0, 0.3 * pisco::deg, 1.0 * pisco::deg, 3.0 * pisco::deg}) {
    double mean = 0;
    const int n = 256;
    for (int k = 0; k < n; ++k) {
      const double phi = 2 * std::numbers::pi * k / n, u = t * std::cos(phi), v = t * std::sin(phi);
      mean += std::exp(-(u * u / (2 * std::pow(fx * s, 2)) + v * v / (2 * std::pow(fy * s, 2)))) / n;
    }
    EXPECT_NEAR(pisco::elliptical_gaussian_radial_profile(fx, fy, t), mean, 1e-14) << t;
  }
  EXPECT_THROW(pisco::radial_beam_window([](double) { return 1.0; }, 4.0, 10), pisco::Error);
  EXPECT_THROW(pisco::radial_beam_window([](double) { return NAN; }, 0.1, 10), pisco::Error);
}
