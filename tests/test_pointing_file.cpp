// Pointing files of boresight quaternions (include/pisco/pointing_file.hpp): written and read back
// exactly, in chunks; every malformed file an error naming the file and what was expected, every bad
// sample an error naming the sample.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "pisco/output_file.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/quaternion.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco_test::expect_error;

class PointingFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("ptgfile");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A file with one float64 dataset `name` of shape `dims`.
  fs::path raw(const std::string& file, const char* name, std::vector<hsize_t> dims, const std::vector<double>& v) {
    const fs::path path = dir_ / file;
    const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hid_t space = H5Screate_simple(int(dims.size()), dims.data(), nullptr);
    const hid_t ds = H5Dcreate2(f, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
    H5Dclose(ds);
    H5Sclose(space);
    H5Fclose(f);
    return path;
  }

  fs::path dir_;
};

std::vector<pisco::Quat> some_quats(std::size_t n) {
  std::vector<pisco::Quat> q;
  for (std::size_t i = 0; i < n; ++i) q.push_back(pisco::quat_from_pointing(0.1 + 0.002 * double(i), 0.01 * double(i), 0.3));
  return q;
}

TEST_F(PointingFile, WrittenAndReadBackInChunks) {
  const std::vector<pisco::Quat> q = some_quats(1000);
  std::vector<double> times(q.size());
  for (std::size_t i = 0; i < times.size(); ++i) times[i] = 0.05 * double(i);
  const fs::path file = dir_ / "bore.h5";
  pisco::BoresightFile::write(file, q, times);
  EXPECT_FALSE(fs::exists(file.string() + pisco::temporary_suffix()));
  ASSERT_TRUE(pisco::BoresightFile::holds_boresight(file));
  const pisco::BoresightFile f(file);
  ASSERT_EQ(f.size(), q.size());
  std::vector<pisco::Quat> chunk;
  for (std::size_t first = 0; first < q.size(); first += 333) {
    const std::size_t n = std::min<std::size_t>(333, q.size() - first);
    f.read(first, n, chunk);
    ASSERT_EQ(chunk.size(), n);
    for (std::size_t i = 0; i < n; ++i) {
      EXPECT_EQ(chunk[i].x, q[first + i].x);
      EXPECT_EQ(chunk[i].w, q[first + i].w);
    }
  }
  expect_error([&] { f.read(900, 200, chunk); }, "has 1000");
}

