// `pisco-vk` as a user runs it: a small simulation end to end, and every input error (docs/formats.md,
// "Errors and partial files") with its message, a non-zero exit status and no output file left behind.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <numbers>
#include <string>
#include <sys/wait.h>
#include <utility>
#include <vector>

#include <hdf5.h>
#include <toml++/toml.h>

#include "backend_fixtures.hpp"
#include "beam_file_writers.hpp"
#include "map_file_writers.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/pisco.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/scan.hpp"
#include "pisco/spectra.hpp"
#include "pisco/tod_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;

struct Result {
  int status;
  std::string output;  // stdout and stderr
};

Result run(const std::string& args) {
  const std::string cmd = std::string(PISCO_VK_EXE) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  while (std::size_t n = std::fread(buf.data(), 1, buf.size(), p)) out.append(buf.data(), n);
  const int rc = pclose(p);
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, out};
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("cli");
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }
  // A small valid simulation; `sky`, `beam`, `scan`, ... replace its tables.
  std::string config(const std::string& sky = "[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                     const std::string& beam = "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n",
                     const std::string& fp = "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n",
                     const std::string& scan = "[scan]\ntype = \"pixel_centres\"\nnside = 16\n",
                     const std::string& extra = "") {
    return sky + beam + fp + scan + "[engine]\nbackend = \"cpu\"\n[output]\ndir = \"" + (dir_ / "out").string() +
           "\"\nplots = false\nlmax = 32\n" + extra;
  }
  // The failing command left no output files (final or temporary) behind.
  void expect_no_output() {
    if (!fs::exists(dir_ / "out")) return;
    for (const auto& e : fs::directory_iterator(dir_ / "out")) ADD_FAILURE() << "left behind: " << e.path();
  }
  void expect_error(const std::string& args, const std::string& needle) {
    const Result r = run(args);
    std::cout << "$ pisco-vk " << args.substr(0, 80) << "\n" << r.output;
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find(needle), std::string::npos) << "expected '" << needle << "' in:\n" << r.output;
    std::size_t errors = 0;
    for (std::size_t at = r.output.find("pisco-vk: error:"); at != std::string::npos; at = r.output.find("pisco-vk: error:", at + 1))
      ++errors;
    EXPECT_EQ(errors, 1u) << "one clear message";
    expect_no_output();
  }
  fs::path dir_;
};

TEST_F(Cli, VersionHelpAndDevices) {
  const Result v = run("--version");
  EXPECT_EQ(v.status, 0);
  EXPECT_NE(v.output.find(pisco::version), std::string::npos);
  for (const char* cmd : {"--help", "run --help", "devices --help", "bench --help", "validate --help"}) {
    const Result h = run(cmd);
    EXPECT_EQ(h.status, 0) << cmd;
    EXPECT_NE(h.output.find("Usage"), std::string::npos) << cmd << ": " << h.output;
  }
  const Result d = run("devices");
  std::cout << d.output;
  EXPECT_EQ(d.status, 0);
  EXPECT_NE(d.output.find("cpu"), std::string::npos);
  EXPECT_NE(run("frobnicate").status, 0);
}

// The bench's set-up apart (the polar copy made in it) and the engine's host work, and the streamed
// run's host work per detector-sample: each line printed with finite figures.
TEST_F(Cli, BenchPrintsTheSetUpApartAndTheStreamsHostWork) {
  const Result b = run("bench -b simd --threads 2 --rho-max 1");
  ASSERT_EQ(b.status, 0) << b.output;
  EXPECT_NE(b.output.find("set-up"), std::string::npos) << b.output;
  EXPECT_NE(b.output.find("ns/sample"), std::string::npos) << b.output;
  const Result e = run("bench -b simd --threads 2 --rho-max 1 --beam elliptical");
  ASSERT_EQ(e.status, 0) << e.output;
  EXPECT_NE(e.output.find("elliptical beam 1.52 x 1.46 deg FWHM (2D grid)"), std::string::npos) << e.output;
  EXPECT_NE(run("bench --beam square").status, 0);
  const Result s = run("bench --stream --threads 2");
  ASSERT_EQ(s.status, 0) << s.output;
  std::istringstream lines(s.output);
  std::string line;
  int rows = 0;
  while (std::getline(lines, line)) {
    unsigned threads = 0;
    double boresight = 0, quaternions = 0, from_boresight = 0, pointing = 0, binning = 0, total = 0;
    if (std::sscanf(line.c_str(), "%u %lf %lf %lf %lf %lf %lf", &threads, &boresight, &quaternions, &from_boresight,
                    &pointing, &binning, &total) != 7)
      continue;
    ++rows;
    EXPECT_TRUE(threads == 1 || threads == 2) << line;
    EXPECT_GT(from_boresight, 0.0) << line;
    EXPECT_GT(pointing, 0.0) << line;
    EXPECT_GT(binning, 0.0) << line;
    EXPECT_NEAR(total, boresight + quaternions + from_boresight, 0.05) << line;  // four figures rounded to 0.005
  }
  EXPECT_EQ(rows, 2) << s.output;
}

TEST_F(Cli, SmallSimulationEndToEnd) {
  const fs::path cfg = write("sim.toml", config());
  const Result r = run("run " + cfg.string());
  std::cout << r.output;
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"tod.h5", "maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"})
    EXPECT_TRUE(fs::exists(dir_ / "out" / f)) << f;
  EXPECT_NE(r.output.find("summary: 18432 samples"), std::string::npos);  // 2 detectors x 3072 x 3
  // The TOD file holds what the library computes for the same inputs.
  const auto dets = pisco::read_tod_detectors(dir_ / "out" / "tod.h5");
  ASSERT_EQ(dets.size(), 2u);
  EXPECT_EQ(dets[0].name, "pa");
  EXPECT_EQ(pisco::read_tod_signal(dir_ / "out" / "tod.h5", "pb").size(), 9216u);
  const auto attrs = pisco::read_tod_attributes(dir_ / "out" / "tod.h5");
  EXPECT_EQ(attrs.at("backend"), "cpu");
  EXPECT_NE(attrs.at("config").find("pixel_centres"), std::string::npos);
  const pisco::Sky maps = pisco::Sky::read_fits(dir_ / "out" / "maps.fits");
  EXPECT_EQ(maps.nside(), 16);
}

