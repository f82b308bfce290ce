// HEALPix FITS maps: round trips, files written by HEALPix C++ and by hand with CFITSIO, the IAU
// convention, partial column sets, and every failure giving one error that names the file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include <fitshandle.h>
#include <fitsio.h>
#include <healpix_map.h>
#include <healpix_map_fitsio.h>

#include "map_file_writers.hpp"
#include "support.hpp"
#include "pisco/error.hpp"
#include "pisco/sky.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::Sky;

// A fresh directory per test, removed afterwards.
class SkyFits : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("pisco-sky-fits-" + std::to_string(::getpid()) + "-" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::permissions(dir_, fs::perms::owner_all, fs::perm_options::add, ec);
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
};

std::vector<double> random_map(int nside, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1e-4);
  std::vector<double> m(12 * static_cast<std::size_t>(nside) * nside);
  for (double& v : m) v = normal(rng);
  return m;
}

// A HEALPix-style table written directly with CFITSIO, so the tests control every key.
struct TableSpec {
  long long nside_key = 0;  // 0: no NSIDE key
  std::string ordering = "RING";
  std::string polcconv;     // empty: no POLCCONV key
  std::vector<std::string> names;
  std::vector<std::vector<double>> columns;
  std::vector<long long> repeats;  // values per row for each column (default 1)
  std::string unit1;               // empty: no TUNIT1
};

void write_table(const fs::path& file, const TableSpec& spec) {
  fitsfile* f = nullptr;
  int status = 0;
  fits_create_diskfile(&f, file.c_str(), &status);
  fits_create_img(f, BYTE_IMG, 0, nullptr, &status);
  const int ncols = static_cast<int>(spec.names.size());
  std::vector<std::string> forms(ncols);
  std::vector<char*> ttype(ncols), tform(ncols), tunit(ncols);
  std::string empty;
  long long rows = 0;
  for (int c = 0; c < ncols; ++c) {
    const long long repeat = spec.repeats.empty() ? 1 : spec.repeats[c];
    forms[c] = std::to_string(repeat) + "D";
    ttype[c] = const_cast<char*>(spec.names[c].c_str());
    tform[c] = const_cast<char*>(forms[c].c_str());
    tunit[c] = const_cast<char*>(c == 0 ? spec.unit1.c_str() : empty.c_str());
    rows = std::max<long long>(rows, static_cast<long long>(spec.columns[c].size()) / repeat);
  }
  fits_create_tbl(f, BINARY_TBL, rows, ncols, ttype.data(), tform.data(), tunit.data(), "xtension",
                  &status);
  if (spec.nside_key) {
    long long nside = spec.nside_key;
    fits_update_key(f, TLONGLONG, "NSIDE", &nside, nullptr, &status);
  }
  fits_update_key(f, TSTRING, "ORDERING", const_cast<char*>(spec.ordering.c_str()), nullptr, &status);
  if (!spec.polcconv.empty())
    fits_update_key(f, TSTRING, "POLCCONV", const_cast<char*>(spec.polcconv.c_str()), nullptr,
                    &status);
  for (int c = 0; c < ncols; ++c)
    fits_write_col(f, TDOUBLE, c + 1, 1, 1, static_cast<long long>(spec.columns[c].size()),
                   const_cast<double*>(spec.columns[c].data()), &status);
  fits_close_file(f, &status);
  ASSERT_EQ(status, 0) << "test setup: CFITSIO status " << status;
}

using pisco_test::contains;
using pisco_test::error_of;

double max_abs_diff(std::span<const double> a, std::span<const double> b) {
  double d = a.size() == b.size() ? 0.0 : std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) d = std::max(d, std::abs(a[i] - b[i]));
  return d;
}

double max_abs(std::span<const double> a) {
  double m = 0.0;
  for (double v : a) m = std::max(m, std::abs(v));
  return m;
}

std::size_t file_count(const fs::path& dir) {
  return static_cast<std::size_t>(std::distance(fs::directory_iterator(dir), fs::directory_iterator()));
}