TEST_F(PointingFile, MalformedFilesAreNamed) {
  expect_error([&] { pisco::BoresightFile(dir_ / "missing.h5"); }, "missing.h5");
  { std::ofstream(dir_ / "text.h5") << "not hdf5"; }
  expect_error([&] { pisco::BoresightFile(dir_ / "text.h5"); }, "text.h5");
  const fs::path three = raw("three.h5", "boresight", {10, 3}, std::vector<double>(30, 0.5));
  expect_error([&] { pisco::BoresightFile{three}; }, "shape (10, 3)");
  const fs::path other = raw("other.h5", "pointing", {10, 4}, std::vector<double>(40, 0.5));
  EXPECT_FALSE(pisco::BoresightFile::holds_boresight(other));
  expect_error([&] { pisco::BoresightFile{other}; }, "no dataset '/boresight'");
  // times of another length than the quaternions
  const std::vector<pisco::Quat> q = some_quats(10);
  const fs::path file = dir_ / "times.h5";
  pisco::BoresightFile::write(file, q, {});
  {
    const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hsize_t dims[1] = {7};
    const hid_t space = H5Screate_simple(1, dims, nullptr);
    const hid_t ds = H5Dcreate2(f, "times", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dclose(ds);
    H5Sclose(space);
    H5Fclose(f);
  }
  expect_error([&] { pisco::BoresightFile{file}; }, "'/times' has 7 samples but '/boresight' has 10");
  expect_error([&] { pisco::BoresightFile::write(dir_ / "x.h5", q, {1.0, 2.0}); }, "2 times for 10 quaternions");
}

// The plate's angles, one per quaternion: a dataset '/hwp_angle' of another length or shape is an error
// naming the file and both lengths when the file is opened; a non-finite angle names its sample; write()
// refuses angles of another length and leaves no file behind.
TEST_F(PointingFile, HwpAngleOfAnotherLengthIsNamed) {
  const std::vector<pisco::Quat> q = some_quats(10);
  std::vector<double> angles(q.size());
  for (std::size_t i = 0; i < angles.size(); ++i) angles[i] = 0.25 * double(i);
  const fs::path good = dir_ / "good.h5";
  pisco::BoresightFile::write(good, q, {}, angles);
  {
    const pisco::BoresightFile f(good);
    ASSERT_TRUE(f.has_hwp_angle());
    std::vector<double> h;
    f.read_hwp_angle(2, 5, h);
    ASSERT_EQ(h.size(), 5u);
    EXPECT_EQ(h[0], angles[2]);
    EXPECT_EQ(h[4], angles[6]);
    expect_error([&] { f.read_hwp_angle(8, 5, h); }, "'/hwp_angle' has 10");
  }

  // A boresight of 10 quaternions with `name`'s 'hwp_angle' of shape `dims`.
  auto with_hwp = [&](const std::string& name, std::vector<hsize_t> dims, double value) {
    const fs::path file = dir_ / name;
    pisco::BoresightFile::write(file, q);
    const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t space = H5Screate_simple(int(dims.size()), dims.data(), nullptr);
    const hid_t ds = H5Dcreate2(f, "hwp_angle", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    hsize_t n = 1;
    for (hsize_t d : dims) n *= d;
    const std::vector<double> v(n, value);
    H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
    H5Dclose(ds);
    H5Sclose(space);
    H5Fclose(f);
    return file;
  };
  const fs::path shorter = with_hwp("short.h5", {7}, 0.5);
  const std::string message = pisco_test::error_of([&] { pisco::BoresightFile{shorter}; });
  EXPECT_NE(message.find(shorter.string()), std::string::npos) << message;
  EXPECT_NE(message.find("'/hwp_angle' has 7 samples but '/boresight' has 10"), std::string::npos) << message;
  expect_error([&] { pisco::BoresightFile{with_hwp("long.h5", {13}, 0.5)}; },
               "'/hwp_angle' has 13 samples but '/boresight' has 10");
  expect_error([&] { pisco::BoresightFile{with_hwp("empty.h5", {0}, 0.5)}; },
               "'/hwp_angle' has 0 samples but '/boresight' has 10");
  expect_error([&] { pisco::BoresightFile{with_hwp("table.h5", {10, 2}, 0.5)}; }, "hwp_angle");

  angles[6] = NAN;
  const fs::path nan = dir_ / "nan.h5";
  pisco::BoresightFile::write(nan, q, {}, angles);
  const pisco::BoresightFile f(nan);
  std::vector<double> h;
  f.read_hwp_angle(0, 6, h);  // the good part reads
  expect_error([&] { f.read_hwp_angle(4, 4, h); }, "'/hwp_angle' sample 6 is not finite");

  const fs::path refused = dir_ / "refused.h5";
  expect_error([&] { pisco::BoresightFile::write(refused, q, {}, {0.1, 0.2, 0.3}); },
               "3 plate angles for 10 quaternions");
  EXPECT_FALSE(fs::exists(refused));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 6);  // nothing half-written
}

TEST_F(PointingFile, BadSamplesAreNamed) {
  std::vector<pisco::Quat> q = some_quats(50);
  q[17] = {0, 0, 0.5, 0.5};  // norm 0.707
  q[31].y = NAN;
  q[40] = {1e200, 0, 0, 1e200};  // finite: named by its norm, not as non-finite
  const fs::path file = dir_ / "bad.h5";
  pisco::BoresightFile::write(file, q);
  const pisco::BoresightFile f(file);
  std::vector<pisco::Quat> chunk;
  f.read(0, 17, chunk);  // the good part reads
  expect_error([&] { f.read(10, 20, chunk); }, "sample 17 has norm 0.7071");
  expect_error([&] { f.read(20, 20, chunk); }, "sample 31 has a non-finite component");
  expect_error([&] { f.read(35, 10, chunk); }, "sample 40 has norm 1.41421356237309");
}

}  // namespace