// The same simulation through the vulkan backend (lavapipe in CI): the TOD agrees with the cpu run to
// the float32 precision contract (docs/validation.md, "B"), and the file records the backend.
TEST_F(Cli, VulkanBackendMatchesTheReference) {
  if (const std::string why = pisco_test::backend_unavailable("vulkan"); !why.empty())
    GTEST_SKIP() << "vulkan backend unavailable: " << why;
  const fs::path cfg = write("sim.toml", config());
  ASSERT_EQ(run("run -q " + cfg.string() + " -o " + (dir_ / "cpu").string()).status, 0);
  const Result r = run("run " + cfg.string() + " -o " + (dir_ / "vk").string() + " --backend vulkan");
  std::cout << r.output;
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(pisco::read_tod_attributes(dir_ / "vk" / "tod.h5").at("backend"), "vulkan");
  for (const char* det : {"pa", "pb"}) {
    const auto ref = pisco::read_tod_signal(dir_ / "cpu" / "tod.h5", det);
    const auto got = pisco::read_tod_signal(dir_ / "vk" / "tod.h5", det);
    ASSERT_EQ(got.size(), ref.size());
    double rms = 0, err = 0;
    for (std::size_t i = 0; i < ref.size(); ++i) {
      rms += ref[i] * ref[i];
      err += (got[i] - ref[i]) * (got[i] - ref[i]);
    }
    EXPECT_LE(std::sqrt(err), 1e-5 * std::sqrt(rms)) << det;
  }
}

TEST_F(Cli, ConstantElevationScanWithOffsetsMatchesTheLibrary) {
  const std::string scan =
      "[scan]\ntype = \"ces\"\nelevation_deg = 50\naz_throw_deg = 40\nsample_rate_hz = 10\n"
      "duration_hours = 0.05\nboresight_deg = [15]\nnside = 16\n";
  const std::string fp = "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\nxi_deg = 2.5\neta_deg = -1.0\n";
  const fs::path cfg = write("ces.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n",
                                                fp, scan, "tod_pointing = true\nspectra = false\n"));
  const Result r = run("run " + cfg.string());
  ASSERT_EQ(r.status, 0) << r.output;
  // The same simulation through the library: boresight, offset, engine.
  pisco::CesScan ces;
  ces.latitude = -22.96 * pisco::deg;
  ces.longitude = -67.79 * pisco::deg;
  ces.elevation = 50 * pisco::deg;
  ces.az_centre = std::numbers::pi;
  ces.az_throw = 40 * pisco::deg;
  ces.sample_rate = 10;
  ces.start_unix = 1559347200;
  ces.boresight_angles = {15 * pisco::deg};
  ces.samples = 1800;
  pisco::Pointing b, det;
  ces.generate(0, ces.samples, b);
  pisco::offset_pointing(b, 2.5 * pisco::deg, -1.0 * pisco::deg, 0, det);
  const pisco::Pointing file_ptg = pisco::read_pointing_hdf5(dir_ / "out" / "tod.h5", "pa");
  ASSERT_EQ(file_ptg.size(), det.size());
  double worst = 0;
  for (std::size_t i = 0; i < det.size(); ++i)
    worst = std::max({worst, std::abs(file_ptg.theta[i] - det.theta[i]), std::abs(file_ptg.psi[i] - det.psi[i])});
  EXPECT_EQ(worst, 0.0);
  // The same TOD three ways: the command line's CES run (boresight angles, the engine applying the
  // offsets); the library given the boresight as quaternions and the offset pair; the library given
  // each detector's own expanded angles on a pair without offset. float64 rounding apart.
  const pisco::Sky sky = pisco::synthesize_sky(pisco::read_cl_table(pisco::default_cl_file(), 64, true), 32, 3);
  pisco::BeamOptions o;
  o.rho_max = 8 * pisco::deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(4 * pisco::deg, o)};
  pisco::FocalPlane on_boresight, offset;
  on_boresight.add_pair("p", 0, 0, 0);
  std::vector<pisco::Detector> dets = on_boresight.detectors();
  for (auto& d : dets) d.set_offset(2.5 * pisco::deg, -1.0 * pisco::deg, 0);
  offset = pisco::FocalPlane(dets);
  std::vector<pisco::Quat> q;
  for (std::size_t i = 0; i < b.size(); ++i) q.push_back(pisco::quat_from_pointing(b.theta[i], b.phi[i], b.psi[i]));
  pisco::Engine lib_angles(sky, beams, on_boresight), lib_quats(sky, beams, offset);
  std::vector<double> tod(det.size()), tod_q(det.size());
  lib_angles.convolve(1, det, tod);
  lib_quats.convolve(1, pisco::QuatPointingView{q}, tod_q);
  const std::vector<double> file_tod = pisco::read_tod_signal(dir_ / "out" / "tod.h5", "pb");
  double diff = 0, diff_q = 0, rms = 0;
  for (std::size_t i = 0; i < tod.size(); ++i) {
    diff = std::max(diff, std::abs(file_tod[i] - tod[i]));
    diff_q = std::max(diff_q, std::abs(file_tod[i] - tod_q[i]));
    rms += tod[i] * tod[i];
  }
  rms = std::sqrt(rms / double(tod.size()));
  std::cout << "ces run: " << det.size() << " samples per detector, TOD rms " << rms
            << "; max |file - library (expanded angles)| " << diff << ", |file - library (quaternions)| " << diff_q
            << "\n";
  EXPECT_LE(diff, 1e-12 * rms);
  EXPECT_LE(diff_q, 1e-12 * rms);
  // The vulkan backend on the same run, within the backend bars.
  if (const std::string why = pisco_test::backend_unavailable("vulkan"); !why.empty())
    GTEST_SKIP() << "the cpu run passed; its vulkan comparison needs the vulkan backend: " << why;
  const Result v = run("run " + cfg.string() + " -b vulkan -o " + (dir_ / "vk-ces").string());
  ASSERT_EQ(v.status, 0) << v.output;
  const std::vector<double> vk_tod = pisco::read_tod_signal(dir_ / "vk-ces" / "tod.h5", "pb");
  double err = 0;
  for (std::size_t i = 0; i < tod.size(); ++i) err += (vk_tod[i] - tod[i]) * (vk_tod[i] - tod[i]);
  err = std::sqrt(err / double(tod.size()));
  std::cout << "ces run on vulkan: relative rms error " << err / rms << "\n";
  EXPECT_LE(err, 1e-5 * rms);
}

