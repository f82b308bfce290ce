// Beams as teams hold them (docs/beams.md): harmonic beams against HEALPix C++'s own synthesis, GRASP
// files written from an analytic beam against that beam's beamsor, and every malformed input held to
// one error naming the file and what was expected.
#include <fitsio.h>
#include <gtest/gtest.h>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <healpix_map.h>
#include <xcomplex.h>

#include <cmath>
#include <complex>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numbers>
#include <random>

#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"
#include "beam_file_writers.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::Beamsor;
using pisco::deg;
using pisco::GraspBeam;
using pisco::HarmonicBeam;
using cd = std::complex<double>;
constexpr double pi = std::numbers::pi;

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("pisco_test_beam_files_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return dir / name;
}

HarmonicBeam random_beam(int lmax, int mmax, unsigned seed, double fwhm) {
  HarmonicBeam b;
  b.lmax = lmax;
  b.mmax = mmax;
  b.source = "random";
  const std::size_t n = HarmonicBeam::size(lmax, mmax);
  b.t.assign(n, cd{});
  b.e.assign(n, cd{});
  b.b.assign(n, cd{});
  std::mt19937 g(seed);
  std::normal_distribution<double> normal;
  const double s = fwhm / std::sqrt(8 * std::log(2.0));
  for (int m = 0; m <= mmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const double w = std::exp(-0.5 * l * (l + 1) * s * s) * std::sqrt((2 * l + 1) / (4 * pi)) / (1 + m);
      const std::size_t k = HarmonicBeam::index(lmax, l, m);
      b.t[k] = m ? 0.2 * w * cd(normal(g), normal(g)) : w * (1.0 + 0.05 * normal(g));
      if (l >= 2) {
        b.e[k] = 0.3 * w * cd(normal(g), m ? normal(g) : 0.0);
        b.b[k] = 0.3 * w * cd(normal(g), m ? normal(g) : 0.0);
      }
    }
  b.t[0] = cd(std::sqrt(1 / (4 * pi)), 0);
  return b;
}

using pisco_test::write_alm_fits;

template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const pisco::Error& e) {
    return e.what();
  }
  return "(no error)";
}

// ---- harmonic beams -----------------------------------------------------------------------------

// HEALPix C++'s alm2map_pol of a beam's coefficients against the beam's own synthesis (stokes_at), at
// every `stride`-th pixel centre within 30 deg of the north pole (the beam axis), Q and U turned from
// (theta-hat, phi-hat) to the Ludwig-3 basis.
struct HealpixComparison {
  double worst = 0, scale_t = 0, scale_all = 0;  // largest difference; largest |T|, and |T|, |Q|, |U|
  int checked = 0;
  bool finite = true;
};
HealpixComparison compare_with_healpix(const HarmonicBeam& beam, int nside, int stride) {
  const int lmax = beam.lmax, mmax = beam.mmax;
  Alm<xcomplex<double>> t(lmax, mmax), e(lmax, mmax), b(lmax, mmax);
  for (int m = 0; m <= mmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const std::size_t k = HarmonicBeam::index(lmax, l, m);
      t(l, m) = xcomplex<double>(beam.t[k].real(), beam.t[k].imag());
      e(l, m) = xcomplex<double>(beam.e[k].real(), beam.e[k].imag());
      b(l, m) = xcomplex<double>(beam.b[k].real(), beam.b[k].imag());
    }
  Healpix_Map<double> mt(nside, RING, SET_NSIDE), mq(nside, RING, SET_NSIDE), mu(nside, RING, SET_NSIDE);
  alm2map_pol(t, e, b, mt, mq, mu);
  HealpixComparison c;
  for (int p = 0; p < mt.Npix(); p += stride) {
    const pointing ang = mt.pix2ang(p);
    if (ang.theta > 30 * deg) break;
    const auto s = beam.stokes_at(ang.theta, ang.phi);
    c.finite = c.finite && std::isfinite(s[0]) && std::isfinite(s[1]) && std::isfinite(s[2]);
    const cd l3 = cd(mq[p], mu[p]) * std::polar(1.0, 2 * ang.phi);
    c.worst = std::max({c.worst, std::abs(s[0] - mt[p]), std::abs(s[1] - l3.real()), std::abs(s[2] - l3.imag())});
    c.scale_t = std::max(c.scale_t, std::abs(mt[p]));
    c.scale_all = std::max({c.scale_all, std::abs(mt[p]), std::abs(mq[p]), std::abs(mu[p])});
    ++c.checked;
  }
  return c;
}

