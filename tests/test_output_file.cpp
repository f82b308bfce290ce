// Output files written whole or not at all (include/pisco/output_file.hpp; docs/formats.md, "Errors and
// partial files"): every writer of the library on a full disk (PISCO_TEST_FAULT=write-fail:NAME makes the
// writer of NAME find /dev/full under its file) gives one error naming the file and the reason and leaves
// no temporary file; temporary files in progress are listed and can be removed at once.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "pisco/output_file.hpp"
#include "pisco/pisco.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/tod_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco_test::contains;
using pisco_test::error_of;

class OutputFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("output");
  }
  void TearDown() override {
    ::unsetenv("PISCO_TEST_FAULT");
    fs::remove_all(dir_);
  }
  // Nothing but `expected` in the directory.
  void expect_only(const std::vector<std::string>& expected) {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    EXPECT_EQ(names, expected);
  }
  fs::path dir_;
};

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST_F(OutputFile, TextFilesAreWrittenWholeOrNotAtAll) {
  pisco::write_file_atomically(dir_ / "a.txt", "first\n");
  pisco::write_file_atomically(dir_ / "a.txt", "second\n");
  EXPECT_EQ(read(dir_ / "a.txt"), "second\n");
  ::setenv("PISCO_TEST_FAULT", "write-fail:a.txt", 1);
  const std::string e = error_of([&] { pisco::write_file_atomically(dir_ / "a.txt", std::string(100000, 'x')); });
  EXPECT_TRUE(contains(e, (dir_ / "a.txt").string() + ": cannot write 100000 bytes (No space left on device)")) << e;
  EXPECT_EQ(read(dir_ / "a.txt"), "second\n") << "the previous file stays";
  expect_only({"a.txt"});
  ::unsetenv("PISCO_TEST_FAULT");
  const std::string m = error_of([&] { pisco::write_file_atomically(dir_ / "missing" / "b.txt", "x"); });
  EXPECT_TRUE(contains(m, "b.txt: cannot create the temporary file")) << m;
}

// Each writer on a full disk: one error naming the file and the system's reason, no temporary file.
TEST_F(OutputFile, EveryWriterOnAFullDisk) {
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  ::setenv("PISCO_TEST_FAULT", "write-fail:tod.h5", 1);
  std::string e = error_of([&] {
    pisco::TodWriter w(dir_ / "tod.h5", fp, 50000, pisco::TodPrecision::float64, true, {{"units", "K"}});
    const std::vector<double> s(50000, 1.0);
    pisco::Pointing p;
    for (int i = 0; i < 50000; ++i) p.push_back(1.0, 0.0, 0.0);
    const pisco::PointingView v = p.view();
    w.write(0, 0, s, &v);
    w.write(1, 0, s, &v);
    w.commit();
  });
  std::cout << e << "\n";
  EXPECT_TRUE(contains(e, "tod.h5: cannot write samples 0..49999 of dataset '/pa/signal'")) << e;
  EXPECT_TRUE(contains(e, "No space left on device")) << e;
  EXPECT_FALSE(contains(e, "\n")) << "one line";
  ::setenv("PISCO_TEST_FAULT", "write-fail:maps.fits", 1);
  e = error_of([&] { pisco::Sky(16).write_fits(dir_ / "maps.fits"); });
  std::cout << e << "\n";
  EXPECT_TRUE(contains(e, "maps.fits:") && contains(e, "No space left on device")) << e;
  ::setenv("PISCO_TEST_FAULT", "write-fail:bore.h5", 1);
  e = error_of([&] { pisco::BoresightFile::write(dir_ / "bore.h5", std::vector<pisco::Quat>(20000, pisco::Quat{0, 0, 0, 1})); });
  std::cout << e << "\n";
  EXPECT_TRUE(contains(e, "bore.h5: cannot write '/boresight'") && contains(e, "No space left on device")) << e;
  ::setenv("PISCO_TEST_FAULT", "write-fail:beam.fits", 1);
  pisco::BeamOptions o;
  o.rho_max = 5 * pisco::deg;
  e = error_of([&] { pisco::Beamsor::gaussian(1.5 * pisco::deg, o).write_healpix_fits(dir_ / "beam.fits", 64); });
  EXPECT_TRUE(contains(e, "beam.fits:") && contains(e, "No space left on device")) << e;
  expect_only({});
  ::unsetenv("PISCO_TEST_FAULT");
  EXPECT_TRUE(pisco::temporary_files().empty());
}

// Temporary files in progress are listed, and removed at once by remove_temporary_files(): what a
// program stopped by a signal does. The writer then fails cleanly.
TEST_F(OutputFile, TemporaryFilesAreListedAndRemoved) {
  pisco::FocalPlane fp;
  fp.add({"d", 0, 0, 1, 0});
  {
    pisco::TodWriter w(dir_ / "tod.h5", fp, 10, pisco::TodPrecision::float64, false, {});
    const auto listed = pisco::temporary_files();
    ASSERT_EQ(listed.size(), 1u);
    EXPECT_EQ(listed[0], w.temporary_path());
    EXPECT_EQ(pisco::remove_temporary_files(), 1u);
    EXPECT_FALSE(fs::exists(w.temporary_path()));
    w.write(0, 0, std::vector<double>(10, 0.0));
    const std::string e = error_of([&] { w.commit(); });
    EXPECT_TRUE(contains(e, "cannot rename the temporary file")) << e;
  }
  EXPECT_TRUE(pisco::temporary_files().empty());
  expect_only({});
}

TEST_F(OutputFile, BoresightFilesKeepPlateAngles) {
  const std::vector<pisco::Quat> q(5, pisco::Quat{0, 0, 0, 1});
  const std::vector<double> hwp{0.0, 0.1, 0.2, 0.3, 0.4};
  pisco::BoresightFile::write(dir_ / "bore.h5", q, {}, hwp);
  const pisco::BoresightFile f(dir_ / "bore.h5");
  ASSERT_TRUE(f.has_hwp_angle());
  std::vector<double> back;
  f.read_hwp_angle(0, 5, back);
  EXPECT_EQ(back, hwp);
}

}  // namespace