TEST(Sky, ConstructorChecksNside) {
  const Sky sky(4);
  EXPECT_EQ(sky.npix(), 192u);
  EXPECT_DOUBLE_EQ(sky.pixel_area() * 192, 4 * std::numbers::pi);
  EXPECT_EQ(sky.units(), "K_CMB");
  for (int bad : {0, -4, 12, 16384}) {
    const std::string msg = error_of([&] { Sky s(bad); });
    std::cout << "NSIDE " << bad << ": " << msg << "\n";
    EXPECT_TRUE(contains(msg, std::to_string(bad))) << msg;
  }
}

TEST(Sky, CheckFiniteNamesOriginMapAndPixel) {
  Sky sky(2);
  sky.Q()[17] = std::numeric_limits<double>::infinity();
  const std::string msg = error_of([&] { sky.check_finite("my-origin"); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, "my-origin") && contains(msg, "Stokes Q") && contains(msg, "pixel 17"))
      << msg;
}

TEST_F(SkyFits, RoundTripIsExact) {
  Sky sky(16, "uK_CMB");
  for (int k = 0; k < 4; ++k) {
    const auto m = random_map(16, 100 + k);
    std::copy(m.begin(), m.end(), sky.stokes(static_cast<pisco::StokesIndex>(k)).begin());
  }
  const fs::path file = dir_ / "sky.fits";
  sky.write_fits(file);
  const Sky back = Sky::read_fits(file);
  EXPECT_EQ(back.nside(), 16);
  EXPECT_EQ(back.units(), "uK_CMB");
  for (int k = 0; k < 4; ++k) {
    const auto s = static_cast<pisco::StokesIndex>(k);
    const double d = max_abs_diff(sky.stokes(s), back.stokes(s));
    std::cout << "Stokes " << "IQUV"[k] << ": max |written - read| = " << d << "\n";
    EXPECT_EQ(d, 0.0);
  }
}

TEST_F(SkyFits, WriteOverwritesAndLeavesNoTemporary) {
  const fs::path file = dir_ / "sky.fits";
  Sky a(8);
  a.I()[3] = 1.0;
  a.write_fits(file);
  Sky b(8);
  b.I()[3] = 2.0;
  b.write_fits(file);
  std::cout << "files in the directory after two writes: " << file_count(dir_) << "\n";
  EXPECT_EQ(file_count(dir_), 1u);
  EXPECT_EQ(Sky::read_fits(file).I()[3], 2.0);
}

TEST_F(SkyFits, NestedFileFromHealpixCxxIsConvertedToRing) {
  const int nside = 8;
  std::vector<Healpix_Map<double>> ring(3), nest(3);
  for (int k = 0; k < 3; ++k) {
    ring[k].SetNside(nside, RING);
    nest[k].SetNside(nside, NEST);
    const auto values = random_map(nside, 7 + k);
    for (int p = 0; p < ring[k].Npix(); ++p) {
      ring[k][p] = values[p];
      nest[k][ring[k].ring2nest(p)] = values[p];
    }
  }
  const fs::path file = dir_ / "nested.fits";
  {
    fitshandle out;
    out.create(file.string());
    write_Healpix_map_to_fits(out, nest[0], nest[1], nest[2], PLANCK_FLOAT64);
  }
  const Sky sky = Sky::read_fits(file);
  double worst = 0.0;
  for (int k = 0; k < 3; ++k) {
    const auto s = sky.stokes(static_cast<pisco::StokesIndex>(k));
    for (int p = 0; p < ring[k].Npix(); ++p) worst = std::max(worst, std::abs(s[p] - ring[k][p]));
  }
  std::cout << "NESTED file read back: max |read - RING map| = " << worst
            << ", max |V| = " << max_abs(sky.V()) << "\n";
  EXPECT_EQ(worst, 0.0);
  EXPECT_EQ(max_abs(sky.V()), 0.0);
}

TEST_F(SkyFits, IauFileHasUNegated) {
  const int nside = 4;
  TableSpec spec;
  spec.nside_key = nside;
  spec.polcconv = "IAU";
  spec.names = {"I_STOKES", "Q_STOKES", "U_STOKES"};
  for (int k = 0; k < 3; ++k) spec.columns.push_back(random_map(nside, 30 + k));
  const fs::path file = dir_ / "iau.fits";
  write_table(file, spec);

  std::ostringstream log;
  auto* old = std::clog.rdbuf(log.rdbuf());
  const Sky sky = Sky::read_fits(file);
  std::clog.rdbuf(old);
  double worst = 0.0;
  for (std::size_t p = 0; p < sky.npix(); ++p) worst = std::max(worst, std::abs(sky.U()[p] + spec.columns[2][p]));
  std::cout << "IAU file: max |U_read + U_file| = " << worst << "; log: " << log.str();
  EXPECT_EQ(worst, 0.0);
  EXPECT_EQ(max_abs_diff(sky.Q(), spec.columns[1]), 0.0);
  EXPECT_TRUE(contains(log.str(), "IAU")) << log.str();
}