// A pointing file of boresight quaternions and a focal plane with offsets: the command line's TOD is
// the library's for the same quaternions, and the recorded detector quaternions carry the offsets. A
// bad quaternion in the file ends the run with one error naming the file and the sample, and no output.
TEST_F(Cli, BoresightPointingFileRunsAndBadSamplesLeaveNoOutput) {
  pisco::SatelliteScan sat;
  sat.spin_period = 60;
  sat.precession_period = 600;
  sat.sample_rate = 5;
  sat.samples = 900;
  std::vector<pisco::Quat> q;
  sat.generate(0, sat.samples, q);
  const fs::path bore = dir_ / "bore.h5";
  pisco::BoresightFile::write(bore, q);
  const std::string fp =
      "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\nxi_deg = 1.5\neta_deg = -2.0\ngamma_deg = 20\n";
  const std::string scan = "[scan]\ntype = \"file\"\nfile = \"" + bore.string() + "\"\n";
  const fs::path cfg = write("file.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                 "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n",
                                                 fp, scan, "tod_pointing = true\nspectra = false\nmaps = false\n"));
  const Result r = run("run " + cfg.string() + " -q");
  ASSERT_EQ(r.status, 0) << r.output;
  const pisco::Sky sky = pisco::synthesize_sky(pisco::read_cl_table(pisco::default_cl_file(), 64, true), 32, 3);
  pisco::BeamOptions o;
  o.rho_max = 8 * pisco::deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(4 * pisco::deg, o)};
  pisco::FocalPlane lib;
  lib.add_pair("p", 0, 0, 0);
  std::vector<pisco::Detector> dets = lib.detectors();
  for (auto& d : dets) d.set_offset(1.5 * pisco::deg, -2.0 * pisco::deg, 20 * pisco::deg);
  pisco::Engine engine(sky, beams, pisco::FocalPlane(dets));
  std::vector<double> tod(q.size());
  engine.convolve(0, pisco::QuatPointingView{q}, tod);
  EXPECT_EQ(pisco::read_tod_signal(dir_ / "out" / "tod.h5", "pa"), tod);
  const std::vector<pisco::Quat> recorded = pisco::read_tod_quats(dir_ / "out" / "tod.h5", "pa");
  ASSERT_EQ(recorded.size(), q.size());
  double worst = 0;
  for (std::size_t i = 0; i < q.size(); ++i) {
    const auto want = pisco::rotate(q[i] * dets[0].offset, {0, 0, 1}), got = pisco::rotate(recorded[i], {0, 0, 1});
    worst = std::max({worst, std::abs(want[0] - got[0]), std::abs(want[1] - got[1]), std::abs(want[2] - got[2])});
  }
  EXPECT_LT(worst, 1e-14) << "recorded lines of sight";

  q[123] = {0.0, 0.0, 0.0, 1.01};
  pisco::BoresightFile::write(bore, q);
  fs::remove_all(dir_ / "out");
  expect_error("run " + cfg.string() + " -q", "sample 123 has norm");
  expect_no_output();
}

// [hwp] with per-detector keys: a CSV focal plane whose rows turn the plate off for one detector and
// give another its own gamma; the command line's TOD equals the library's with the same plates and
// the angles of the rotation.
TEST_F(Cli, HalfWavePlateWithPerDetectorKeys) {
  write("fp.csv", "name,zeta_deg,beam,hwp,hwp_gamma_deg\nd0,0,main,1,10\nd1,30,main,0,0\nd2,60,main,true,-25\n");
  const std::string scan = "[scan]\ntype = \"pixel_centres\"\nnside = 8\n";
  const std::string hwp = "[hwp]\nmodel = \"ideal\"\nrpm = 30\nphase_deg = 5\nsample_rate_hz = 20\n";
  const fs::path cfg = write("hwp.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n",
                                                "[focal_plane]\nfile = \"" + (dir_ / "fp.csv").string() + "\"\n", scan,
                                                "spectra = false\ntod_weights = true\ntod_pointing = true\n") + hwp);
  const Result r = run("run " + cfg.string() + " -q");
  ASSERT_EQ(r.status, 0) << r.output;
  const pisco::Sky sky = pisco::synthesize_sky(pisco::read_cl_table(pisco::default_cl_file(), 64, true), 32, 3);
  pisco::BeamOptions o;
  o.rho_max = 8 * pisco::deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(4 * pisco::deg, o)};
  pisco::FocalPlane fp;
  const double zetas[] = {0, 30, 60};
  for (int i = 0; i < 3; ++i) {
    pisco::Detector d;
    d.name = "d" + std::to_string(i);
    d.zeta = zetas[i] * pisco::deg;
    if (i == 0) d.hwp = pisco::HalfWavePlate::ideal(10 * pisco::deg);
    if (i == 2) d.hwp = pisco::HalfWavePlate::ideal(-25 * pisco::deg);
    fp.add(d);
  }
  const pisco::Pointing p = pisco::pixel_centre_scan(8, {0.0, 45 * pisco::deg, 90 * pisco::deg});
  pisco::HwpAngleStream stream;
  stream.frequency_hz = 0.5;
  stream.phase = 5 * pisco::deg;
  stream.sample_rate = 20;
  std::vector<double> h;
  stream.generate(0, p.size(), h);
  pisco::Engine engine(sky, beams, fp);
  for (std::size_t d = 0; d < 3; ++d) {
    std::vector<double> tod(p.size());
    engine.convolve(d, p, tod, false, fp[d].hwp ? std::span<const double>(h) : std::span<const double>());
    EXPECT_EQ(pisco::read_tod_signal(dir_ / "out" / "tod.h5", fp[d].name), tod) << fp[d].name;
  }
  // tod_weights: each sample's (I, Q, U) weights, the plate's modulation included; a map-maker of one's
  // own that solves with them from the file alone gets the maps pisco-vk wrote.
  const fs::path tod_file = dir_ / "out" / "tod.h5";
  const Healpix_Base base(8, RING, SET_NSIDE);
  std::vector<std::array<double, 9>> ata(base.Npix());
  std::vector<std::array<double, 3>> atd(base.Npix());
  for (std::size_t d = 0; d < 3; ++d) {
    const std::vector<double> w = pisco::read_tod_weights(tod_file, fp[d].name);
    const std::vector<double> signal = pisco::read_tod_signal(tod_file, fp[d].name);
    const pisco::Pointing own = pisco::read_pointing_hdf5(tod_file, fp[d].name);
    ASSERT_EQ(w.size(), 3 * p.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
      const std::array<double, 3> a = pisco::stokes_weights(fp[d], own.psi[i], h[i]);
      ASSERT_TRUE(w[3 * i] == a[0] && w[3 * i + 1] == a[1] && w[3 * i + 2] == a[2]) << fp[d].name << ", sample " << i;
      const std::size_t pix = std::size_t(base.ang2pix(pointing(own.theta[i], own.phi[i])));
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) ata[pix][3 * r + c] += w[3 * i + r] * w[3 * i + c];
        atd[pix][r] += w[3 * i + r] * signal[i];
      }
    }
  }
  const pisco::Sky maps = pisco::Sky::read_fits(dir_ / "out" / "maps.fits", pisco::UnseenPolicy::zero);
  double worst = 0.0, scale = 0.0;
  for (std::size_t pix = 0; pix < ata.size(); ++pix) {
    const auto& m = ata[pix];
    const double det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                       m[2] * (m[3] * m[7] - m[4] * m[6]);
    ASSERT_GT(std::abs(det), 0.0) << "pixel " << pix;
    for (int k = 0; k < 3; ++k) {  // Cramer's rule
      std::array<double, 9> mk = m;
      for (int r = 0; r < 3; ++r) mk[3 * r + k] = atd[pix][r];
      const double x = (mk[0] * (mk[4] * mk[8] - mk[5] * mk[7]) - mk[1] * (mk[3] * mk[8] - mk[5] * mk[6]) +
                        mk[2] * (mk[3] * mk[7] - mk[4] * mk[6])) / det;
      const double want = (k == 0 ? maps.I() : k == 1 ? maps.Q() : maps.U())[pix];
      worst = std::max(worst, std::abs(x - want));
      scale = std::max(scale, std::abs(want));
    }
  }
  std::cout << "maps from the file's weights: largest difference " << worst / scale << " of the largest value\n";
  EXPECT_LT(worst, 1e-9 * scale);
  // Plate keys without an [hwp] table are an error naming the detector.
  fs::remove_all(dir_ / "out");
  const fs::path bad = write("bad.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n",
                                                "[focal_plane]\nfile = \"" + (dir_ / "fp.csv").string() + "\"\n", scan));
  expect_error("run " + bad.string(), "'d0' has half-wave plate keys");
}

