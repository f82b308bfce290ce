// TOD and pointing files in HDF5: streaming writes in uneven chunks (float64 and float32), attributes,
// pointing datasets, commit by rename, no output when a writer is abandoned, and every error of a pointing
// input file naming the file, group, dataset or sample.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "support.hpp"
#include "pisco/output_file.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/tod_file.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::FocalPlane;
using pisco::Pointing;
using pisco::TodPrecision;
using pisco::TodWriter;
using pisco_test::contains;
using pisco_test::error_of;

// Like pisco_test::expect_error, printing the message so that the log shows what a user would see.
void expect_error(const std::function<void()>& f, const std::string& needle) {
  const std::string message = error_of(f);
  std::cout << "    error: " << message << "\n";
  EXPECT_TRUE(contains(message, needle)) << "expected a pisco::Error mentioning '" << needle << "', got: " << message;
}

// A fresh directory per test, removed afterwards.
class TodFile : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("pisco-tod-file-" + std::to_string(::getpid()) + "-" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    // Every HDF5 identifier the library opened has been closed again.
    EXPECT_EQ(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL), 0) << "HDF5 objects left open";
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // Files in the test directory other than the given ones (temporaries left behind, for instance).
  std::vector<std::string> files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir_)) out.push_back(e.path().filename().string());
    return out;
  }
  fs::path dir_;
};

FocalPlane two_detectors() {
  FocalPlane fp;
  // Names out of alphabetical order: readers must keep focal-plane order.
  fp.add({"z_det", 0.25, 0.01, 1.1, 1});
  fp.add({"a_det", 0.25 - std::numbers::pi / 2, 0.02, 0.9, 0});
  return fp;
}

std::vector<double> random_signal(std::size_t n, unsigned seed, double offset = 2.725) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1e-4);
  std::vector<double> v(n);
  for (double& x : v) x = offset + normal(rng);  // a K-level monopole plus uK-level anisotropies
  return v;
}

Pointing random_pointing(std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Pointing p;
  for (std::size_t i = 0; i < n; ++i)
    p.push_back(std::acos(1.0 - 2.0 * u(rng)), 2.0 * std::numbers::pi * u(rng), std::numbers::pi * (2.0 * u(rng) - 1.0));
  return p;
}

// Uneven chunk boundaries covering [0, n): 0, 1, 8, 8 (an empty chunk), 307, 700, 1313, ..., n.
std::vector<std::size_t> uneven_bounds(std::size_t n) {
  std::vector<std::size_t> b;
  for (std::size_t x : {0, 1, 8, 8, 307})
    if (x < n) b.push_back(x);
  for (std::size_t x = 700; x < n; x += 613) b.push_back(x);
  b.push_back(n);
  return b;
}

// Writes a whole TOD of two detectors, interleaving the detectors and writing the chunks of the second
// detector in reverse order.
void write_tod(const fs::path& file, TodPrecision precision, const std::vector<std::vector<double>>& signal,
               const std::vector<Pointing>* pointing, const std::map<std::string, std::string>& attributes) {
  const std::size_t n = signal[0].size();
  TodWriter writer(file, two_detectors(), n, precision, pointing != nullptr, attributes);
  const auto b = uneven_bounds(n);
  for (std::size_t c = 0; c + 1 < b.size(); ++c) {
    for (std::size_t d = 0; d < 2; ++d) {
      const std::size_t k = d == 0 ? c : b.size() - 2 - c;
      const std::size_t offset = b[k], count = b[k + 1] - b[k];
      const std::span<const double> chunk(signal[d].data() + offset, count);
      if (pointing) {
        const pisco::PointingView view = (*pointing)[d].view().subspan(offset, count);
        writer.write(d, offset, chunk, &view);
      } else {
        writer.write(d, offset, chunk);
      }
    }
  }
  writer.commit();
}

// A pointing file written with the HDF5 C API, as another tool (h5py, say) would: no link creation
// order, datasets of the given type.
struct PointingGroup {
  std::string name;
  std::vector<double> theta, phi, psi;
};