TEST(HarmonicBeam, SynthesisMatchesHealpixAlm2mapPol) {
  const HarmonicBeam beam = random_beam(60, 12, 7, 5 * deg);
  const HealpixComparison c = compare_with_healpix(beam, 32, 1);
  EXPECT_GT(c.checked, 100);
  EXPECT_LT(c.worst, 1e-12 * c.scale_t) << "worst " << c.worst << " of " << c.scale_t;
}

// Any mmax up to lmax: at lmax = mmax = 1400 the Wigner-d closed form's factorials overflow a double
// and its powers underflow it (a file with mmax above about 1024 once gave "B_TT is nan"); the
// synthesis against HEALPix C++'s alm2map_pol at points out to 30 deg, where every m counts.
TEST(HarmonicBeam, AnyMmaxUpToLmaxMatchesHealpixAlm2mapPol) {
  const int lmax = 1400, mmax = 1400;
  HarmonicBeam beam = random_beam(lmax, mmax, 11, 0.3 * deg);
  // The high m as large as the low ones at the largest l: every m counts at 30 deg.
  for (int m = 0; m <= mmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const std::size_t k = HarmonicBeam::index(lmax, l, m);
      beam.t[k] *= 1.0 + m;
      beam.e[k] *= 1.0 + m;
      beam.b[k] *= 1.0 + m;
    }
  const HealpixComparison c = compare_with_healpix(beam, 256, 2017);
  ASSERT_TRUE(c.finite);
  EXPECT_GT(c.checked, 20);
  EXPECT_LT(c.worst, 1e-10 * c.scale_all) << "worst " << c.worst << " of " << c.scale_all;
}

TEST(HarmonicBeam, BeamsorNodesAreTheSynthesisAndTurnWithTheAngle) {
  const int lmax = 200, mmax = 6;
  HarmonicBeam beam = random_beam(lmax, mmax, 3, 2 * deg);
  pisco::FileBeamOptions o;
  o.rho_max = 5 * deg;
  o.grid_step = 0.25 * deg;
  o.angle = 30 * deg;
  const Beamsor bs = Beamsor::from_harmonic(beam, o);
  ASSERT_FALSE(bs.is_radial());
  // The same beam turned in harmonic space: b_lm e^{-i m alpha}.
  HarmonicBeam turned = beam;
  for (int m = 0; m <= mmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const std::size_t k = HarmonicBeam::index(lmax, l, m);
      const cd r = std::polar(1.0, -m * o.angle);
      turned.t[k] *= r;
      turned.e[k] *= r;
      turned.b[k] *= r;
    }
  const int n = bs.grid_size();
  double worst = 0, peak = 0;
  for (int j = 0; j < n; j += 3)
    for (int i = 0; i < n; i += 3) {
      const double x = -bs.grid_half_width() + i * bs.grid_step(), y = -bs.grid_half_width() + j * bs.grid_step();
      const double r = std::sqrt(x * x + y * y);
      if (r > bs.grid_half_width()) continue;
      const auto s = turned.stokes_at(std::asin(r), std::atan2(y, x));
      // stokes_at gives Q, U in the antenna's Ludwig-3 basis; the beamsor's are in the turned frame's.
      const cd p = cd(s[1], s[2]) * std::polar(1.0, -2 * o.angle);
      const std::size_t k = static_cast<std::size_t>(j) * n + i;
      worst = std::max({worst, std::abs(bs.element(0, 0)[k] - s[0]), std::abs(bs.element(1, 1)[k] - p.real()),
                        std::abs(bs.element(1, 2)[k] - p.imag())});
      peak = std::max(peak, std::abs(s[0]));
    }
  // Radii are shared between nodes after rounding to 1e-12 rad: a 1e-11 relative difference.
  EXPECT_LT(worst, 1e-10 * peak);
}