TEST_F(Cli, TensorModesScaleWithR) {
  // r = 1: the synthesized sky's BB follows the shipped tensor template within cosmic variance.
  const fs::path cfg = write("r.toml", config("[sky]\nnside = 64\nlmax = 128\nseed = 9\nr = 1.0\n", "[beams.main]\nfwhm_deg = 4\nrho_max_deg = 8\n",
                                              "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"main\"\n",
                                              "[scan]\ntype = \"pixel_centres\"\nnside = 8\n", "tod = false\n"));
  const Result r = run("run " + cfg.string());
  ASSERT_EQ(r.status, 0) << r.output;
  std::ifstream in(dir_ / "out" / "input_spectra.txt"), tmpl(std::string(PISCO_TEST_ASSETS_DIR) + "/spectra/tensor_bb_r1.txt");
  std::map<int, double> ref;
  std::string line;
  while (std::getline(tmpl, line))
    if (line[0] != '#') {
      std::istringstream ss(line);
      int l;
      double d;
      ss >> l >> d;
      ref[l] = d;
    }
  double sum_in = 0, sum_ref = 0;
  while (std::getline(in, line))
    if (line[0] != '#') {
      std::istringstream ss(line);
      int l;
      double tt, ee, bb;
      ss >> l >> tt >> ee >> bb;
      if (l >= 2 && l <= 32) {
        sum_in += bb;
        sum_ref += ref.at(l);
      }
    }
  std::cout << "r = 1 sky: sum of D_l^BB over l = 2..32 is " << sum_in / sum_ref << " of the template\n";
  EXPECT_NEAR(sum_in / sum_ref, 1.0, 0.3);
}

TEST_F(Cli, ConfigErrors) {
  expect_error("run " + (dir_ / "absent.toml").string(), "absent.toml: no such file (expected a TOML file)");
  expect_error("run " + write("bad.toml", "[sky\nnside = 3").string(), "bad.toml:1:");
  expect_error("run " + write("typo.toml", config() + "[output.extra]\n").string(), "unknown key");
  expect_error("run " + write("typo2.toml", config("[sky]\nnsid = 32\n")).string(), "[sky] unknown key 'nsid'");
  expect_error("run " + write("nside.toml", config("[sky]\nnside = 100\n")).string(), "[sky] nside: expected a power of two");
  expect_error("run " + write("rho.toml", config("[sky]\nnside = 32\n", "[beams.main]\nfwhm_deg = 1.5\nrho_max_deg = 90\n")).string(),
               "rho_max_deg");
  expect_error("run " + write("wide.toml", config("[sky]\nnside = 32\n", "[beams.main]\nfwhm_deg = 12\nrho_max_deg = 5\n")).string(),
               "wider than the beam grid");
  expect_error("run " + write("beam.toml", config("[sky]\nnside = 32\n", "[beams.main]\nfwhm_deg = 2\n",
                                                  "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"side\"\n")).string(),
               "no beam named \"side\"");
  expect_error("run " + write("backend.toml", config() + "").string() + " --backend nosuch", "backend 'nosuch' is unknown");
  expect_error("run " + write("device.toml", config() + "").string() + " --backend vulkan --device nosuch",
               pisco_test::backend_unavailable("vulkan").empty() ? "no device named 'nosuch'" : "is not available");
  expect_error("run " + write("cpu_device.toml", config() + "").string() + " --backend cpu --device 0",
               "-d/--device: the cpu backend has no device setting (it applies to simd, vulkan and cuda)");
  expect_error("bench -b vulkan --threads 2 --rho-max 5",
               "--threads: the vulkan backend has no threads setting (it applies to cpu and simd)");
  // A value the table of settings does not take: the words of simulation files and Python, behind the flag.
  expect_error("bench -b vulkan --arithmetic double --rho-max 5",
               "--arithmetic: expected \"auto\", \"float64\" or \"float-float\", got \"double\"");
}

// A Gaussian of `fwhm` polarized along x as the frameworks' b_lm, in healpy's alm FITS layout, with
// MAX-MPOL = `mmax_key`.
void write_gaussian_blm(const fs::path& file, double fwhm, int lmax, long mmax_key = 2) {
  const pisco::HarmonicBeam g = pisco_test::gaussian_blm(fwhm, lmax);
  pisco_test::write_alm_fits(file, {&g.t, &g.e, &g.b}, lmax, 2, mmax_key);
}

double relative_rms(const std::vector<double>& got, const std::vector<double>& want) {
  double e = 0, r = 0;
  for (std::size_t i = 0; i < want.size(); ++i) {
    e += (got[i] - want[i]) * (got[i] - want[i]);
    r += want[i] * want[i];
  }
  return std::sqrt(e / r);
}