TEST_F(SkyFits, OneAndThreeColumnFilesLeaveMissingMapsZero) {
  const int nside = 4;
  TableSpec one;
  one.nside_key = nside;
  one.names = {"TEMPERATURE"};
  one.columns = {random_map(nside, 1)};
  write_table(dir_ / "one.fits", one);
  const Sky a = Sky::read_fits(dir_ / "one.fits");
  std::cout << "1 column: max |I diff| = " << max_abs_diff(a.I(), one.columns[0])
            << ", max |Q|, |U|, |V| = " << max_abs(a.Q()) << ", " << max_abs(a.U()) << ", "
            << max_abs(a.V()) << ", units " << a.units() << "\n";
  EXPECT_EQ(max_abs_diff(a.I(), one.columns[0]), 0.0);
  EXPECT_EQ(max_abs(a.Q()) + max_abs(a.U()) + max_abs(a.V()), 0.0);
  EXPECT_EQ(a.units(), "K_CMB");

  TableSpec three = one;
  three.names = {"I", "Q", "U"};
  three.columns = {random_map(nside, 2), random_map(nside, 3), random_map(nside, 4)};
  three.unit1 = "uK";
  write_table(dir_ / "three.fits", three);
  const Sky b = Sky::read_fits(dir_ / "three.fits");
  std::cout << "3 columns: max |U diff| = " << max_abs_diff(b.U(), three.columns[2])
            << ", max |V| = " << max_abs(b.V()) << ", units " << b.units() << "\n";
  EXPECT_EQ(max_abs_diff(b.U(), three.columns[2]), 0.0);
  EXPECT_EQ(max_abs(b.V()), 0.0);
  EXPECT_EQ(b.units(), "uK");
}

// UNSEEN pixels: an error naming the column by default; kept with UnseenPolicy::flag, 0 with zero
// (tests/test_unseen.cpp has the rest).
TEST_F(SkyFits, UnseenPixelsAreAnErrorUnlessAPolicySaysOtherwise) {
  Sky sky(4);
  sky.I()[5] = -1.6375e30;
  sky.write_fits(dir_ / "unseen.fits");
  const std::string msg = error_of([&] { Sky::read_fits(dir_ / "unseen.fits"); });
  EXPECT_TRUE(contains(msg, "column 1 (I_STOKES) has 1 UNSEEN pixel") && contains(msg, "at pixel 5")) << msg;
  EXPECT_EQ(Sky::read_fits(dir_ / "unseen.fits", pisco::UnseenPolicy::flag).I()[5], -1.6375e30);
  EXPECT_EQ(Sky::read_fits(dir_ / "unseen.fits", pisco::UnseenPolicy::zero).I()[5], 0.0);
}

// A file cut short within its table is an error, even for readers that need only part of it.
TEST_F(SkyFits, TruncatedFile) {
  Sky(4).write_fits(dir_ / "whole.fits");
  const auto size = fs::file_size(dir_ / "whole.fits");
  fs::copy_file(dir_ / "whole.fits", dir_ / "cut.fits");
  fs::resize_file(dir_ / "cut.fits", size - 2880);
  const std::string msg = error_of([&] { Sky::read_fits(dir_ / "cut.fits"); });
  EXPECT_TRUE(contains(msg, "cut.fits: is truncated")) << msg;
}

TEST_F(SkyFits, MissingFile) {
  const fs::path file = dir_ / "absent.fits";
  const std::string msg = error_of([&] { Sky::read_fits(file); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, file.string()) && contains(msg, "no such file")) << msg;
}

