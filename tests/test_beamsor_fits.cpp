// HEALPix beamsor files: write/read round trips of Gaussian beamsors, the resampling error against
// the analytic profile, NESTED and lower-case files, extra Mueller columns, and input errors.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <fitsio.h>
#include <healpix_base.h>
#include <pointing.h>

#include "support.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"
#include "pisco/units.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::Beamsor;

constexpr double pi = std::numbers::pi;
using pisco::deg;
const double fwhm_to_sigma = 1.0 / std::sqrt(8 * std::log(2.0));

class BeamsorFits : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("pisco-beamsor-fits-" + std::to_string(::getpid()) + "-" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
};

using pisco_test::contains;
using pisco_test::error_of;

std::size_t file_count(const fs::path& dir) {
  return static_cast<std::size_t>(std::distance(fs::directory_iterator(dir), fs::directory_iterator()));
}

// A beam table written by hand with CFITSIO: columns of 12 NSIDE^2 values in the given ordering.
void write_table(const fs::path& file, int nside, const std::string& ordering,
                 const std::vector<std::string>& names,
                 const std::vector<std::vector<double>>& columns) {
  fitsfile* f = nullptr;
  int status = 0;
  fits_create_diskfile(&f, file.c_str(), &status);
  fits_create_img(f, BYTE_IMG, 0, nullptr, &status);
  std::vector<char*> ttype, tform, tunit;
  char form[] = "1D", unit[] = "";
  for (const auto& n : names) {
    ttype.push_back(const_cast<char*>(n.c_str()));
    tform.push_back(form);
    tunit.push_back(unit);
  }
  fits_create_tbl(f, BINARY_TBL, 12LL * nside * nside, static_cast<int>(names.size()),
                  ttype.data(), tform.data(), tunit.data(), "BEAM", &status);
  long long ns = nside;
  fits_update_key(f, TLONGLONG, "NSIDE", &ns, nullptr, &status);
  fits_update_key(f, TSTRING, "ORDERING", const_cast<char*>(ordering.c_str()), nullptr, &status);
  for (std::size_t c = 0; c < columns.size(); ++c)
    fits_write_col(f, TDOUBLE, static_cast<int>(c) + 1, 1, 1,
                   static_cast<long long>(columns[c].size()), const_cast<double*>(columns[c].data()),
                   &status);
  fits_close_file(f, &status);
  ASSERT_EQ(status, 0) << "test setup: CFITSIO status " << status;
}

// The analytic circular Gaussian exp(-theta^2 / 2 s^2) as a full-sky map in the given ordering.
std::vector<double> gaussian_map(int nside, double fwhm, Healpix_Ordering_Scheme scheme) {
  const Healpix_Base base(nside, scheme, SET_NSIDE);
  const double s = fwhm * fwhm_to_sigma;
  std::vector<double> m(static_cast<std::size_t>(base.Npix()));
  for (int p = 0; p < base.Npix(); ++p) {
    const double theta = base.pix2ang(p).theta;
    m[p] = std::exp(-theta * theta / (2 * s * s));
  }
  return m;
}

std::vector<std::string> column_names(const fs::path& file) {
  fitsfile* f = nullptr;
  int status = 0, ncols = 0;
  fits_open_diskfile(&f, file.c_str(), READONLY, &status);
  fits_movabs_hdu(f, 2, nullptr, &status);
  fits_get_num_cols(f, &ncols, &status);
  std::vector<std::string> names;
  for (int c = 1; c <= ncols; ++c) {
    char key[FLEN_KEYWORD], value[FLEN_VALUE] = {};
    fits_make_keyn("TTYPE", c, key, &status);
    fits_read_key(f, TSTRING, key, value, nullptr, &status);
    names.push_back(value);
  }
  fits_close_file(f, &status);
  EXPECT_EQ(status, 0);
  return names;
}