// Beams from files through `pisco-vk run` (docs/beams.md): a b_lm file of a Gaussian gives the TOD of
// the Gaussian beam (to the harmonic kernel's difference from exp(-rho^2 / 2 s^2), O(s^2)); a GRASP beam
// split into a main part and sidelobes gives the unsplit beam's TOD; bad keys and files are one error.
TEST_F(Cli, BeamFilesAndSplitBeams) {
  write_gaussian_blm(dir_ / "gauss_blm.fits", 4.0 * pisco::deg, 400);
  const std::string gauss = "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n";
  const std::string blm = "[beams.main]\ntype = \"blm\"\nfile = \"gauss_blm.fits\"\nrho_max_deg = 8.0\n";
  ASSERT_EQ(run("run " + write("g.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n", gauss)).string() + " -o " + (dir_ / "g").string()).status, 0);
  const Result b = run("run " + write("b.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n", blm)).string() + " -o " + (dir_ / "b").string());
  std::cout << b.output;
  ASSERT_EQ(b.status, 0) << b.output;
  EXPECT_NE(b.output.find("beam main for zeta -90 deg: harmonic beam"), std::string::npos) << b.output;
  // The pair's TOD in run `got` against run `want`, detector by detector.
  const auto expect_tods_close = [&](const char* got, const char* want, const char* what, double bar) {
    for (const char* det : {"pa", "pb"}) {
      const double e = relative_rms(pisco::read_tod_signal(dir_ / got / "tod.h5", det), pisco::read_tod_signal(dir_ / want / "tod.h5", det));
      std::cout << det << ": " << what << ": relative RMS " << e << "\n";
      EXPECT_LT(e, bar) << det;
    }
  };
  expect_tods_close("b", "g", "b_lm file vs Gaussian beam", 1e-3);

  fs::copy_file(fs::path(PISCO_TEST_ASSETS_DIR) / "examples" / "grasp_beam.grd", dir_ / "horn.grd");
  const std::string grasp = "[beams.main]\ntype = \"grasp\"\nfile = \"horn.grd\"\nrho_max_deg = 4.5\n";
  const std::string sky = "[sky]\nnside = 64\nlmax = 128\nseed = 3\n";
  ASSERT_EQ(run("run " + write("w.toml", config(sky, grasp)).string() + " -o " + (dir_ / "w").string()).status, 0);
  const Result sp = run("run " + write("s.toml", config(sky, grasp + "sidelobe_split_deg = 4.0\n")).string() + " -o " + (dir_ / "s").string());
  std::cout << sp.output;
  ASSERT_EQ(sp.status, 0) << sp.output;
  EXPECT_NE(sp.output.find("split at 4 deg"), std::string::npos) << sp.output;
  // The outer part is cut at rho_max, so its band limit is the sky's own: both parts are summed on the
  // sky's pixels, and what differs is the main part's grid (to 4 deg) against the whole beam's (to 4.5
  // deg): bilinear interpolation between other nodes, a few 1e-5.
  expect_tods_close("s", "w", "split GRASP beam vs whole disc", 1e-4);

  fs::remove_all(dir_ / "out");
  expect_error("run " + write("set.toml", config(sky, grasp + "set = 3\n")).string(), "set = 3, but");
  expect_error("run " + write("setkey.toml", config(sky, gauss + "set = 1\n")).string(), "unknown key 'set'");
  expect_error("run " + write("nofile.toml", config(sky, "[beams.main]\ntype = \"blm\"\nfile = \"absent.fits\"\n")).string(),
               "absent.fits");
  write_gaussian_blm(dir_ / "bad_mmax.fits", 4.0 * pisco::deg, 40, 60);
  expect_error("run " + write("mmax.toml", config(sky, "[beams.main]\ntype = \"blm\"\nfile = \"bad_mmax.fits\"\n")).string(),
               "MAX-MPOL = 60 is above MAX-LPOL = 40");
  expect_error("run " + write("far.toml", config(sky, "[beams.main]\ntype = \"grasp\"\nfile = \"horn.grd\"\nrho_max_deg = 8\n")).string(),
               "is beyond it");
  expect_error("run " + write("split.toml", config(sky, grasp + "sidelobe_split_deg = 6.0\n")).string(),
               "sidelobe_split_deg: 6 deg must lie in (0, rho_max = 4.5 deg)");
  expect_error("run " + write("nside.toml", config(sky, grasp + "sidelobe_nside = 64\n")).string(),
               "only with sidelobe_split_deg");
  expect_error("run " + write("pw2.toml", config(sky, grasp + "sidelobe_split_deg = 3.0\nsidelobe_nside = 48\n")).string(),
               "sidelobe_nside: 48 must be a power of two up to 8192");
  // sidelobe_nside above the sky's (64 here): refused, not silently lowered.
  expect_error("run " + write("above.toml", config(sky, grasp + "sidelobe_split_deg = 3.0\nsidelobe_nside = 128\n")).string(),
               "sidelobe_nside = 128 is above the sky's NSIDE 64");
  // A b_lm file of T alone for a polarized pair: an error naming the option that means it.
  {
    const pisco::HarmonicBeam g = pisco_test::gaussian_blm(4.0 * pisco::deg, 200);
    pisco_test::write_alm_fits(dir_ / "t_only.fits", {&g.t}, 200, 2);
  }
  const std::string t_only = "[beams.main]\ntype = \"blm\"\nfile = \"t_only.fits\"\nrho_max_deg = 8.0\n";
  expect_error("run " + write("tonly.toml", config(sky, t_only)).string(),
               "t_only.fits holds T coefficients alone, so detector 'pa' (polarization efficiency 1) would see no "
               "polarization; give a file with T, E and B, or set temperature_only = true");
  EXPECT_EQ(run("run -q --no-plots " + write("tonly_ok.toml", config(sky, t_only + "temperature_only = true\n")).string() +
                " -o " + (dir_ / "tonly").string())
                .status,
            0);
  expect_error("run " + write("tokey.toml", config(sky, gauss + "temperature_only = true\n")).string(),
               "unknown key 'temperature_only'");
  write("b.fits", "not read: the split is refused first");
  expect_error("run " + write("fsplit.toml", config(sky, "[beams.main]\ntype = \"file\"\nfile = \"b.fits\"\nsidelobe_split_deg = 1\n")).string(),
               "cannot be split");
}

// A device lost in the middle of a run (injected): one clear error, no output left half-written.
TEST_F(Cli, LostDeviceLeavesNoOutput) {
  if (const std::string why = pisco_test::backend_unavailable("vulkan"); !why.empty())
    GTEST_SKIP() << "vulkan backend unavailable: " << why;
  ::setenv("PISCO_VK_TEST_FAULT", "lose-device-after:1", 1);
  expect_error("run " + write("lost.toml", config()).string() + " --backend vulkan", "device was lost");
  ::unsetenv("PISCO_VK_TEST_FAULT");
}