TEST_F(SkyFits, TextFile) {
  const fs::path file = dir_ / "notes.fits";
  std::ofstream(file) << "this is not a FITS file\n";
  const std::string msg = error_of([&] { Sky::read_fits(file); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, file.string()) && contains(msg, "FITS")) << msg;
}

TEST_F(SkyFits, NsideNotPowerOfTwo) {
  TableSpec spec;
  spec.nside_key = 12;
  spec.names = {"I_STOKES"};
  spec.columns = {std::vector<double>(12 * 12 * 12, 1.0)};
  const fs::path file = dir_ / "nside12.fits";
  write_table(file, spec);
  const std::string msg = error_of([&] { Sky::read_fits(file); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, file.string()) && contains(msg, "NSIDE = 12") &&
              contains(msg, "power of two"))
      << msg;
}

TEST_F(SkyFits, MalformedTables) {
  TableSpec base;
  base.nside_key = 2;
  base.names = {"I_STOKES"};
  base.columns = {std::vector<double>(48, 1.0)};

  TableSpec no_nside = base;
  no_nside.nside_key = 0;
  TableSpec two_columns = base;
  two_columns.names = {"I", "Q"};
  two_columns.columns = {base.columns[0], base.columns[0]};
  TableSpec uneven = base;  // column 2 holds two values per row: 96 values against 48
  uneven.names = {"I", "Q", "U"};
  uneven.columns = {base.columns[0], std::vector<double>(96, 1.0), base.columns[0]};
  uneven.repeats = {1, 2, 1};
  TableSpec short_map = base;
  short_map.columns = {std::vector<double>(40, 1.0)};
  TableSpec bad_order = base;
  bad_order.ordering = "SPIRAL";

  const std::vector<std::pair<TableSpec, std::string>> cases = {
      {no_nside, "no NSIDE"},   {two_columns, "has 2 columns"},  {uneven, "different lengths"},
      {short_map, "needs 12"},  {bad_order, "ORDERING"}};
  int n = 0;
  for (const auto& [spec, expected] : cases) {
    const fs::path file = dir_ / ("bad" + std::to_string(n++) + ".fits");
    write_table(file, spec);
    const std::string msg = error_of([&] { Sky::read_fits(file); });
    std::cout << msg << "\n";
    EXPECT_TRUE(contains(msg, file.string()) && contains(msg, expected)) << msg;
  }
}

TEST_F(SkyFits, NanPixelIsReportedWithFileAndPixel) {
  Sky sky(4);
  sky.U()[123] = std::numeric_limits<double>::quiet_NaN();
  const fs::path file = dir_ / "nan.fits";
  // The library's writers refuse it (naming the column and the pixel); another tool's file holds it.
  const std::string refused = error_of([&] { sky.write_fits(file); });
  EXPECT_TRUE(contains(refused, "column U_STOKES: pixel 123 is nan")) << refused;
  EXPECT_EQ(file_count(dir_), 0u);
  pisco_test::write_unchecked_sky(sky, file);
  const std::string msg = error_of([&] { Sky::read_fits(file); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, file.string()) && contains(msg, "Stokes U") &&
              contains(msg, "pixel 123"))
      << msg;
}

TEST_F(SkyFits, UnwritableDestinationThrowsAndLeavesNothing) {
  // A regular file as the parent directory defeats even root.
  const fs::path blocker = dir_ / "blocker";
  std::ofstream(blocker) << "x";
  const fs::path file = blocker / "sky.fits";
  const std::string msg = error_of([&] { Sky(4).write_fits(file); });
  std::cout << msg << "\n";
  EXPECT_TRUE(contains(msg, file.string())) << msg;
  EXPECT_EQ(file_count(dir_), 1u);

  // A read-only directory (permissions do not bind root, so only checked for other users).
  const fs::path locked = dir_ / "locked";
  fs::create_directory(locked);
  fs::permissions(locked, fs::perms::owner_read | fs::perms::owner_exec);
  if (::geteuid() != 0) {
    const std::string msg2 = error_of([&] { Sky(4).write_fits(locked / "sky.fits"); });
    std::cout << msg2 << "\n";
    EXPECT_TRUE(contains(msg2, (locked / "sky.fits").string())) << msg2;
    EXPECT_EQ(file_count(locked), 0u);
  } else {
    std::cout << "read-only directory case not checked: running as root\n";
  }
}

}  // namespace