TEST(HarmonicBeam, GaussianFileIsRadialAndMatchesTheGaussianBeam) {
  // The Gaussian the frameworks write (-sqrt 2 on E and B, B = i E at m = 2), read from a FITS file.
  const int lmax = 700;
  const double fwhm = 1.5 * deg, s = fwhm / std::sqrt(8 * std::log(2.0));
  const HarmonicBeam g = pisco_test::gaussian_blm(fwhm, lmax);
  const fs::path file = scratch("gauss_blm.fits");
  write_alm_fits(file, {&g.t, &g.e, &g.b}, lmax, 2);
  const HarmonicBeam read = HarmonicBeam::read_fits(file);
  EXPECT_EQ(read.lmax, lmax);
  EXPECT_EQ(read.mmax, 2);
  pisco::FileBeamOptions o;
  o.rho_max = 5 * deg;
  const Beamsor bs = Beamsor::from_harmonic(read, o);
  EXPECT_TRUE(bs.is_radial()) << bs.description();
  EXPECT_NEAR(bs.omega_tilde(), 1.0, 1e-6);
  // The small-angle Gaussian exp(-rho^2 / 2 s^2) / (2 pi s^2): the harmonic heat kernel differs from
  // it by O(s^2) ~ 4e-5 of the peak; Q equals T (a detector polarized along x) and U is zero.
  double worst_t = 0, worst_q = 0, worst_u = 0;
  const double peak = 1 / (2 * pi * s * s);
  for (double rho = 0; rho < 3 * fwhm; rho += 0.05 * deg) {
    const pisco::Mueller m = bs.at(std::sin(rho), 0.0);
    worst_t = std::max(worst_t, std::abs(m[0][0] - peak * std::exp(-rho * rho / (2 * s * s))));
    worst_q = std::max(worst_q, std::abs(m[1][1] - m[0][0]));
    worst_u = std::max(worst_u, std::abs(m[1][2]));
  }
  EXPECT_LT(worst_t, 2e-3 * peak);
  EXPECT_LT(worst_q, 1e-3 * peak);
  EXPECT_LT(worst_u, 1e-12 * peak);
}

TEST(HarmonicBeam, MalformedInputsNameWhatIsWrong) {
  HarmonicBeam b = random_beam(20, 4, 1, 10 * deg);
  HarmonicBeam bad = b;
  bad.mmax = 30;
  EXPECT_NE(error_of([&] { bad.check(); }).find("mmax = 30 must lie in 0..lmax = 20"), std::string::npos);
  bad = b;
  bad.e[5] = cd(std::nan(""), 0);
  EXPECT_NE(error_of([&] { bad.check(); }).find("is not finite"), std::string::npos);
  bad = b;
  bad.t[0] = 0;
  EXPECT_NE(error_of([&] { bad.check(); }).find("must be positive"), std::string::npos);
  bad = b;
  bad.b.clear();
  EXPECT_NE(error_of([&] { bad.check(); }).find("E and B must both be empty"), std::string::npos);

  const fs::path f = scratch("bad_mmax.fits");
  write_alm_fits(f, {&b.t}, 20, 4, 25);
  const std::string e1 = error_of([&] { HarmonicBeam::read_fits(f); });
  EXPECT_NE(e1.find(f.string()), std::string::npos) << e1;
  EXPECT_NE(e1.find("MAX-MPOL = 25 is above MAX-LPOL = 20"), std::string::npos) << e1;
  const fs::path two = scratch("two.fits");
  write_alm_fits(two, {&b.t, &b.e}, 20, 4);
  EXPECT_NE(error_of([&] { HarmonicBeam::read_fits(two); }).find("expected 1 (T) or 3 (T, E, B)"), std::string::npos);
  const fs::path text = scratch("not_fits.fits");
  std::ofstream(text) << "hello";
  EXPECT_NE(error_of([&] { HarmonicBeam::read_fits(text); }).find(text.string()), std::string::npos);
}

// ---- GRASP files --------------------------------------------------------------------------------

// The analytic beam: an elliptical Gaussian (widths fx along x, fy along y) with the quadrupole
// cross-polar field cx = kappa sin(2 sigma) q e^(1 - q) co, and a phase, which Stokes patterns ignore.
struct Analytic {
  double fx = 1.5 * deg, fy = 1.0 * deg, kappa = 0.05;
  void fields(double rho, double sigma, cd& co, cd& cx) const {
    const double to_s = 1.0 / std::sqrt(8 * std::log(2.0));
    const double sx = fx * to_s, sy = fy * to_s;
    const double u = rho * std::cos(sigma), v = rho * std::sin(sigma);
    const double power = std::exp(-(u * u / (2 * sx * sx) + v * v / (2 * sy * sy)));
    const double q = rho * rho / (2 * sx * sy);
    const double k = kappa * std::sin(2 * sigma) * q * std::exp(1 - q);
    co = std::sqrt(power) * std::polar(1.0, 0.3 + 40 * rho);
    cx = k * co;
  }
  Beamsor beamsor(double rho_max, double step) const {
    pisco::BeamOptions o;
    o.rho_max = rho_max;
    o.grid_step = step;
    o.cross_polar = kappa;
    o.cross_polar_pattern = pisco::CrossPolarPattern::quadrupole;
    return Beamsor::elliptical_gaussian(fx, fy, 0.0, o);
  }
};