// A pointing file of per-detector groups (docs/formats.md, "Pointing files"): groups[k].second samples
// of theta, phi, psi in the group named groups[k].first; theta of sample `odd` is `odd_theta` (a value
// the reader must refuse) when odd is below the count.
void write_detector_pointing(const fs::path& file, const std::vector<std::pair<std::string, std::size_t>>& groups,
                             std::size_t odd = SIZE_MAX, double odd_theta = 0.0) {
  const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(f, 0) << file;
  for (const auto& [name, n] : groups) {
    const hid_t g = H5Gcreate2(f, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    std::vector<double> v[3];
    for (std::size_t i = 0; i < n; ++i) {
      v[0].push_back(i == odd ? odd_theta : 0.5 + 0.01 * double(i));  // theta
      v[1].push_back(0.1 * double(i));         // phi
      v[2].push_back(0.0);                     // psi
    }
    const char* names[3] = {"theta", "phi", "psi"};
    for (int k = 0; k < 3; ++k) {
      const hsize_t dims[1] = {n};
      const hid_t space = H5Screate_simple(1, dims, nullptr);
      const hid_t ds = H5Dcreate2(g, names[k], H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      if (n > 0) H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v[k].data());
      H5Dclose(ds);
      H5Sclose(space);
    }
    H5Gclose(g);
  }
  H5Fclose(f);
}

TEST_F(Cli, InputFileErrors) {
  expect_error("run " + write("sky.toml", config("[sky]\nfile = \"missing.fits\"\n")).string(), "missing.fits");
  // A map with a NaN pixel.
  pisco::Sky nan_sky(16);
  nan_sky.Q()[77] = std::numeric_limits<double>::quiet_NaN();
  pisco_test::write_unchecked_sky(nan_sky, dir_ / "nan.fits");  // the library's writers refuse it
  expect_error("run " + write("nan.toml", config("[sky]\nfile = \"nan.fits\"\n")).string(), "pixel 77");
  // A focal-plane table with a malformed number.
  write("fp.csv", "name,zeta_deg,beam\nd1,abc,main\n");
  expect_error("run " + write("fp.toml", config("[sky]\nnside = 32\n", "[beams.main]\nfwhm_deg = 4\nrho_max_deg = 8\n",
                                                "[focal_plane]\nfile = \"fp.csv\"\n")).string(),
               "fp.csv:2: column 'zeta_deg': expected a number");
  // Pointing files: a NaN sample and a theta outside [0, pi], each named by its index. Written by hand
  // (the TOD writer refuses a NaN), in the layout the reader takes.
  for (const auto& [name, theta] : {std::pair{"nanptg.h5", std::numeric_limits<double>::quiet_NaN()}, {"theta.h5", 4.0}})
    write_detector_pointing(dir_ / name, {{"d1", 20}}, 7, theta);
  const std::string det = "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d1\"\nbeam = \"main\"\n";
  const std::string beam = "[beams.main]\nfwhm_deg = 4\nrho_max_deg = 8\n";
  expect_error("run " + write("p1.toml", config("[sky]\nnside = 32\n", beam, det, "[scan]\ntype = \"file\"\nfile = \"nanptg.h5\"\n")).string(),
               "sample 7");
  expect_error("run " + write("p2.toml", config("[sky]\nnside = 32\n", beam, det, "[scan]\ntype = \"file\"\nfile = \"theta.h5\"\n")).string(),
               "sample 7");
}

// Per-detector pointing files whose detectors have different sample counts: one error naming the file,
// the detector and both counts, a non-zero exit and no output, whichever detector is the odd one (the
// first one empty included). The same file with equal counts runs.
TEST_F(Cli, PerDetectorPointingOfUnequalLengthsLeavesNoOutput) {
  const std::string beam = "[beams.main]\nfwhm_deg = 4\nrho_max_deg = 8\n";
  const std::string dets = "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d1\"\nbeam = \"main\"\n"
                           "[[focal_plane.detectors]]\nname = \"d2\"\nbeam = \"main\"\nzeta_deg = 45\n";
  auto cfg = [&](const std::string& file) {
    return write(file + ".toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n", beam, dets,
                                        "[scan]\ntype = \"file\"\nfile = \"" + file + ".h5\"\n",
                                        "spectra = false\nmaps = false\n"));
  };
  write_detector_pointing(dir_ / "even.h5", {{"d1", 20}, {"d2", 20}});
  const Result ok = run("run " + cfg("even").string());
  ASSERT_EQ(ok.status, 0) << ok.output;
  EXPECT_NE(ok.output.find("2 detectors x 20 samples"), std::string::npos) << ok.output;
  EXPECT_EQ(pisco::read_tod_signal(dir_ / "out" / "tod.h5", "d2").size(), 20u);
  fs::remove_all(dir_ / "out");

  write_detector_pointing(dir_ / "short.h5", {{"d1", 20}, {"d2", 15}});
  expect_error("run " + cfg("short").string(), (dir_ / "short.h5").string() + ": detector 'd2' has 15 samples, detector 'd1' 20");
  write_detector_pointing(dir_ / "long.h5", {{"d1", 20}, {"d2", 21}});
  expect_error("run " + cfg("long").string(), (dir_ / "long.h5").string() + ": detector 'd2' has 21 samples, detector 'd1' 20");
  write_detector_pointing(dir_ / "empty.h5", {{"d1", 0}, {"d2", 20}});
  expect_error("run " + cfg("empty").string(), (dir_ / "empty.h5").string() + ": detector 'd2' has 20 samples, detector 'd1' 0");
}

// A per-detector pointing file gives each detector its own lines of sight; a focal plane that also gives
// a detector an offset from the boresight is contradictory: one error naming the file and the detector,
// a non-zero exit and no output.
TEST_F(Cli, PerDetectorPointingWithOffsetsLeavesNoOutput) {
  write_detector_pointing(dir_ / "ptg.h5", {{"d1", 20}, {"d2", 20}});
  const std::string dets = "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d1\"\nbeam = \"main\"\n"
                           "[[focal_plane.detectors]]\nname = \"d2\"\nbeam = \"main\"\nxi_deg = 1.0\neta_deg = -0.5\n";
  const fs::path c = write("offsets.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                  "[beams.main]\nfwhm_deg = 4\nrho_max_deg = 8\n", dets,
                                                  "[scan]\ntype = \"file\"\nfile = \"ptg.h5\"\n", "spectra = false\n"));
  expect_error("run " + c.string(), (dir_ / "ptg.h5").string() + ": the file gives detector 'd2' its own pointing, but " +
                                        "the focal plane also gives it an offset from the boresight");
}

// The numbers of the [scan] table of a simulation file.
std::map<std::string, double> scan_numbers(const fs::path& file) {
  const toml::table t = toml::parse_file(file.string());
  std::map<std::string, double> out;
  if (const toml::table* scan = t["scan"].as_table())
    for (const auto& [key, value] : *scan)
      if (const auto x = value.value<double>()) out[std::string(key.str())] = *x;
  return out;
}

// 19042 -> "19,042", as README.md writes its figures.
std::string with_commas(std::uint64_t n) {
  std::string s = std::to_string(n);
  for (int i = int(s.size()) - 3; i > 0; i -= 3) s.insert(std::size_t(i), ",");
  return s;
}