// Largest |a - b| of every element of a over random points of the disc of radius sin(rho_max),
// relative to the largest |a| of that element over the same points.
struct Comparison {
  double worst_relative = 0.0;
  int worst_element = -1;
};
Comparison compare_at_random_points(const Beamsor& a, const Beamsor& b, int points) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double r = a.grid_half_width();
  std::array<double, 16> diff{}, peak{};
  for (int k = 0; k < points;) {
    const double x = u(rng) * r, y = u(rng) * r;
    if (x * x + y * y > r * r) continue;
    ++k;
    const auto ma = a.at(x, y), mb = b.at(x, y);
    for (int e = 0; e < 16; ++e) {
      diff[e] = std::max(diff[e], std::abs(ma[e / 4][e % 4] - mb[e / 4][e % 4]));
      peak[e] = std::max(peak[e], std::abs(ma[e / 4][e % 4]));
    }
  }
  // The peak of each element is at the beam centre.
  const auto centre = a.at(0, 0);
  Comparison c;
  for (int e = 0; e < 16; ++e) {
    peak[e] = std::max(peak[e], std::abs(centre[e / 4][e % 4]));
    if (peak[e] == 0) continue;
    if (diff[e] / peak[e] > c.worst_relative) {
      c.worst_relative = diff[e] / peak[e];
      c.worst_element = e;
    }
  }
  return c;
}

std::string name(int e) { return std::string("B_") + "TQUV"[e % 4] + "TQUV"[e / 4]; }

TEST_F(BeamsorFits, GaussianRoundTripAtNside1024) {
  pisco::BeamOptions o;
  o.rho_max = 5 * deg;
  const Beamsor original = Beamsor::gaussian(1.5 * deg, o);
  const fs::path file = dir_ / "gauss.fits";
  const auto t0 = std::chrono::steady_clock::now();
  original.write_healpix_fits(file, 1024);
  const auto t1 = std::chrono::steady_clock::now();
  const Beamsor back = Beamsor::read_healpix_fits(file, 5 * deg);
  const auto t2 = std::chrono::steady_clock::now();
  std::cout << "write " << std::chrono::duration<double>(t1 - t0).count() << " s ("
            << fs::file_size(file) / 1048576 << " MiB), read "
            << std::chrono::duration<double>(t2 - t1).count() << " s; " << back.description()
            << ", grid " << back.grid_size() << "^2, step " << back.grid_step() / deg * 60
            << " arcmin\n";
  EXPECT_EQ(file_count(dir_), 1u) << "a temporary file was left behind";

  for (int e = 0; e < 16; ++e) EXPECT_EQ(original.has_element(e / 4, e % 4), back.has_element(e / 4, e % 4)) << name(e);
  // The difference adds up the bilinear errors of two grids (the original's step FWHM/20 and the
  // read-back grid's step of one pixel, each (step/s)^2/8 of the peak near the axis: 1.7e-3 and
  // 1.0e-3) and the HEALPix resampling (below 2.6e-3, see the next test): 5e-3 of the peak.
  const Comparison c = compare_at_random_points(original, back, 20000);
  const double omega_rel = back.omega_tilde() / original.omega_tilde() - 1;
  std::cout << "at() over 20000 random points: max |read - original| / peak = " << c.worst_relative
            << " (" << name(c.worst_element) << "); Omega~ " << original.omega_tilde() << " -> "
            << back.omega_tilde() << " sr, relative change " << omega_rel << "\n";
  EXPECT_LT(c.worst_relative, 5e-3);
  EXPECT_LT(std::abs(omega_rel), 1e-3);
}

// Largest |grid node - analytic Gaussian| / peak over the nodes within rho_max, and where it is.
struct NodeError {
  double worst = 0.0, rho = 0.0;
};
NodeError node_error(const Beamsor& b, double s) {
  const auto grid = b.element(0, 0);
  const int n = b.grid_size();
  const double a = b.grid_half_width(), step = b.grid_step();
  NodeError e;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = -a + i * step, y = -a + j * step, r2 = x * x + y * y;
      if (r2 > a * a) continue;
      const double rho = std::asin(std::sqrt(r2));
      const double err = std::abs(grid[static_cast<std::size_t>(j) * n + i] - std::exp(-rho * rho / (2 * s * s)));
      if (err > e.worst) e = {err, rho};
    }
  return e;
}