void write_uv_grd(const fs::path& file, const Analytic& a, double half, int n, int nsets = 1) {
  pisco_test::write_uv_grd(file, [&a](double rho, double sigma, cd& co, cd& cx) { a.fields(rho, sigma, co, cx); }, half, n,
                           nsets);
}

double worst_element_difference(const Beamsor& a, const Beamsor& b) {
  EXPECT_EQ(a.grid_size(), b.grid_size());
  double worst = 0;
  for (int e = 0; e < 16; ++e) {
    const auto x = a.element(e / 4, e % 4), y = b.element(e / 4, e % 4);
    if (x.empty() && y.empty()) continue;
    for (int j = 0; j < a.grid_size(); ++j)
      for (int i = 0; i < a.grid_size(); ++i) {
        const double px = -a.grid_half_width() + i * a.grid_step(), py = -a.grid_half_width() + j * a.grid_step();
        if (px * px + py * py > a.grid_half_width() * a.grid_half_width()) continue;
        const std::size_t k = static_cast<std::size_t>(j) * a.grid_size() + i;
        worst = std::max(worst, std::abs((x.empty() ? 0.0 : x[k]) - (y.empty() ? 0.0 : y[k])));
      }
  }
  return worst;
}

TEST(GraspBeam, UvGridReproducesTheAnalyticBeamsor) {
  const Analytic a;
  const fs::path file = scratch("analytic_uv.grd");
  const double rho_max = 4 * deg, step = a.fy / 20;
  write_uv_grd(file, a, std::sin(4.5 * deg), 301);  // 1.8 arcmin: FWHM_y / 33
  const auto beams = GraspBeam::read(file);
  ASSERT_EQ(beams.size(), 1u);
  EXPECT_EQ(beams[0].frequency, 100.0);
  pisco::FileBeamOptions o;
  o.rho_max = rho_max;
  o.grid_step = step;
  const Beamsor got = Beamsor::from_grasp(beams[0], o);
  const Beamsor want = a.beamsor(rho_max, step);
  const double worst = worst_element_difference(got, want);
  std::printf("uv grid: worst Mueller element difference %.2e of the peak; Omega~ %.10g vs %.10g\n", worst,
              got.omega_tilde(), want.omega_tilde());
  EXPECT_LT(worst, 1e-5);
  EXPECT_NEAR(got.omega_tilde() / want.omega_tilde(), 1.0, 1e-5);
}

TEST(GraspBeam, ThetaPhiGridAndCutsReproduceTheAnalyticBeamsor) {
  const Analytic a;
  const double rho_max = 4 * deg, step = a.fy / 20;
  const Beamsor want = a.beamsor(rho_max, step);
  // IGRID 7: x = phi 0..360 (the last column repeats the first), y = theta 0..5 deg.
  {
    const fs::path file = scratch("analytic_tp.grd");
    std::ofstream out(file);
    out.precision(17);
    const int nphi = 181, ntheta = 151;
    out << "theta-phi grid\n++++\n1\n1 3 2 7\n0 0\n0 0 360 5\n" << nphi << " " << ntheta << " 0\n";
    for (int j = 0; j < ntheta; ++j)
      for (int i = 0; i < nphi; ++i) {
        cd co, cx;
        a.fields(5.0 * deg * j / (ntheta - 1), 2 * pi * i / (nphi - 1), co, cx);
        out << co.real() << " " << co.imag() << " " << cx.real() << " " << cx.imag() << "\n";
      }
    out.close();
    const Beamsor got = Beamsor::from_grasp(GraspBeam::read(file).at(0), {rho_max, step, 0.0});
    const double worst = worst_element_difference(got, want);
    std::printf("theta-phi grid: worst Mueller element difference %.2e of the peak\n", worst);
    EXPECT_LT(worst, 1e-5);
  }
  // Cuts from -5 to 5 deg at 60 phi in [0, 180), two frequencies in one file.
  {
    const fs::path file = scratch("analytic.cut");
    std::ofstream out(file);
    out.precision(17);
    const int ncut = 60, nv = 301;
    for (int f = 0; f < 2; ++f)
      for (int c = 0; c < ncut; ++c) {
        const double phi = 180.0 * c / ncut;
        out << "Field data in cuts\n-5 " << 10.0 / (nv - 1) << " " << nv << " " << phi << " 3 1 2\n";
        for (int k = 0; k < nv; ++k) {
          const double theta = (-5.0 + 10.0 * k / (nv - 1)) * deg;
          cd co, cx;
          a.fields(std::abs(theta), phi * deg + (theta < 0 ? pi : 0), co, cx);
          if (f == 1) co *= 2.0, cx *= 2.0;
          out << co.real() << " " << co.imag() << " " << cx.real() << " " << cx.imag() << "\n";
        }
      }
    out.close();
    const auto beams = GraspBeam::read(file);
    ASSERT_EQ(beams.size(), 2u);
    EXPECT_NE(beams[1].source.find("beam 2 of 2"), std::string::npos);
    const Beamsor got = Beamsor::from_grasp(beams[0], {rho_max, step, 0.0});
    const double worst = worst_element_difference(got, want);
    std::printf("120 half-cuts: worst Mueller element difference %.2e of the peak\n", worst);
    EXPECT_LT(worst, 1e-5);
  }
}