// The row of README.md's table of examples for `example` ("| satellite.toml | ... |").
std::string readme_row(const std::string& example) {
  std::ifstream in(fs::path(PISCO_TEST_ASSETS_DIR) / ".." / "README.md");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("| " + example + " |", 0) == 0) return line;
  ADD_FAILURE() << "README.md has no row for " << example;
  return "";
}

// One of the satellite examples run whole (a second or so on two cores) as README.md says a user runs
// it: the figures it prints against what they must be. The samples per detector are duration x rate; the
// hit map is, pixel for pixel, twice the library's boresight scan (a PSB pair without offsets) binned at
// the maps' NSIDE, summing to detectors x samples; the solved pixels it prints are the maps' pixels that
// are not UNSEEN; README.md's row for the example quotes the same numbers. Returns the run's output.
std::string run_satellite_example(const fs::path& dir, const std::string& example) {
  const fs::path cfg = fs::path(PISCO_TEST_ASSETS_DIR) / "examples" / example;
  const fs::path out = dir / "out";
  const Result r = run("run " + cfg.string() + " -o " + out.string() + " --no-plots --backend cpu");
  std::cout << r.output;
  EXPECT_EQ(r.status, 0) << r.output;
  if (r.status != 0) return r.output;

  const auto num = scan_numbers(cfg);
  auto get = [&](const char* key, double fallback) {
    const auto it = num.find(key);
    return it == num.end() ? fallback : it->second;
  };
  pisco::SatelliteScan sat;
  sat.spin_sun_angle = get("spin_sun_angle_deg", 45) * pisco::deg;
  sat.spin_boresight_angle = get("spin_boresight_angle_deg", 50) * pisco::deg;
  sat.precession_period = get("precession_period_min", 192.348) * 60;
  sat.spin_period = get("spin_period_min", 20) * 60;
  sat.sample_rate = get("sample_rate_hz", 19);
  sat.start_time = get("start_time_s", 0);
  sat.precession_phase = get("precession_phase_deg", 0) * pisco::deg;
  sat.spin_phase = get("spin_phase_deg", 0) * pisco::deg;
  sat.samples = std::size_t(std::llround(get("duration_hours", 1) * 3600 * sat.sample_rate));
  const int nside = int(get("nside", 64));
  const std::size_t npix = 12 * std::size_t(nside) * std::size_t(nside);
  const std::size_t samples = 2 * sat.samples;  // one PSB pair

  EXPECT_NE(r.output.find("scan: satellite, 2 detectors x " + std::to_string(sat.samples) + " samples"), std::string::npos);
  EXPECT_NE(r.output.find("summary: " + std::to_string(samples) + " samples"), std::string::npos);
  const std::string maps_line = "maps: NSIDE " + std::to_string(nside) + ", ";
  const std::size_t at = r.output.find(maps_line);
  EXPECT_NE(at, std::string::npos) << r.output;
  if (at == std::string::npos) return r.output;
  std::size_t solved = 0;
  char of[64] = {};
  EXPECT_EQ(std::sscanf(r.output.c_str() + at + maps_line.size(), "%zu of %63s", &solved, of), 2);
  EXPECT_EQ(std::string(of), std::to_string(npix));

  std::vector<pisco::Quat> q;
  sat.generate(0, sat.samples, q);
  std::vector<double> want(npix, 0.0);
  for (const pisco::Quat& b : q) {
    const auto v = pisco::rotate(b, {0, 0, 1});
    want[pisco::ang2pix(nside, std::acos(std::clamp(v[2], -1.0, 1.0)), std::atan2(v[1], v[0]))] += 2;
  }
  const pisco::Sky hits = pisco::Sky::read_fits(out / "hits.fits");
  EXPECT_EQ(hits.nside(), nside);
  if (hits.nside() != nside) return r.output;
  std::size_t hit = 0, differ = 0;
  double sum = 0;
  for (std::size_t p = 0; p < npix; ++p) {
    sum += hits.I()[p];
    hit += hits.I()[p] > 0;
    differ += hits.I()[p] != want[p];
  }
  EXPECT_EQ(sum, double(samples));
  EXPECT_EQ(differ, 0u) << "pixels whose hits are not the library scan's";
  const pisco::Sky maps = pisco::Sky::read_fits(out / "maps.fits", pisco::UnseenPolicy::flag);
  const std::size_t seen = npix - std::size_t(std::count_if(maps.I().begin(), maps.I().end(), pisco::is_unseen));
  EXPECT_EQ(seen, solved);
  EXPECT_LE(solved, hit);
  std::cout << example << ": " << sat.samples << " samples per detector, " << hit << " pixels hit, " << solved
            << " solved of " << npix << "\n";

  const std::string row = readme_row(example);
  EXPECT_NE(row.find(with_commas(solved) + " "), std::string::npos) << "README.md: " << row;
  if (example == "satellite.toml") {
    EXPECT_NE(row.find(with_commas(sat.samples) + " samples per detector"), std::string::npos) << "README.md: " << row;
    EXPECT_NE(row.find(with_commas(solved) + " of " + with_commas(npix) + " NSIDE " + std::to_string(nside)),
              std::string::npos)
        << "README.md: " << row;
  }
  return r.output;
}

// assets/examples/satellite.toml, whole: the README's figures.
TEST_F(Cli, SatelliteExampleAsTheReadmeSays) { run_satellite_example(dir_, "satellite.toml"); }

// assets/examples/grasp_beam.toml, whole: the README's figures; the GRASP beam is turned for the pair's
// B detector (zeta -90 deg), and both detectors' beamsors are described in the log.
TEST_F(Cli, GraspBeamExampleAsTheReadmeSays) {
  const std::string output = run_satellite_example(dir_, "grasp_beam.toml");
  EXPECT_NE(output.find("beam horn for zeta 0 deg: GRASP uv grid"), std::string::npos) << output;
  EXPECT_NE(output.find("beam horn for zeta -90 deg: GRASP uv grid"), std::string::npos) << output;
  EXPECT_NE(output.find("turned by -90 deg"), std::string::npos) << output;
}

