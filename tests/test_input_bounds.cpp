// Inputs bounded by what they hold (docs/formats.md, "What is refused"): a small file that declares a
// huge grid, cut or harmonic table is refused before anything is allocated, naming the file, what it
// declares and the bytes it would take; inputs are read from regular files only (a FIFO named as any
// input is refused at once instead of blocking the reader forever); a b_lm file with any mmax up to
// lmax loads.
#include <fitsio.h>
#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <complex>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <random>

#include "beam_file_writers.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/simulation_config.hpp"
#include "pisco/sky.hpp"
#include "pisco/spectra.hpp"
#include "pisco/tod_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::deg;
using pisco::HarmonicBeam;
using pisco_test::contains;
using cd = std::complex<double>;

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const pisco::Error& e) {
    return e.what();
  }
  return "(no error)";
}

class InputBounds : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = pisco_test::fresh_test_dir("bounds"); }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path text(const std::string& name, const std::string& contents) {
    const fs::path f = dir_ / name;
    std::ofstream(f) << contents;
    return f;
  }
  fs::path dir_;
};

// A GRASP grid header of a few hundred bytes declaring 10000 x 10000 points (3.2 GB), with and without
// row limits, and a cut declaring ten million points: refused from the header, naming the sizes.
TEST_F(InputBounds, GraspHeadersDeclaringMoreThanTheFileHolds) {
  const std::string head = "a grid declaring more than it holds\nVERSION: 1\n++++\n1\n1 3 2 7\n0 0\n-1 -1 1 1\n";
  for (const std::string klimit : {"0", "1"}) {
    const fs::path f = text("big" + klimit + ".grd", head + "10000 10000 " + klimit + "\n0 0 0 0\n0 0 0 0\n");
    const std::string m = error_of([&] { pisco::GraspBeam::read(f); });
    EXPECT_TRUE(contains(m, f.string() + ": line 8: NX NY = 10000 x 10000 of field set 1 of 1 declares 1e+08 points "
                            "(3.2 GB in memory), but the ") &&
                contains(m, "expected a grid the file holds"))
        << m;
  }
  // A grid the file holds is read (here 3 x 2 points, without and with row limits).
  const fs::path small = text("small.grd", head + "3 2 0\n1 0 0 0\n1 0 0 0\n1 0 0 0\n1 0 0 0\n1 0 0 0\n1 0 0 0\n");
  EXPECT_EQ(pisco::GraspBeam::read(small).at(0).nx, 3);
  const fs::path limited = text("limited.grd", head + "3 2 1\n1 1\n1 0 0 0\n2 2\n1 0 0 0\n1 0 0 0\n");
  EXPECT_EQ(pisco::GraspBeam::read(limited).at(0).ny, 2);

  // Messages that once misled: a directory named as a GRASP file ("line 0: no ++++"), and a grid centre
  // that is not finite (blamed on the grid step).
  fs::create_directory(dir_ / "beam.grd");
  const std::string d = error_of([&] { pisco::GraspBeam::read(dir_ / "beam.grd"); });
  EXPECT_TRUE(contains(d, "beam.grd: is a directory (expected a TICRA GRASP .grd or .cut file)")) << d;
  const fs::path nan_centre = text("nan.grd", "a grid\nVERSION: 1\n++++\n1\n1 3 2 7\nnan 0\n-1 -1 1 1\n3 2 0\n");
  const std::string n = error_of([&] { pisco::GraspBeam::read(nan_centre); });
  EXPECT_TRUE(contains(n, "nan.grd: line 6: the centre \"IX IY\" of field set 1 must be finite grid offsets")) << n;

  const fs::path cut = text("big.cut", "a cut\n0 0.1 10000000 0 3 1 2\n1 0 0 0\n");
  const std::string m = error_of([&] { pisco::GraspBeam::read(cut); });
  EXPECT_TRUE(contains(m, cut.string() + ": line 2: V_NUM = 10000000 declares 320 MB of points, but the ") &&
              contains(m, "expected a cut the file holds"))
      << m;
}