TEST(GraspBeam, AzimuthElevationGridsReproduceTheAnalyticBeamsor) {
  // IGRID 4, 5 and 6: x = az, y = el in degrees, each grid's direction as docs/beams.md gives it.
  const Analytic a;
  const double rho_max = 4 * deg, step = a.fy / 20;
  const Beamsor want = a.beamsor(rho_max, step);
  for (const int igrid : {4, 5, 6}) {
    const fs::path file = scratch("azel_" + std::to_string(igrid) + ".grd");
    std::ofstream out(file);
    out.precision(17);
    const int n = 301;
    out << "az-el grid\n++++\n1\n1 3 2 " << igrid << "\n0 0\n-5 -5 5 5\n" << n << " " << n << " 0\n";
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double az = (-5.0 + 10.0 * i / (n - 1)) * deg, el = (-5.0 + 10.0 * j / (n - 1)) * deg;
        double theta, phi;
        if (igrid == 5) {
          theta = std::hypot(az, el);
          phi = std::atan2(el, -az);
        } else {
          const double u = igrid == 4 ? -std::sin(az) * std::cos(el) : -std::sin(az);
          const double v = igrid == 4 ? std::sin(el) : std::cos(az) * std::sin(el);
          const double w = std::cos(az) * std::cos(el);
          theta = std::acos(std::clamp(w, -1.0, 1.0));
          phi = std::atan2(v, u);
        }
        cd co, cx;
        a.fields(theta, phi, co, cx);
        out << co.real() << " " << co.imag() << " " << cx.real() << " " << cx.imag() << "\n";
      }
    out.close();
    const Beamsor got = Beamsor::from_grasp(GraspBeam::read(file).at(0), {rho_max, step, 0.0});
    const double worst = worst_element_difference(got, want);
    std::printf("IGRID %d: worst Mueller element difference %.2e of the peak\n", igrid, worst);
    EXPECT_LT(worst, 1e-5) << "IGRID " << igrid;
  }
}

TEST(GraspBeam, TurnedBeamIsTheBeamAtTheTurnedDirection) {
  const Analytic a;
  const fs::path file = scratch("turned.grd");
  write_uv_grd(file, a, std::sin(4.5 * deg), 201);
  const GraspBeam g = GraspBeam::read(file).at(0);
  const Beamsor plain = Beamsor::from_grasp(g, {4 * deg, 0.1 * deg, 0.0});
  const Beamsor turned = Beamsor::from_grasp(g, {4 * deg, 0.1 * deg, 90 * deg});
  // Turned by 90 deg, (x, y) sees the plain beam at (y, -x), with the same Stokes response in its own
  // co-polar basis: the pair partner's beam.
  double worst = 0;
  for (double x = -0.05; x <= 0.05; x += 0.0123)
    for (double y = -0.05; y <= 0.05; y += 0.0117) {
      const auto m1 = turned.at(x, y), m0 = plain.at(y, -x);
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) worst = std::max(worst, std::abs(m1[r][c] - m0[r][c]));
    }
  EXPECT_LT(worst, 1e-12);
}