void write_dataset(hid_t group, const char* name, const std::vector<double>& v, hid_t file_type) {
  const hsize_t dims[1] = {v.size()};
  const hid_t space = H5Screate_simple(1, dims, nullptr);
  const hid_t ds = H5Dcreate2(group, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (ds < 0) throw std::runtime_error("test helper: cannot create dataset");
  if (!v.empty()) H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
  H5Dclose(ds);
  H5Sclose(space);
}

void write_pointing_file(const fs::path& file, const std::vector<PointingGroup>& groups,
                         hid_t file_type = H5T_IEEE_F64LE) {
  const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  if (f < 0) throw std::runtime_error("test helper: cannot create " + file.string());
  for (const PointingGroup& g : groups) {
    const hid_t group = H5Gcreate2(f, g.name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    write_dataset(group, "theta", g.theta, file_type);
    write_dataset(group, "phi", g.phi, file_type);
    if (!g.psi.empty() || g.theta.empty()) write_dataset(group, "psi", g.psi, file_type);  // empty psi: none
    H5Gclose(group);
  }
  H5Fclose(f);
}

PointingGroup group_of(const std::string& name, const Pointing& p) { return {name, p.theta, p.phi, p.psi}; }

TEST_F(TodFile, StreamingFloat64ReadsBackExactly) {
  std::cout << "checking: 2 detectors x 40000 samples (several HDF5 chunks) written float64 in uneven, "
               "interleaved chunks read back bit for bit, in focal-plane order with zeta, epsilon, gain, beam\n";
  const std::size_t n = 40000;
  const std::vector<std::vector<double>> signal = {random_signal(n, 1), random_signal(n, 2, -1e-3)};
  const fs::path file = dir_ / "tod.h5";
  write_tod(file, TodPrecision::float64, signal, nullptr, {{"units", "K_CMB"}});

  EXPECT_EQ(pisco::read_tod_signal(file, "z_det"), signal[0]);
  EXPECT_EQ(pisco::read_tod_signal(file, "a_det"), signal[1]);
  const auto detectors = pisco::read_tod_detectors(file);
  ASSERT_EQ(detectors.size(), 2u);
  const FocalPlane fp = two_detectors();
  for (std::size_t d = 0; d < 2; ++d) {
    EXPECT_EQ(detectors[d].name, fp[d].name);
    EXPECT_EQ(detectors[d].zeta, fp[d].zeta);
    EXPECT_EQ(detectors[d].epsilon, fp[d].epsilon);
    EXPECT_EQ(detectors[d].gain, fp[d].gain);
    EXPECT_EQ(detectors[d].beam, fp[d].beam);
  }
  EXPECT_EQ(pisco::pointing_detectors(file), (std::vector<std::string>{"z_det", "a_det"}));
}

TEST_F(TodFile, SharedFileCreatedByOneAndWrittenByItsOpenersReadsBackAsOne) {
  std::cout << "checking: a shared file (create_shared, then open_shared by two writers, as the ranks of an MPI "
               "run) written in halves reads back as the file of one writer; commit() renames it once, and a "
               "shared writer destroyed without commit() removes the temporary file\n";
  const std::size_t n = 40000;
  const std::vector<std::vector<double>> signal = {random_signal(n, 1), random_signal(n, 2, -1e-3)};
  const std::vector<Pointing> pointing = {random_pointing(n, 3), random_pointing(n, 4)};
  const fs::path file = dir_ / "tod.h5";
  const FocalPlane fp = two_detectors();
  TodWriter::create_shared(file, fp, n, TodPrecision::float64, true, {{"units", "K_CMB"}}, false, ".tmp-shared");
  EXPECT_TRUE(fs::exists(dir_ / "tod.h5.tmp-shared"));
  int barriers = 0;
  for (int leader : {0, 1}) {  // the second writer, then the leader (HDF5 opens a file once per process)
    pisco::SharedTodOptions o;
    o.temporary_suffix = ".tmp-shared";
    o.leader = leader == 1;
    o.barrier = [&] { ++barriers; };
    TodWriter w = TodWriter::open_shared(file, fp, n, TodPrecision::float64, true, false, o);
    const std::size_t first = leader == 1 ? 0 : n / 2, count = leader == 1 ? n / 2 : n - n / 2;
    for (std::size_t d = 0; d < 2; ++d) {
      const pisco::PointingView view = pointing[d].view().subspan(first, count);
      w.write(d, first, std::span<const double>(signal[d].data() + first, count), &view);
    }
    w.commit();
    EXPECT_EQ(fs::exists(file), leader == 1);
  }
  EXPECT_EQ(barriers, 2);
  EXPECT_EQ(files(), std::vector<std::string>{"tod.h5"});
  EXPECT_EQ(pisco::read_tod_signal(file, "z_det"), signal[0]);
  EXPECT_EQ(pisco::read_tod_signal(file, "a_det"), signal[1]);
  EXPECT_EQ(pisco::read_tod_attributes(file).at("units"), "K_CMB");
  EXPECT_EQ(pisco::read_pointing_hdf5(file, "a_det").theta, pointing[1].theta);
  fs::remove(file);

  // Abandoned: no file left.
  TodWriter::create_shared(file, fp, n, TodPrecision::float32, false, {}, true, ".tmp-shared");
  {
    pisco::SharedTodOptions o;
    o.temporary_suffix = ".tmp-shared";
    o.leader = true;
    TodWriter w = TodWriter::open_shared(file, fp, n, TodPrecision::float32, false, true, o);
    w.write(0, 0, std::span<const double>(signal[0].data(), 100));
  }
  EXPECT_TRUE(files().empty());
}

TEST_F(TodFile, StreamingFloat32ReadsBackWithinFloatRounding) {
  std::cout << "checking: a float32 TOD stores the nearest float of every sample (relative error <= 2^-24)\n";
  const std::size_t n = 3001;
  const std::vector<std::vector<double>> signal = {random_signal(n, 3), random_signal(n, 4, 0.0)};
  const fs::path file = dir_ / "tod32.h5";
  write_tod(file, TodPrecision::float32, signal, nullptr, {});
  for (std::size_t d = 0; d < 2; ++d) {
    const auto back = pisco::read_tod_signal(file, d == 0 ? "z_det" : "a_det");
    ASSERT_EQ(back.size(), n);
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(back[i], static_cast<double>(static_cast<float>(signal[d][i]))) << "sample " << i;
      ASSERT_LE(std::abs(back[i] - signal[d][i]), std::abs(signal[d][i]) * std::ldexp(1.0, -24));
    }
  }
  // The dataset really is float32 on disk.
  const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  const hid_t ds = H5Dopen2(f, "/a_det/signal", H5P_DEFAULT);
  const hid_t type = H5Dget_type(ds);
  EXPECT_EQ(H5Tget_class(type), H5T_FLOAT);
  EXPECT_EQ(H5Tget_size(type), 4u);
  H5Tclose(type);
  H5Dclose(ds);
  H5Fclose(f);
}

TEST_F(TodFile, AttributesRoundTrip) {
  std::cout << "checking: every caller attribute comes back as a string, plus pisco_format = pisco-tod-1, "
               "including a long multi-line config\n";
  std::string config;
  for (int i = 0; i < 5000; ++i) config += "key_" + std::to_string(i) + " = \"value with ünïcode\"\n";
  const std::map<std::string, std::string> attributes = {
      {"units", "K_CMB"}, {"nside", "512"}, {"beam", "gaussian fwhm 1.5 deg"}, {"backend", "cpu"},
      {"device", "cpu (2 threads)"}, {"version", "0.1.0"}, {"created", "2024-01-01T00:00:00Z"},
      {"config", config}, {"empty", ""}};
  const fs::path file = dir_ / "attrs.h5";
  write_tod(file, TodPrecision::float64, {random_signal(10, 5), random_signal(10, 6)}, nullptr, attributes);
  auto back = pisco::read_tod_attributes(file);
  EXPECT_EQ(back.at("pisco_format"), "pisco-tod-1");
  back.erase("pisco_format");
  EXPECT_EQ(back, attributes);
}

TEST_F(TodFile, WithPointingWritesThetaPhiPsi) {
  std::cout << "checking: with_pointing writes float64 theta, phi, psi per detector, readable as a pointing file\n";
  const std::size_t n = 2000;
  const std::vector<std::vector<double>> signal = {random_signal(n, 7), random_signal(n, 8)};
  const std::vector<Pointing> pointing = {random_pointing(n, 9), random_pointing(n, 10)};
  const fs::path file = dir_ / "withpointing.h5";
  write_tod(file, TodPrecision::float32, signal, &pointing, {});
  EXPECT_EQ(pisco::pointing_detectors(file), (std::vector<std::string>{"z_det", "a_det"}));
  for (std::size_t d = 0; d < 2; ++d) {
    const Pointing p = pisco::read_pointing_hdf5(file, d == 0 ? "z_det" : "a_det");
    EXPECT_EQ(p.theta, pointing[d].theta);
    EXPECT_EQ(p.phi, pointing[d].phi);
    EXPECT_EQ(p.psi, pointing[d].psi);
    // The same pointing as the detector's rotation: its axes are the antenna basis of the angles.
    const std::vector<pisco::Quat> q = pisco::read_tod_quats(file, d == 0 ? "z_det" : "a_det");
    ASSERT_EQ(q.size(), n);
    double worst = 0;
    for (std::size_t i = 0; i < n; ++i) {
      double t, f, s;
      pisco::quat_to_pointing(q[i], t, f, s);
      const auto los = pisco::rotate(q[i], {0, 0, 1});
      const double st = std::sin(p.theta[i]);
      worst = std::max({worst, std::abs(los[0] - st * std::cos(p.phi[i])), std::abs(los[1] - st * std::sin(p.phi[i])),
                        std::abs(los[2] - std::cos(p.theta[i])), std::abs(pisco::norm(q[i]) - 1)});
      if (st > 1e-6) worst = std::max(worst, std::abs(std::remainder(s - p.psi[i], 2 * std::numbers::pi)));
    }
    EXPECT_LT(worst, 1e-13);
  }
  std::cout << "checking: a file written without pointing has no theta dataset, and says so\n";
  const fs::path plain = dir_ / "plain.h5";
  write_tod(plain, TodPrecision::float64, signal, nullptr, {});
  const std::string message = error_of([&] { pisco::read_pointing_hdf5(plain, "a_det"); });
  EXPECT_TRUE(contains(message, plain.string()) && contains(message, "'/a_det'") && contains(message, "'theta'"))
      << message;
}

TEST_F(TodFile, WithWeightsWritesThreePerSample) {
  std::cout << "checking: with_weights writes each sample's (I, Q, U) weights, read back bit for bit; a write "
               "without them, with the wrong number, or to a file without weights is an error naming the detector\n";
  const std::size_t n = 3000;
  const FocalPlane fp = two_detectors();
  const fs::path file = dir_ / "weights.h5";
  pisco::TodWriter w(file, fp, n, TodPrecision::float64, false, {}, false, true);
  std::vector<std::vector<double>> weights(2);
  for (std::size_t d = 0; d < 2; ++d) {
    weights[d] = random_signal(3 * n, 20 + d);
    const std::vector<double> signal = random_signal(n, 30 + d);
    for (std::size_t off = 0; off < n; off += 1000)  // in pieces
      w.write(d, off, std::span<const double>(signal).subspan(off, 1000), nullptr, {},
              std::span<const double>(weights[d]).subspan(3 * off, 3000));
  }
  const std::vector<double> two(2 * 3, 0.5);
  const std::string missing = error_of([&] { w.write(0, 0, std::span<const double>(two).first(2)); });
  EXPECT_TRUE(contains(missing, "'z_det'") && contains(missing, "0 weights for 2 signal samples")) << missing;
  const std::string short_ = error_of([&] { w.write(1, 0, std::span<const double>(two).first(2), nullptr, {}, std::span<const double>(two).first(5)); });
  EXPECT_TRUE(contains(short_, "'a_det'") && contains(short_, "5 weights for 2 signal samples")) << short_;
  w.commit();
  EXPECT_EQ(pisco::read_tod_weights(file, "z_det"), weights[0]);
  EXPECT_EQ(pisco::read_tod_weights(file, "a_det"), weights[1]);
  const fs::path plain = dir_ / "plain.h5";
  pisco::TodWriter p(plain, fp, 2, TodPrecision::float64, false, {});
  const std::string unasked = error_of([&] { p.write(0, 0, std::span<const double>(two).first(2), nullptr, {}, std::span<const double>(two)); });
  EXPECT_TRUE(contains(unasked, "weights given, but the file is written without weights")) << unasked;
  p.write(0, 0, std::span<const double>(two).first(2));
  p.write(1, 0, std::span<const double>(two).first(2));
  p.commit();
  const std::string none = error_of([&] { pisco::read_tod_weights(plain, "a_det"); });
  EXPECT_TRUE(contains(none, plain.string()) && contains(none, "'weights'")) << none;
}

TEST_F(TodFile, CommitRenamesAndLeavesNoTemporary) {
  std::cout << "checking: the writer works under file + temporary_suffix(), commit() renames it over an existing file\n";
  const fs::path file = dir_ / "out.h5";
  { std::ofstream(file) << "an older output"; }
  TodWriter writer(file, two_detectors(), 4, TodPrecision::float64, false, {});
  EXPECT_EQ(writer.temporary_path(), fs::path(file.string() + pisco::temporary_suffix()));
  EXPECT_TRUE(fs::exists(writer.temporary_path()));
  const std::vector<double> v = {1, 2, 3, 4};
  writer.write(0, 0, v);
  writer.write(1, 0, v);
  EXPECT_EQ(std::ifstream(file).get(), 'a') << "the final name is untouched before commit()";
  writer.commit();
  EXPECT_FALSE(fs::exists(writer.temporary_path()));
  EXPECT_EQ(files(), std::vector<std::string>{"out.h5"});
  EXPECT_EQ(pisco::read_tod_signal(file, "a_det"), v);
  std::cout << "checking: write() or commit() after commit() is an error\n";
  expect_error([&] { writer.write(0, 0, v); }, "after commit()");
  expect_error([&] { writer.commit(); }, "twice");
}

TEST_F(TodFile, AbandonedWriterLeavesNothing) {
  std::cout << "checking: a writer destroyed without commit() leaves neither the final file nor the temporary\n";
  const fs::path file = dir_ / "abandoned.h5";
  fs::path temporary;
  {
    TodWriter writer(file, two_detectors(), 100, TodPrecision::float64, true, {{"units", "K"}});
    temporary = writer.temporary_path();
    const auto s = random_signal(50, 11);
    const Pointing p = random_pointing(50, 12);
    const pisco::PointingView view = p.view();
    writer.write(0, 0, s, &view);
    EXPECT_TRUE(fs::exists(temporary));
  }
  EXPECT_FALSE(fs::exists(file));
  EXPECT_FALSE(fs::exists(temporary));
  EXPECT_TRUE(files().empty());

  std::cout << "checking: an exception mid-run leaves an existing output untouched and no temporary\n";
  { std::ofstream(file) << "previous run"; }
  EXPECT_THROW(
      {
        TodWriter writer(file, two_detectors(), 10, TodPrecision::float32, false, {});
        writer.write(0, 0, random_signal(5, 13));
        throw std::runtime_error("device lost");
      },
      std::runtime_error);
  EXPECT_EQ(files(), std::vector<std::string>{"abandoned.h5"});
  std::string content;
  std::getline(std::ifstream(file), content);
  EXPECT_EQ(content, "previous run");
}

TEST_F(TodFile, WriterErrors) {
  const fs::path file = dir_ / "errors.h5";
  TodWriter writer(file, two_detectors(), 100, TodPrecision::float64, true, {});
  const auto s = random_signal(10, 14);
  const Pointing p = random_pointing(10, 15);
  const pisco::PointingView view = p.view();
  std::cout << "checking: a detector index beyond the focal plane is an error naming the file\n";
  expect_error([&] { writer.write(2, 0, s, &view); }, "detector index 2 is beyond the focal plane (2 detectors)");
  EXPECT_TRUE(contains(error_of([&] { writer.write(2, 0, s, &view); }), file.string()));
  std::cout << "checking: an offset or size beyond samples_per_detector is an error\n";
  expect_error([&] { writer.write(0, 95, s, &view); }, "samples [95, 105) are beyond the 100 samples per detector");
  expect_error([&] { writer.write(0, 101, {}, nullptr); }, "beyond the 100 samples per detector");
  expect_error([&] { writer.write(0, std::numeric_limits<std::size_t>::max() - 2, s, &view); }, "beyond");
  std::cout << "checking: with_pointing requires a pointing chunk of the signal's length\n";
  expect_error([&] { writer.write(0, 0, s); }, "got no pointing chunk");
  const pisco::PointingView short_view = view.subspan(0, 9);
  expect_error([&] { writer.write(0, 0, s, &short_view); }, "expected equal lengths");
  std::cout << "checking: commit() with samples never written names the detector and the first missing sample\n";
  writer.write(0, 0, s, &view);
  writer.write(0, 20, s, &view);
  expect_error([&] { writer.commit(); }, "'z_det': sample 10 of 100 was never written");
  EXPECT_FALSE(fs::exists(file));

  std::cout << "checking: bad focal planes and paths are refused up front\n";
  FocalPlane duplicate;
  duplicate.add({"d", 0, 0, 1, 0});
  duplicate.add({"d", 0, 0, 1, 0});
  expect_error([&] { TodWriter w(dir_ / "x.h5", duplicate, 1, TodPrecision::float64, false, {}); }, "appears twice");
  FocalPlane slash;
  slash.add({"a/b", 0, 0, 1, 0});
  expect_error([&] { TodWriter w(dir_ / "x.h5", slash, 1, TodPrecision::float64, false, {}); }, "'a/b'");
  expect_error([&] { TodWriter w(dir_ / "x.h5", FocalPlane{}, 1, TodPrecision::float64, false, {}); },
               "no detectors");
  expect_error([&] { TodWriter w(dir_ / "missing" / "x.h5", two_detectors(), 1, TodPrecision::float64, false, {}); },
               "does not exist");

  std::cout << "checking: a failing HDF5 call becomes a pisco::Error naming the file and the operation\n";
  const fs::path blocked = dir_ / "blocked.h5";
  fs::create_directory(blocked.string() + pisco::temporary_suffix());  // the temporary name is taken
  const std::string message =
      error_of([&] { TodWriter w(blocked, two_detectors(), 1, TodPrecision::float64, false, {}); });
  std::cout << "    error: " << message << "\n";
  EXPECT_TRUE(contains(message, blocked.string() + ": cannot create the temporary file") &&
              contains(message, "(HDF5: "))
      << message;
  EXPECT_FALSE(fs::exists(blocked));
  EXPECT_TRUE(fs::is_directory(blocked.string() + pisco::temporary_suffix()))
      << "what was in the way is not the writer's to remove";
}

TEST_F(TodFile, PointingFileRoundTrip) {
  std::cout << "checking: a pointing file written with the HDF5 API (float64 and float32, name order) reads back\n";
  const Pointing a = random_pointing(123, 16), b = random_pointing(77, 17);
  const fs::path file64 = dir_ / "pointing64.h5";
  write_pointing_file(file64, {group_of("det1", a), group_of("det0", b)});
  EXPECT_EQ(pisco::pointing_detectors(file64), (std::vector<std::string>{"det0", "det1"}));
  const Pointing back = pisco::read_pointing_hdf5(file64, "det1");
  EXPECT_EQ(back.theta, a.theta);
  EXPECT_EQ(back.phi, a.phi);
  EXPECT_EQ(back.psi, a.psi);
  EXPECT_EQ(pisco::read_pointing_hdf5(file64, "det0").size(), 77u);

  const fs::path file32 = dir_ / "pointing32.h5";
  write_pointing_file(file32, {group_of("det0", a)}, H5T_IEEE_F32LE);
  const Pointing back32 = pisco::read_pointing_hdf5(file32, "det0");
  ASSERT_EQ(back32.size(), a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(back32.theta[i], static_cast<double>(static_cast<float>(a.theta[i])));
    EXPECT_EQ(back32.psi[i], static_cast<double>(static_cast<float>(a.psi[i])));
  }
}

TEST_F(TodFile, PointingFileErrors) {
  const Pointing good = random_pointing(20, 18);
  std::cout << "checking: a missing file is named\n";
  const fs::path missing = dir_ / "missing.h5";
  expect_error([&] { pisco::read_pointing_hdf5(missing, "det0"); }, missing.string() + ": no such file");
  expect_error([&] { pisco::pointing_detectors(missing); }, "no such file");

  std::cout << "checking: a text file is not an HDF5 file\n";
  const fs::path text = dir_ / "pointing.txt";
  { std::ofstream(text) << "theta phi psi\n0.1 0.2 0.3\n"; }
  expect_error([&] { pisco::read_pointing_hdf5(text, "det0"); }, text.string() + ": not an HDF5 file");
  expect_error([&] { pisco::read_tod_signal(text, "det0"); }, "not an HDF5 file");

  const fs::path file = dir_ / "pointing.h5";
  write_pointing_file(file, {group_of("det0", good)});
  std::cout << "checking: a missing group names the file, the group and the groups present\n";
  expect_error([&] { pisco::read_pointing_hdf5(file, "det9"); },
               file.string() + ": no group '/det9' for detector 'det9' (groups in the file: det0)");

  std::cout << "checking: a missing dataset names the group and the dataset expected\n";
  PointingGroup no_psi = group_of("det0", good);
  no_psi.psi.clear();
  const fs::path file_no_psi = dir_ / "nopsi.h5";
  write_pointing_file(file_no_psi, {no_psi});
  expect_error([&] { pisco::read_pointing_hdf5(file_no_psi, "det0"); },
               file_no_psi.string() + ": group '/det0' has no dataset 'psi' (expected 1-D float64 or float32");

  std::cout << "checking: datasets of different lengths are named with their lengths\n";
  PointingGroup uneven = group_of("det0", good);
  uneven.phi.pop_back();
  const fs::path file_uneven = dir_ / "uneven.h5";
  write_pointing_file(file_uneven, {uneven});
  expect_error([&] { pisco::read_pointing_hdf5(file_uneven, "det0"); },
               file_uneven.string() + ":/det0: datasets theta, phi and psi have different lengths (20, 19, 20");

  std::cout << "checking: a NaN at sample 7 is named with its sample index\n";
  PointingGroup nan = group_of("det0", good);
  nan.phi[7] = std::numeric_limits<double>::quiet_NaN();
  const fs::path file_nan = dir_ / "nan.h5";
  write_pointing_file(file_nan, {nan});
  expect_error([&] { pisco::read_pointing_hdf5(file_nan, "det0"); }, file_nan.string() + ":/det0: sample 7 ");
  EXPECT_TRUE(contains(error_of([&] { pisco::read_pointing_hdf5(file_nan, "det0"); }), "non-finite"));

  std::cout << "checking: theta = 4 rad is outside [0, pi], named with its sample index\n";
  PointingGroup wide = group_of("det0", good);
  wide.theta[12] = 4.0;
  const fs::path file_wide = dir_ / "wide.h5";
  write_pointing_file(file_wide, {wide});
  const std::string message = error_of([&] { pisco::read_pointing_hdf5(file_wide, "det0"); });
  EXPECT_TRUE(contains(message, file_wide.string() + ":/det0: sample 12 has theta = 4") &&
              contains(message, "outside [0, pi]"))
      << message;

  std::cout << "checking: an integer dataset and a 2-D dataset are refused with what was expected\n";
  const fs::path file_int = dir_ / "int.h5";
  write_pointing_file(file_int, {group_of("det0", good)}, H5T_STD_I32LE);
  expect_error([&] { pisco::read_pointing_hdf5(file_int, "det0"); }, "dataset '/det0/theta' is not floating point");
  const fs::path file_2d = dir_ / "twod.h5";
  {
    const hid_t f = H5Fcreate(file_2d.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hid_t g = H5Gcreate2(f, "det0", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    const hsize_t dims[2] = {4, 5};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    for (const char* name : {"theta", "phi", "psi"})
      H5Dclose(H5Dcreate2(g, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
    H5Sclose(space);
    H5Gclose(g);
    H5Fclose(f);
  }
  expect_error([&] { pisco::read_pointing_hdf5(file_2d, "det0"); }, "'/det0/theta' has 2 dimensions");

  std::cout << "checking: reading a TOD group without its attributes names the missing attribute\n";
  expect_error([&] { pisco::read_tod_detectors(file); }, "group '/det0' has no attribute 'zeta'");
  expect_error([&] { pisco::read_tod_signal(file, "det0"); }, "group '/det0' has no dataset 'signal'");
}

}  // namespace