// A b_lm file of a few rows whose MAX-LPOL and MAX-MPOL (or whose one row at l = m = 20000) make a
// dense table of 2e8 coefficients: refused before the table is allocated.
TEST_F(InputBounds, HarmonicFilesDeclaringHugeTables) {
  const HarmonicBeam g = pisco_test::gaussian_blm(10 * deg, 4);
  const fs::path declared = dir_ / "declared.fits";
  pisco_test::write_alm_fits(declared, {&g.t, &g.e, &g.b}, 4, 2);
  {
    fitsfile* f = nullptr;
    int status = 0;
    fits_open_file(&f, declared.c_str(), READWRITE, &status);
    for (int h = 2; h <= 4; ++h) {
      int type = 0;
      fits_movabs_hdu(f, h, &type, &status);
      long big = 20000;
      fits_update_key(f, TLONG, "MAX-LPOL", &big, nullptr, &status);
      fits_update_key(f, TLONG, "MAX-MPOL", &big, nullptr, &status);
    }
    fits_close_file(f, &status);
    ASSERT_EQ(status, 0);
  }
  std::string m = error_of([&] { HarmonicBeam::read_fits(declared); });
  EXPECT_TRUE(contains(m, declared.string() + ": lmax = 20000, mmax = 20000 (MAX-LPOL and MAX-MPOL) make 2e+08 "
                                              "coefficients a component (9.6 GB), but its tables hold 12 rows")) << m;

  // One row at l = m = 20000, no keys.
  const fs::path sparse = dir_ / "sparse.fits";
  {
    fitsfile* f = nullptr;
    int status = 0;
    fits_create_file(&f, sparse.c_str(), &status);
    const char* names[] = {"INDEX", "REAL", "IMAG"};
    const char* forms[] = {"1J", "1D", "1D"};
    fits_create_tbl(f, BINARY_TBL, 0, 3, const_cast<char**>(names), const_cast<char**>(forms), nullptr, "ALM", &status);
    int index[2] = {1, 20000 * 20000 + 20000 + 20000 + 1};
    double re[2] = {0.3, 1e-3}, im[2] = {0, 0};
    fits_write_col(f, TINT, 1, 1, 1, 2, index, &status);
    fits_write_col(f, TDOUBLE, 2, 1, 1, 2, re, &status);
    fits_write_col(f, TDOUBLE, 3, 1, 1, 2, im, &status);
    fits_close_file(f, &status);
    ASSERT_EQ(status, 0);
  }
  m = error_of([&] { HarmonicBeam::read_fits(sparse); });
  EXPECT_TRUE(contains(m, "lmax = 20000, mmax = 20000 (the largest l and m of its rows) make 2e+08 coefficients a "
                          "component (3.2 GB), but its tables hold 2 rows")) << m;
}

// Any mmax up to lmax loads from a file and makes a beamsor (once "B_TT is nan" above about 1024).
TEST_F(InputBounds, HarmonicFilesWithMmaxUpToLmaxLoad) {
  const int lmax = 1100;
  HarmonicBeam b;
  b.lmax = b.mmax = lmax;
  const std::size_t n = HarmonicBeam::size(lmax, lmax);
  b.t.assign(n, cd{});
  b.e.assign(n, cd{});
  b.b.assign(n, cd{});
  std::mt19937 g(5);
  std::normal_distribution<double> normal;
  const double s = 0.5 * deg / std::sqrt(8 * std::log(2.0));
  for (int m = 0; m <= lmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const double w = std::exp(-0.5 * l * (l + 1) * s * s) * std::sqrt((2 * l + 1) / (4 * M_PI));
      const std::size_t k = HarmonicBeam::index(lmax, l, m);
      b.t[k] = m == 0 ? cd(w, 0) : 1e-3 * w * cd(normal(g), normal(g));
      if (l >= 2) b.e[k] = 1e-3 * w * cd(normal(g), m ? normal(g) : 0.0);
    }
  const fs::path file = dir_ / "full.fits";
  pisco_test::write_alm_fits(file, {&b.t, &b.e, &b.b}, lmax, lmax);
  const HarmonicBeam read = HarmonicBeam::read_fits(file);
  EXPECT_EQ(read.mmax, lmax);
  pisco::FileBeamOptions o;
  o.rho_max = 0.8 * deg;
  o.grid_step = 0.2 * deg;
  const pisco::Beamsor bs = pisco::Beamsor::from_harmonic(read, o);
  EXPECT_TRUE(std::isfinite(bs.omega_tilde()) && bs.omega_tilde() > 0) << bs.omega_tilde();
  // The centre node against the synthesis at rho = 0: only m = 0 counts there.
  const auto centre = read.stokes_at(0.0, 0.0);
  EXPECT_NEAR(bs.at(0.0, 0.0)[0][0], centre[0], 1e-9 * std::abs(centre[0]));
}