TEST(GraspBeam, StokesMuellerIsTheCrossPolarMatrixAndARotation) {
  // In-phase cross-polar field kappa: (1 + k^2) R(atan k).
  const double k = 0.2;
  const auto m = Beamsor::stokes_mueller(1 + k * k, 1 - k * k, 2 * k, 0);
  EXPECT_DOUBLE_EQ(m[0][0], 1 + k * k);
  EXPECT_NEAR(m[2][1], -2 * k, 1e-15);
  EXPECT_NEAR(m[2][2], 1 - k * k, 1e-15);
  EXPECT_NEAR(m[3][3], 1 + k * k, 1e-15);
  // Circular: the Q, U, V block is I times a rotation (orthogonal, determinant 1).
  const auto c = Beamsor::stokes_mueller(2, 0.6, 0.8, std::sqrt(4 - 1.0));
  double gram[3][3] = {};
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b)
      for (int x = 0; x < 3; ++x) gram[a][b] += c[a + 1][x + 1] * c[b + 1][x + 1] / 4;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) EXPECT_NEAR(gram[a][b], a == b ? 1.0 : 0.0, 1e-14);
}

TEST(GraspBeam, MalformedFilesNameTheLineAndWhatWasExpected) {
  const Analytic a;
  const fs::path good = scratch("good.grd");
  write_uv_grd(good, a, std::sin(4.5 * deg), 11);
  std::vector<std::string> lines;
  {
    std::ifstream in(good);
    for (std::string l; std::getline(in, l);) lines.push_back(l);
  }
  const auto variant = [&](const std::string& name, const std::function<void(std::vector<std::string>&)>& edit) {
    auto copy = lines;
    edit(copy);
    const fs::path f = scratch(name);
    std::ofstream out(f);
    for (const auto& l : copy) out << l << "\n";
    out.close();
    return error_of([&] { GraspBeam::read(f); });
  };
  const std::size_t header = 10;  // the first data row's index (0-based)
  EXPECT_NE(variant("trunc.grd", [](auto& l) { l.resize(l.size() - 5); }).find("ends before point 7 of row 11"), std::string::npos);
  EXPECT_NE(variant("comp.grd", [&](auto& l) { l[header + 3] = "1 2 3"; }).find("line 14: point 4 of row 1"), std::string::npos);
  EXPECT_NE(variant("comp2.grd", [&](auto& l) { l[header + 3] = "1 2 3"; }).find("expected 4 numbers"), std::string::npos);
  EXPECT_NE(variant("nan.grd", [&](auto& l) { l[header + 2] = "nan 0 0 0"; }).find("is not finite"), std::string::npos);
  EXPECT_NE(variant("ncomp.grd", [](auto& l) { l[6] = "1 3 5 1"; }).find("NCOMP = 5"), std::string::npos);
  EXPECT_NE(variant("icomp.grd", [](auto& l) { l[6] = "1 1 2 1"; }).find("ICOMP = 1 (E_theta and E_phi)"), std::string::npos);
  EXPECT_NE(variant("igrid.grd", [](auto& l) { l[6] = "1 3 2 9"; }).find("IGRID = 9"), std::string::npos);
  EXPECT_NE(variant("noplus.grd", [](auto& l) { l[4] = "+++"; }).find("no line starting with \"++++\""), std::string::npos);
  const std::string t = variant("trunc2.grd", [](auto& l) { l.resize(l.size() - 5); });
  EXPECT_NE(t.find(scratch("trunc2.grd").string()), std::string::npos) << t;
  // A beam without power, and a rho_max beyond the grid.
  const fs::path zero = scratch("zero.grd");
  Analytic none;
  {
    auto copy = lines;
    for (std::size_t i = header; i < copy.size(); ++i) copy[i] = "0 0 0 0";
    std::ofstream out(zero);
    for (const auto& l : copy) out << l << "\n";
  }
  const std::string z = error_of([&] { Beamsor::from_grasp(GraspBeam::read(zero).at(0), {2 * deg, 0.1 * deg, 0.0}); });
  EXPECT_NE(z.find("zero everywhere"), std::string::npos) << z;
  const std::string far = error_of([&] { Beamsor::from_grasp(GraspBeam::read(good).at(0), {10 * deg, 0.1 * deg, 0.0}); });
  EXPECT_NE(far.find("rho_max = 10 deg is beyond it"), std::string::npos) << far;
  EXPECT_NE(error_of([&] { GraspBeam::read(scratch("x.txt")); }).find("expected a TICRA GRASP file named .grd"), std::string::npos);
}

}  // namespace