// assets/examples/deconvolve.toml, whole, as README.md says a user runs it: the deconvolving
// map-maker's iterations, and its figure: the rms polarization the pair's beam mismatch leaks into
// the maps, binned against deconvolved (reconvolved to the target beam), as README.md quotes it.
TEST_F(Cli, DeconvolveExampleAsTheReadmeSays) {
  const fs::path cfg = fs::path(PISCO_TEST_ASSETS_DIR) / "examples" / "deconvolve.toml";
  const fs::path out = dir_ / "out";
  const Result r = run("run " + cfg.string() + " -o " + out.string() + " --no-plots");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("mapmaker: iteration 30, residual"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("mapmaker: converged after "), std::string::npos) << r.output;
  const pisco::Sky binned = pisco::Sky::read_fits(out / "binned_maps.fits", pisco::UnseenPolicy::flag);
  const pisco::Sky maps = pisco::Sky::read_fits(out / "maps.fits", pisco::UnseenPolicy::flag);
  const auto rms_p = [](const pisco::Sky& m) {
    double s = 0;
    for (std::size_t p = 0; p < m.npix(); ++p) s += m.Q()[p] * m.Q()[p] + m.U()[p] * m.U()[p];
    return std::sqrt(s / double(m.npix()));
  };
  const double ratio = rms_p(binned) / rms_p(maps);
  std::cout << "rms P binned " << rms_p(binned) << ", deconvolved " << rms_p(maps) << ": " << ratio << "x\n";
  EXPECT_GT(ratio, 5.0);
  const std::string quoted = std::to_string(int(ratio)) + "x below";
  EXPECT_NE(readme_row("deconvolve.toml").find(quoted), std::string::npos) << quoted;
}

// rms P / rms I (mean removed) over the solved pixels of a run's maps.fits.
double polarization_figure(const fs::path& maps_file) {
  const pisco::Sky maps = pisco::Sky::read_fits(maps_file, pisco::UnseenPolicy::flag);
  double mean = 0, ii = 0, pp = 0;
  std::size_t n = 0;
  for (std::size_t p = 0; p < maps.npix(); ++p)
    if (!pisco::is_unseen(maps.I()[p])) {
      mean += maps.I()[p];
      ++n;
    }
  mean /= double(n);
  for (std::size_t p = 0; p < maps.npix(); ++p)
    if (!pisco::is_unseen(maps.I()[p])) {
      ii += (maps.I()[p] - mean) * (maps.I()[p] - mean);
      pp += maps.Q()[p] * maps.Q()[p] + maps.U()[p] * maps.U()[p];
    }
  return std::sqrt(pp / ii);
}

// assets/examples/beam_drift.toml, whole, as README.md says a user runs it: the README's figures; on
// its unpolarized sky the maps' polarization is the drifting beam's leakage, as README.md quotes it
// (two digits, within 2%), and it is zero to rounding when the B detector's beam is held round.
TEST_F(Cli, BeamDriftExampleAsTheReadmeSays) {
  run_satellite_example(dir_, "beam_drift.toml");
  const double drift = polarization_figure(dir_ / "out" / "maps.fits");
  const std::string row = readme_row("beam_drift.toml"), key = "rms P / rms I = ";
  ASSERT_NE(row.find(key), std::string::npos) << row;
  const double quoted = std::stod(row.substr(row.find(key) + key.size()));
  EXPECT_NEAR(drift, quoted, 0.02 * quoted) << "README.md quotes " << quoted;
  std::ifstream in(fs::path(PISCO_TEST_ASSETS_DIR) / "examples" / "beam_drift.toml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string from = "beam_b = \"drift\"";
  ASSERT_NE(text.find(from), std::string::npos);
  text.replace(text.find(from), from.size(), "beam_b = \"round\"");
  const fs::path held = dir_ / "held.toml";
  std::ofstream(held) << text;
  const Result r = run("run " + held.string() + " -o " + (dir_ / "held").string() + " --no-plots --backend cpu -q");
  ASSERT_EQ(r.status, 0) << r.output;
  const double round = polarization_figure(dir_ / "held" / "maps.fits");
  std::cout << "beam_drift.toml: rms P / rms I = " << drift << " drifting, " << round << " held round\n";
  EXPECT_LT(round, 1e-12);
  EXPECT_GT(drift, 1e-2);
}

// assets/examples/ground_pickup.toml, whole (docs/ground.md): the ground's pickup and what it leaves in
// the maps, as README.md quotes them (to 1%), and the files of the ground's own maps and spectra.
TEST_F(Cli, GroundExampleAsTheReadmeSays) {
  const fs::path cfg = fs::path(PISCO_TEST_ASSETS_DIR) / "examples" / "ground_pickup.toml";
  const Result r = run("run " + cfg.string() + " -o " + (dir_ / "out").string() + " --no-plots --backend simd");
  std::cout << r.output;
  if (r.status != 0 && r.output.find("simd") != std::string::npos && r.output.find("not available") != std::string::npos)
    GTEST_SKIP() << "no simd backend here";
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "out" / "ground_maps.fits"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "ground_spectra.txt"));
  const std::string row = readme_row("ground_pickup.toml");
  const auto figure = [](const std::string& text, const std::string& key) {
    const std::size_t at = text.find(key);
    return at == std::string::npos ? std::nan("") : std::stod(text.substr(at + key.size()));
  };
  for (const auto& [printed, quoted] : std::vector<std::pair<std::string, std::string>>{
           {"picked up through the beams: mean ", "picked up: mean "},
           {"scan-synchronous rms ", "scan-synchronous rms "},
           {"rms I about it ", "rms I about their mean "},
           {"rms P ", "rms P "}}) {
    const double got = figure(r.output, printed), said = figure(row, quoted);
    ASSERT_TRUE(std::isfinite(got)) << printed << "\n" << r.output;
    ASSERT_TRUE(std::isfinite(said)) << quoted << "\n" << row;
    EXPECT_NEAR(got, said, 0.01 * said) << printed << ": README.md quotes " << said;
  }
}

// assets/examples/hwp_satellite.toml, whole: the README's figures, and its leakage figure as README.md
// and docs/validation.md (H4) quote it, to two digits.
TEST_F(Cli, HwpSatelliteExampleAsTheReadmeSays) {
  const std::string output = run_satellite_example(dir_, "hwp_satellite.toml");
  const std::string key = "leakage figure rms P / rms I = ";
  const std::size_t at = output.find(key);
  ASSERT_NE(at, std::string::npos) << output;
  const double leakage = std::stod(output.substr(at + key.size()));
  ASSERT_GT(leakage, 0.0);
  const int e = int(std::floor(std::log10(leakage)));
  char quoted[32];
  std::snprintf(quoted, sizeof quoted, "rms P / rms I = %.1fe%d", leakage / std::pow(10.0, e), e);
  EXPECT_NE(readme_row("hwp_satellite.toml").find(quoted), std::string::npos) << quoted;
  std::ifstream v(fs::path(PISCO_TEST_ASSETS_DIR) / ".." / "docs" / "validation.md");
  const std::string validation((std::istreambuf_iterator<char>(v)), std::istreambuf_iterator<char>());
  EXPECT_NE(validation.find(quoted), std::string::npos) << "docs/validation.md, H4: " << quoted;
}

}  // namespace