// The error the HEALPix resampling adds, free of any other grid: the analytic Gaussian written as a
// map, read back, compared with the analytic profile at the beamsor's grid nodes. The largest error
// is on the beam axis, which HEALPix interpolates from the first ring of pixels at
// theta_1 = acos(1 - 1/(3 NSIDE^2)): the axis value is low by 1 - exp(-theta_1^2 / 2 s^2), about
// 1/(3 NSIDE^2 s^2). The pixel sum Omega~ is a midpoint rule in cos(theta) with ring spacing growing
// away from the pole; it is low by about 1/(18 NSIDE^2 s^2).
TEST_F(BeamsorFits, ResamplingErrorAgainstAnalyticGaussian) {
  const double fwhm = 1.5 * deg, rho_max = 5 * deg, s = fwhm * fwhm_to_sigma;
  const int nside = 1024;
  const fs::path file = dir_ / "analytic.fits";
  write_table(file, nside, "RING", {"B_TT"}, {gaussian_map(nside, fwhm, RING)});

  const Beamsor b = Beamsor::read_healpix_fits(file, rho_max, std::sqrt(4 * pi / (12.0 * nside * nside)));  // one pixel
  const NodeError e = node_error(b, s);
  // A grid with an odd node count has a node on the axis, where the error peaks.
  const Beamsor odd = Beamsor::read_healpix_fits(file, rho_max, 2 * std::sin(rho_max) / 173.5);
  ASSERT_EQ(odd.grid_size() % 2, 1);
  const NodeError e_odd = node_error(odd, s);
  const double theta1 = std::acos(1 - 1 / (3.0 * nside * nside));
  const double axis_predicted = 1 - std::exp(-theta1 * theta1 / (2 * s * s));

  const double reference = pisco::cap_integral([&](double r, double) { return std::exp(-r * r / (2 * s * s)); },
                                               rho_max, s);
  const double omega_rel = b.omega_tilde() / reference - 1;
  const double omega_predicted = -1 / (18.0 * nside * nside * s * s);
  std::cout << "NSIDE " << nside << " (pixel " << std::sqrt(4 * pi / (12.0 * nside * nside)) / deg * 60
            << " arcmin), FWHM 1.5 deg:\n  grid " << b.grid_size() << "^2 (no axis node): max |node - analytic| / peak = "
            << e.worst << " at rho = " << e.rho / deg * 60 << " arcmin\n  grid " << odd.grid_size()
            << "^2 (axis node): max = " << e_odd.worst << " at rho = " << e_odd.rho / deg * 60
            << " arcmin; predicted on the axis " << axis_predicted << "\n  Omega~ pixel sum / quadrature - 1 = "
            << omega_rel << ", predicted " << omega_predicted << "\n";
  EXPECT_LT(e.worst, 1e-3);
  EXPECT_LT(e_odd.worst, 3e-3);
  EXPECT_NEAR(e_odd.worst, axis_predicted, 0.1 * axis_predicted);
  EXPECT_NEAR(omega_rel, omega_predicted, 0.05 * std::abs(omega_predicted));
}

TEST_F(BeamsorFits, NestedAndLowerCaseFilesMatchRing) {
  const int nside = 64;
  const double fwhm = 10 * deg, rho_max = 30 * deg;
  write_table(dir_ / "ring.fits", nside, "RING", {"B_TT"}, {gaussian_map(nside, fwhm, RING)});
  write_table(dir_ / "nest.fits", nside, "NESTED", {"b_tt"}, {gaussian_map(nside, fwhm, NEST)});
  const Beamsor r = Beamsor::read_healpix_fits(dir_ / "ring.fits", rho_max, 0.5 * deg);
  const Beamsor n = Beamsor::read_healpix_fits(dir_ / "nest.fits", rho_max, 0.5 * deg);
  double worst = 0.0;
  for (std::size_t k = 0; k < r.element(0, 0).size(); ++k)
    worst = std::max(worst, std::abs(r.element(0, 0)[k] - n.element(0, 0)[k]));
  std::cout << "NESTED vs RING file: max |grid difference| = " << worst << ", Omega~ " << r.omega_tilde()
            << " vs " << n.omega_tilde() << "; grid " << r.grid_size() << "^2\n";
  EXPECT_EQ(worst, 0.0);
  EXPECT_EQ(r.omega_tilde(), n.omega_tilde());
  EXPECT_EQ(r.grid_size(), static_cast<int>(std::ceil(2 * std::sin(rho_max) / (0.5 * deg))) + 1);
}