// A C_l table whose multipole is a finite 2e67: beyond every lmax, skipped, never converted out of range
// (float-to-integer overflow under the sanitizers before).
TEST_F(InputBounds, ClTableMultipolesBeyondAnyRange) {
  const fs::path f = text("cl.txt", "20000000000000000000000000000000000000000000000000000000000000000000 1 1 1 1\n"
                                    "2 6.283185307179586 0 0 0\n");
  const pisco::Spectra s = pisco::read_cl_table(f, 10, false);
  EXPECT_NEAR(s.TT[2], 6.283185307179586 * 2 * M_PI / 6, 1e-12);  // C_l = 2 pi D_l / l (l + 1)
}

// An HDF5 dataset declaring 4e11 elements in a file of a few kilobytes (chunked, nothing written):
// refused when opened, before any reader allocates for it.
TEST_F(InputBounds, HdfDatasetsDeclaringMoreThanTheFileHolds) {
  const fs::path f = dir_ / "huge.h5";
  {
    const hid_t file = H5Fcreate(f.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hsize_t dims[2] = {100000000000ull, 4}, chunk[2] = {1024, 4};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t plist = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(plist, 2, chunk);
    const hid_t ds = H5Dcreate2(file, "boresight", H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, plist, H5P_DEFAULT);
    ASSERT_GE(ds, 0);
    H5Dclose(ds);
    H5Pclose(plist);
    H5Sclose(space);
    H5Fclose(file);
  }
  const std::string m = error_of([&] { pisco::BoresightFile b(f); });
  EXPECT_TRUE(contains(m, "huge.h5: dataset '/boresight' declares 4e+11 elements (3.2 TB), more than 64 times the file's"))
      << m;
}

// FITS headers are checked card by card before CFITSIO parses them: an unquoted value that overran
// CFITSIO's buffers (an abort inside the library) and a byte that is not ASCII are refused, naming the
// HDU, the card and the keyword.
TEST_F(InputBounds, FitsHeaderCardsOutsideTheStandardAreRefused) {
  pisco::Sky sky(4);
  const fs::path good = dir_ / "sky.fits";
  sky.write_fits(good);
  std::string bytes;
  {
    std::ifstream in(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const auto patched = [&](const std::string& name, const std::string& key, const std::string& value) {
    std::string b = bytes;
    const std::size_t at = b.find(key);
    EXPECT_NE(at, std::string::npos) << key;
    b.replace(at + 10, 70, (value + std::string(70, ' ')).substr(0, 70));
    const fs::path f = dir_ / name;
    std::ofstream(f, std::ios::binary) << b;
    return f;
  };
  std::string m = error_of([&] { pisco::Sky::read_fits(patched("word.fits", "TTYPE1  = ", std::string(60, 's'))); });
  EXPECT_TRUE(contains(m, "word.fits: HDU 2, header card ") && contains(m, "(TTYPE1): the value 'ssssssssssss") &&
              contains(m, "is neither a quoted string, a number, T nor F"))
      << m;
  m = error_of([&] { pisco::Sky::read_fits(patched("open.fits", "TTYPE1  = ", "'I_STOKES")); });
  EXPECT_TRUE(contains(m, "(TTYPE1): the value ''I_STOKES' is neither")) << m;
  m = error_of([&] { pisco::Sky::read_fits(patched("byte.fits", "TTYPE1  = ", "'I\x01'")); });
  EXPECT_TRUE(contains(m, "holds a byte that is not printable ASCII")) << m;
  // Values of every kind the standard allows read as before.
  EXPECT_EQ(pisco::Sky::read_fits(patched("ok.fits", "TTYPE1  = ", "'I''S'  / a comment")).nside(), 4);
}

// Files on which the HDF5 library itself crashes, loops or asks for gigabytes (found by fuzzing,
// tests/fuzz/regressions): read first in a child process, each is one pisco::Error naming the file;
// the test process survives every one.
TEST_F(InputBounds, CorruptHdfFilesThatCrashTheLibraryAreOneError) {
  const fs::path regressions = fs::path(PISCO_TEST_ASSETS_DIR).parent_path() / "tests" / "fuzz" / "regressions";
  ::setenv("PISCO_HDF5_PROBE_SECONDS", "5", 1);
  int files = 0;
  for (const char* target : {"fuzz_focal_plane_hdf5", "fuzz_pointing_hdf5"})
    for (const auto& e : fs::directory_iterator(regressions / target)) {
      const fs::path f = dir_ / e.path().filename();
      fs::copy_file(e.path(), f);
      const std::string m = error_of([&] {
        if (std::string(target) == "fuzz_focal_plane_hdf5") {
          pisco::read_toast_focal_plane(f);
        } else {
          pisco::BoresightFile b(f);
          std::vector<double> hwp;
          if (b.has_hwp_angle()) b.read_hwp_angle(0, std::min<std::size_t>(b.size(), 16), hwp);
        }
      });
      std::cout << f.filename().string() << ": " << m << "\n";
      EXPECT_TRUE(contains(m, f.string() + ": ")) << m;
      ++files;
    }
  ::unsetenv("PISCO_HDF5_PROBE_SECONDS");
  EXPECT_GE(files, 10);
}

// A FIFO named as any input: refused at once, naming it, instead of a reader blocked forever.
TEST_F(InputBounds, FifosAreRefusedByEveryReader) {
  const fs::path fifo = dir_ / "input.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::vector<std::pair<std::string, std::function<void()>>> readers = {
      {"GRASP", [&] { pisco::GraspBeam::read(fifo.string() + ".grd"); }},
      {"b_lm", [&] { HarmonicBeam::read_fits(fifo); }},
      {"beamsor", [&] { pisco::Beamsor::read_healpix_fits(fifo, 2 * deg); }},
      {"sky", [&] { pisco::Sky::read_fits(fifo); }},
      {"simulation file", [&] { pisco::read_simulation_file(fifo); }},
      {"focal plane", [&] { pisco::read_focal_plane_file(fifo, {"main"}); }},
      {"TOAST focal plane", [&] { pisco::read_toast_focal_plane(fifo); }},
      {"pointing", [&] { pisco::BoresightFile f(fifo); }},
      {"C_l table", [&] { pisco::read_cl_table(fifo, 10, false); }},
  };
  fs::create_symlink(fifo, fifo.string() + ".grd");  // GRASP wants its extension: a link to the FIFO
  for (const auto& [name, read] : readers) {
    // Run where a blocked reader cannot hang the test: a FIFO opened for reading waits for a writer.
    auto done = std::async(std::launch::async, [&] { return error_of(read); });
    if (done.wait_for(std::chrono::seconds(20)) != std::future_status::ready) {
      std::ofstream(fifo) << "unblock";  // a writer, so that the reader returns
      ADD_FAILURE() << name << ": blocked on the FIFO";
      done.wait();
      continue;
    }
    const std::string m = done.get();
    EXPECT_TRUE(contains(m, ": is a FIFO; inputs are read from regular files only (expected ")) << name << ": " << m;
  }
}

}  // namespace