TEST_F(BeamsorFits, CrossPolarColumnsRoundTrip) {
  pisco::BeamOptions o;
  o.rho_max = 5 * deg;
  o.cross_polar = 0.1;
  const Beamsor original = Beamsor::gaussian(1.5 * deg, o);
  const fs::path file = dir_ / "xpol.fits";
  original.write_healpix_fits(file, 512);
  std::vector<std::string> expected;
  for (int e = 0; e < 16; ++e)
    if (original.has_element(e / 4, e % 4)) expected.push_back(name(e));
  const auto names = column_names(file);
  std::string listed;
  for (const auto& n : names) listed += n + " ";
  std::cout << "columns written: " << listed << "\n";
  EXPECT_EQ(names, expected);
  EXPECT_TRUE(original.has_element(2, 1) && original.has_element(1, 2));  // B_QU and B_UQ

  const Beamsor back = Beamsor::read_healpix_fits(file, 5 * deg);
  for (int e = 0; e < 16; ++e) EXPECT_EQ(original.has_element(e / 4, e % 4), back.has_element(e / 4, e % 4)) << name(e);
  // At NSIDE 512 every error above is four times larger, and the read-back grid step twice.
  const Comparison c = compare_at_random_points(original, back, 20000);
  const auto centre = back.at(0, 0);
  std::cout << "NSIDE 512: max |read - original| / element peak = " << c.worst_relative << " ("
            << name(c.worst_element) << "); B_QU / B_TT at the centre = " << centre[2][1] / centre[0][0]
            << " (expected -2 kappa / (1 + kappa^2) = " << -0.2 / 1.01 << ")\n";
  EXPECT_LT(c.worst_relative, 1.5e-2);
  EXPECT_NEAR(centre[2][1] / centre[0][0], -0.2 / 1.01, 1e-9);
}

TEST_F(BeamsorFits, MissingBttColumnIsAnError) {
  const int nside = 16;
  write_table(dir_ / "no_tt.fits", nside, "RING", {"B_QQ", "SOMETHING"},
              {gaussian_map(nside, 10 * deg, RING), gaussian_map(nside, 10 * deg, RING)});
  const std::string msg = error_of([&] { Beamsor::read_healpix_fits(dir_ / "no_tt.fits", 20 * deg); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, (dir_ / "no_tt.fits").string()) && contains(msg, "B_TT")) << msg;
}

TEST_F(BeamsorFits, RhoMaxOutsideFrontHemisphereIsAnError) {
  const int nside = 16;
  const fs::path file = dir_ / "beam.fits";
  write_table(file, nside, "RING", {"B_TT"}, {gaussian_map(nside, 10 * deg, RING)});
  for (double rho_deg : {95.0, 90.0, 0.0, -5.0}) {
    const std::string msg = error_of([&] { Beamsor::read_healpix_fits(file, rho_deg * deg); });
    std::cout << "rho_max " << rho_deg << " deg: " << msg << "\n";
    EXPECT_TRUE(contains(msg, file.string()) && contains(msg, "rho_max")) << msg;
  }
}

TEST_F(BeamsorFits, BadFilesAreErrors) {
  const int nside = 16;
  auto tt = gaussian_map(nside, 10 * deg, RING);
  tt[7] = std::numeric_limits<double>::quiet_NaN();
  write_table(dir_ / "nan.fits", nside, "RING", {"B_TT"}, {tt});
  tt[7] = -1.6375e30;  // UNSEEN inside the cap
  write_table(dir_ / "unseen.fits", nside, "RING", {"B_TT"}, {tt});
  write_table(dir_ / "nside12.fits", 12, "RING", {"B_TT"}, {std::vector<double>(12 * 144, 1.0)});
  std::ofstream(dir_ / "text.fits") << "not FITS\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"nan.fits", "pixel 7"}, {"unseen.fits", "UNSEEN"}, {"nside12.fits", "NSIDE = 12"},
      {"text.fits", "FITS"},   {"absent.fits", "no such file"}};
  for (const auto& [file, expected] : cases) {
    const std::string msg = error_of([&] { Beamsor::read_healpix_fits(dir_ / file, 20 * deg); });
    std::cout << msg << "\n";
    EXPECT_TRUE(contains(msg, (dir_ / file).string()) && contains(msg, expected)) << msg;
  }
}

TEST_F(BeamsorFits, WriteErrorsLeaveNoFile) {
  pisco::BeamOptions o;
  o.rho_max = 5 * deg;
  const Beamsor b = Beamsor::gaussian(1.5 * deg, o);
  const std::string bad_nside = error_of([&] { b.write_healpix_fits(dir_ / "b.fits", 12); });
  std::cout << bad_nside << "\n";
  EXPECT_TRUE(contains(bad_nside, "NSIDE = 12")) << bad_nside;
  const fs::path blocker = dir_ / "blocker";
  std::ofstream(blocker) << "x";
  const std::string unwritable = error_of([&] { b.write_healpix_fits(blocker / "b.fits", 64); });
  std::cout << unwritable << "\n";
  EXPECT_TRUE(contains(unwritable, (blocker / "b.fits").string())) << unwritable;
  EXPECT_EQ(file_count(dir_), 1u);
}

}  // namespace
