// pisco::Simulation (simulation.hpp; docs/library.md): a simulation file run through the library writes
// the same TOD file, maps and spectra as `pisco-vk run`, bit for bit; and its parts (read_simulation_file,
// make_sky, make_beams, make_engine, write_maps, write_spectra) work one by one.
#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <set>
#include <span>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include "pisco/pisco.hpp"
#include "pisco/simulation.hpp"
#include "support.hpp"
#include "beams/beam_kind.hpp"
#include "pipeline/mapmaker_kind.hpp"

#include <healpix_base.h>
#include <iomanip>
#include <sstream>

namespace {

namespace fs = std::filesystem;

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// A log of what a run said, with its steps counted.
class Recorder final : public pisco::RunObserver {
 public:
  void log(const std::string& line) override { lines += line; }
  void begin_convolution(std::uint64_t samples) override { expected = samples; ++begun; }
  void advance(std::uint64_t samples) override { done += samples; }
  void end_convolution() override { ++ended; }
  std::string lines;
  std::uint64_t expected = 0, done = 0;
  int begun = 0, ended = 0;
};

// The one-process context, its steps counted.
class CountingContext final : public pisco::RunContext {
 public:
  void step(const std::function<void()>& f) override {
    ++steps;
    f();
  }
  int steps = 0;
};

class SimulationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("simulation");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A small simulation: a synthesized sky, a Gaussian and an elliptical beam, a pair and a detector
  // with an offset and a half-wave plate, pixel centres at three angles; the TOD with pointing and
  // weights.
  fs::path write_config(const std::string& extra_output = "") {
    const fs::path p = dir_ / "sim.toml";
    std::ofstream(p) << "[sky]\nnside = 32\nlmax = 64\nseed = 3\n"
                        "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n"
                        "[beams.ell]\ntype = \"elliptical\"\nfwhm_x_deg = 3.5\nfwhm_y_deg = 4.5\nangle_deg = 20\n"
                        "rho_max_deg = 8.0\n"
                        "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
                        "[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"ell\"\nzeta_deg = 30\nxi_deg = 1\n"
                        "eta_deg = -0.5\ngamma_deg = 10\n"
                        "[scan]\ntype = \"pixel_centres\"\nnside = 16\n"
                        "[hwp]\nrpm = 60\nsample_rate_hz = 10\n"
                        "[engine]\nbackend = \"cpu\"\nchunk_samples = 1000\n"
                        "[output]\ndir = \""
                     << (dir_ / "out").string() << "\"\nplots = false\nlmax = 32\ntod_pointing = true\ntod_weights = true\n"
                     << extra_output;
    return p;
  }

  fs::path dir_;
};

int run_cli(const std::string& args) {
  const std::string cmd = std::string(PISCO_VK_EXE) + " " + args + " > /dev/null 2>&1";
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// [[sources]] (docs/sources.md): a polarized source at a pixel's centre adds to the TOD what that
// pixel of a [sky] point_source gives (plain quadrature, the float64 reference), for a detector with an
// offset and a plate; a moving source on a scan without times is refused, naming the key.
TEST_F(SimulationTest, SourcesAddWhatTheirPixelWould) {
  const int nside = 32;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const pointing at = base.pix2ang(base.ang2pix(pointing(1.0, 2.0)));
  const double area = 4 * std::numbers::pi / double(base.Npix()), deg = std::numbers::pi / 180;
  const double th = at.theta / deg, ph = at.phi / deg;
  const auto config = [&](const std::string& name, const std::string& sky, const std::string& sources,
                          const std::string& scan) {
    const fs::path p = dir_ / (name + ".toml");
    std::ofstream(p) << std::setprecision(17) << "[sky]\nnside = 32\n" << sky
                     << "[beams.main]\ntype = \"elliptical\"\nfwhm_x_deg = 3.5\nfwhm_y_deg = 4.5\nangle_deg = 20\n"
                        "rho_max_deg = 8.0\n"
                        "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"main\"\nzeta_deg = 30\n"
                        "xi_deg = 1\neta_deg = -0.5\ngamma_deg = 10\n"
                     << scan
                     << "[hwp]\nrpm = 60\nsample_rate_hz = 10\n"
                        "[engine]\nbackend = \"cpu\"\nquadrature = \"plain\"\n"
                        "[output]\ndir = \""
                     << (dir_ / name).string() << "\"\nmaps = false\nspectra = false\nplots = false\n"
                     << sources;
    return p;
  };
  const std::string scan = "[scan]\ntype = \"raster\"\nnside = 64\ntheta_deg = 57\nphi_deg = 115\nradius_deg = 12\n";
  const fs::path with_pixel = config("pixel", "point_source = [" + std::to_string(th) + ", " + std::to_string(ph) +
                                                  ", 2.0, 0.3, -0.5, 0.1]\n", "", scan);
  std::ostringstream src;
  src << std::setprecision(17) << "[[sources]]\nname = \"s\"\ntheta_deg = " << th << "\nphi_deg = " << ph
      << "\nI = " << 2.0 * area << "\nQ = " << 0.3 * area << "\nU = " << -0.5 * area << "\nV = " << 0.1 * area << "\n";
  const fs::path with_source =
      config("source", "point_source = [" + std::to_string(th) + ", " + std::to_string(ph) + ", 0, 0, 0, 0]\n",
             src.str(), scan);
  pisco::Simulation::from_file(with_pixel).run();
  pisco::Simulation::from_file(with_source).run();
  const std::vector<double> a = pisco::read_tod_signal(dir_ / "pixel" / "tod.h5", "d");
  const std::vector<double> b = pisco::read_tod_signal(dir_ / "source" / "tod.h5", "d");
  ASSERT_EQ(a.size(), b.size());
  double peak = 0.0, worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    peak = std::max(peak, std::abs(a[i]));
    worst = std::max(worst, std::abs(a[i] - b[i]));
  }
  EXPECT_GT(peak, 0.0);
  EXPECT_LE(worst, 1e-12 * peak);

  const fs::path moving = config("moving", "", "[[sources]]\nname = \"jupiter\"\ntime_s = [0, 10]\ntheta_deg = [50, 51]\n"
                                               "phi_deg = [100, 100]\nI = [1e-5, 1e-5]\n", scan);
  try {
    (void)pisco::read_simulation_file(moving);
    FAIL() << "a moving source without times";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("[sources[0]] time_s: a moving source needs the samples' times"), std::string::npos)
        << e.what();
  }
}

// A source's track from a CSV track file ([[sources]] file, docs/formats.md "Source tracks") adds the
// same TOD as the same track written in the table, on a constant-elevation scan that crosses it; a
// table that gives both the file and a track's key is refused naming the key.
TEST_F(SimulationTest, SourceTracksFromFilesAreTheTablesOwn) {
  const auto config = [&](const std::string& name, const std::string& sources) {
    const fs::path p = dir_ / (name + ".toml");
    std::ofstream(p) << "[sky]\nnside = 16\n"
                        "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 3.0\nrho_max_deg = 6.0\n"
                        "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"main\"\nzeta_deg = 30\n"
                        "[scan]\ntype = \"ces\"\nsample_rate_hz = 2\nduration_hours = 0.05\naz_throw_deg = 30\nnside = 8\n"
                        "[engine]\nbackend = \"cpu\"\nnormalization = \"integral\"\n"
                        "[output]\ndir = \""
                     << (dir_ / name).string() << "\"\nmaps = false\nspectra = false\nplots = false\n" << sources;
    return p;
  };
  // The scan's boresight at its first sample, and a source drifting across the scan's path from there.
  pisco::Simulation probe = pisco::Simulation::from_file(config("probe", ""));
  pisco::Pointing first;
  probe.config().scan.ces.generate(0, 1, first);
  const double deg = std::numbers::pi / 180, th = first.theta[0] / deg, ph = first.phi[0] / deg;
  std::ostringstream table, csv;
  table << std::setprecision(17) << "[[sources]]\nname = \"planet\"\ntime_s = [0, 100, 180]\ntheta_deg = [" << th
        << ", " << th + 1 << ", " << th + 1.5 << "]\nphi_deg = [" << ph << ", " << ph + 2 << ", " << ph + 3
        << "]\nI = [1e-3, 1.2e-3, 1e-3]\nU = [0, 1e-4, 2e-4]\n";
  csv << std::setprecision(17) << "# a planet\ntime_s,theta_deg,phi_deg,I,U\n0," << th << "," << ph << ",1e-3,0\n100,"
      << th + 1 << "," << ph + 2 << ",1.2e-3,1e-4\n180," << th + 1.5 << "," << ph + 3 << ",1e-3,2e-4\n";
  std::ofstream(dir_ / "planet.csv") << csv.str();
  pisco::Simulation::from_file(config("table", table.str())).run();
  pisco::Simulation::from_file(config("file", "[[sources]]\nname = \"planet\"\nfile = \"planet.csv\"\n")).run();
  pisco::Simulation::from_file(config("none", "")).run();
  const std::vector<double> a = pisco::read_tod_signal(dir_ / "table" / "tod.h5", "d");
  const std::vector<double> b = pisco::read_tod_signal(dir_ / "file" / "tod.h5", "d");
  const std::vector<double> c = pisco::read_tod_signal(dir_ / "none" / "tod.h5", "d");
  ASSERT_EQ(a.size(), 360u);
  ASSERT_EQ(b.size(), a.size());
  double seen = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i], b[i]) << "sample " << i;
    seen = std::max(seen, std::abs(a[i] - c[i]));
  }
  EXPECT_GT(seen, 1e-4);  // the scan does cross the source

  try {
    (void)pisco::read_simulation_file(
        config("both", "[[sources]]\nname = \"planet\"\nfile = \"planet.csv\"\nI = 1\n"));
    FAIL() << "a file and a key of the track";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("[sources[0]] I: a source read from a track file (file) takes name and file only"),
              std::string::npos)
        << e.what();
  }
}

// A beam that changes with time ([beams.NAME] type = "sequence", docs/beams.md): a detector whose beam
// drifts from "round" at 0 s to "oval" at the run's end has, at each sample, the two beams' TOD
// (detectors of their own beside it, with the same angle and offset) linearly interpolated in the
// sample's time i / the scan's rate; the file's mistakes are refused naming the table and key.
TEST_F(SimulationTest, BeamsThatChangeWithTimeAreInterpolated) {
  const auto config = [&](const std::string& name, const std::string& drift, const std::string& scan) {
    const fs::path p = dir_ / (name + ".toml");
    const std::string det = "zeta_deg = 30\nxi_deg = 1\neta_deg = -0.5\ngamma_deg = 10\n";
    std::ofstream(p) << "[sky]\nnside = 32\nlmax = 64\nseed = 3\n"
                        "[beams.round]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n"
                        "[beams.oval]\ntype = \"elliptical\"\nfwhm_x_deg = 3.5\nfwhm_y_deg = 4.5\nangle_deg = 20\n"
                        "rho_max_deg = 8.0\n"
                     << drift
                     << "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"drift\"\n" << det
                     << "[[focal_plane.detectors]]\nname = \"r\"\nbeam = \"round\"\n" << det
                     << "[[focal_plane.detectors]]\nname = \"o\"\nbeam = \"oval\"\n" << det << scan
                     << "[engine]\nbackend = \"cpu\"\nchunk_samples = 50\n"
                        "[output]\ndir = \""
                     << (dir_ / name).string() << "\"\nmaps = false\nspectra = false\nplots = false\n";
    return p;
  };
  // 144 samples at 2 Hz: the nodes at 0 and 71.5 s, the run's first and last samples.
  const std::string ces = "[scan]\ntype = \"ces\"\nsample_rate_hz = 2\nduration_hours = 0.02\naz_throw_deg = 40\nnside = 8\n";
  const std::string drift = "[beams.drift]\ntype = \"sequence\"\ntimes_s = [0, 71.5]\nbeams = [\"round\", \"oval\"]\n";
  pisco::Simulation::from_file(config("drift", drift, ces)).run();
  const fs::path tod = dir_ / "drift" / "tod.h5";
  const std::vector<double> d = pisco::read_tod_signal(tod, "d"), r = pisco::read_tod_signal(tod, "r"),
                            o = pisco::read_tod_signal(tod, "o");
  ASSERT_EQ(d.size(), 144u);
  double worst = 0, rms = 0, apart = 0;
  for (std::size_t i = 0; i < d.size(); ++i) {
    const double w = double(i) / 2.0 / 71.5;
    worst = std::max(worst, std::abs(d[i] - ((1 - w) * r[i] + w * o[i])));
    apart = std::max(apart, std::abs(r[i] - o[i]));
    rms += d[i] * d[i];
  }
  rms = std::sqrt(rms / double(d.size()));
  EXPECT_LE(worst, 1e-12 * rms);
  EXPECT_GT(apart, 1e-3 * rms);  // the two beams do differ
  EXPECT_EQ(d.front(), r.front());
  EXPECT_EQ(d.back(), o.back());

  const auto refused = [&](const std::string& name, const std::string& drift_table, const std::string& scan) {
    try {
      (void)pisco::read_simulation_file(config(name, drift_table, scan));
    } catch (const pisco::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(refused("unknown", "[beams.drift]\ntype = \"sequence\"\ntimes_s = [0, 10]\nbeams = [\"round\", \"ovl\"]\n", ces)
                .find("[beams.drift] beams: beam 1 is \"ovl\", which is not a [beams] table (expected one of: oval, round)"),
            std::string::npos);
  EXPECT_NE(refused("nested", "[beams.drift]\ntype = \"sequence\"\ntimes_s = [0, 10]\nbeams = [\"round\", \"drift\"]\n", ces)
                .find("beam 1 is \"drift\", itself a beam that changes with time"),
            std::string::npos);
  EXPECT_NE(refused("order", "[beams.drift]\ntype = \"sequence\"\ntimes_s = [10, 0]\nbeams = [\"round\", \"oval\"]\n", ces)
                .find("[beams.drift] times_s: time 1 (0 s) is not after time 0 (10 s)"),
            std::string::npos);
  EXPECT_NE(refused("count", "[beams.drift]\ntype = \"sequence\"\ntimes_s = [0]\nbeams = [\"round\", \"oval\"]\n", ces)
                .find("times_s: expected one time (seconds from the run's first sample) for each of the 2 beams, got 1"),
            std::string::npos);
  EXPECT_NE(refused("extra", "[beams.drift]\ntype = \"sequence\"\ntimes_s = [0, 1]\nbeams = [\"round\", \"oval\"]\n"
                             "fwhm_deg = 2\n", ces)
                .find("unknown key 'fwhm_deg'"),
            std::string::npos);
  EXPECT_NE(refused("timeless", drift, "[scan]\ntype = \"pixel_centres\"\nnside = 8\n")
                .find("[beams.drift] type: a beam that changes with time needs each sample's time: a ces or satellite "
                      "scan"),
            std::string::npos);
  // A run longer than the sequence: the first sample past its last node is named (by its index in
  // its chunk, and its time), and no output is left.
  const std::string short_drift = "[beams.drift]\ntype = \"sequence\"\ntimes_s = [0, 30]\nbeams = [\"round\", \"oval\"]\n";
  try {
    pisco::Simulation::from_file(config("short", short_drift, ces)).run();
    FAIL() << "samples past the sequence's last node";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("is at time 30.5 s, outside its beam_sequence's nodes (0 to 30 s)"),
              std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "short" / "tod.h5"));
}

// A beam that turns with the half-wave plate ([beams.NAME] type = "plate", docs/changing.md): a
// detector whose beams at four plate angles over 180 deg alternate between a round and an elliptical
// beam has, at each sample, their trigonometric interpolant in the plate's angle ([hwp]'s stream, from
// the detector's own plate gamma): against the two beams' TOD on detectors without a plate in the same
// run, combined with the interpolant's weights and each beam's Omega~ over their mean. The file's
// mistakes are refused naming the table and key.
TEST_F(SimulationTest, BeamsThatTurnWithThePlateAreInterpolated) {
  const auto config = [&](const std::string& name, const std::string& plate, const std::string& hwp) {
    const fs::path p = dir_ / (name + ".toml");
    const std::string det = "zeta_deg = 30\nxi_deg = 1\neta_deg = -0.5\ngamma_deg = 10\n";
    std::ofstream(p) << "[sky]\nnside = 32\nlmax = 64\nseed = 3\n"
                        "[beams.round]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n"
                        "[beams.oval]\ntype = \"elliptical\"\nfwhm_x_deg = 3.5\nfwhm_y_deg = 4.5\nangle_deg = 20\n"
                        "rho_max_deg = 8.0\n"
                     << plate
                     << "[focal_plane]\n[[focal_plane.detectors]]\nname = \"t\"\nbeam = \"turning\"\n" << det
                     << "[[focal_plane.detectors]]\nname = \"r\"\nbeam = \"round\"\nhwp = false\n" << det
                     << "[[focal_plane.detectors]]\nname = \"o\"\nbeam = \"oval\"\nhwp = false\n" << det
                     << "[scan]\ntype = \"ces\"\nsample_rate_hz = 2\nduration_hours = 0.02\naz_throw_deg = 40\nnside = 8\n"
                     << hwp << "[engine]\nbackend = \"cpu\"\nchunk_samples = 50\n"
                        "[output]\ndir = \""
                     << (dir_ / name).string() << "\"\nmaps = false\nspectra = false\nplots = false\n";
    return p;
  };
  const std::string plate = "[beams.turning]\ntype = \"plate\"\nbeams = [\"round\", \"oval\", \"round\", \"oval\"]\n";
  const std::string hwp = "[hwp]\nfrequency_hz = 0.13\n";
  const fs::path file = config("plate", plate, hwp);
  pisco::Simulation::from_file(file).run();
  const fs::path tod = dir_ / "plate" / "tod.h5";
  const std::vector<double> t = pisco::read_tod_signal(tod, "t"), r = pisco::read_tod_signal(tod, "r"),
                            o = pisco::read_tod_signal(tod, "o");
  const pisco::SimulationConfig c = pisco::read_simulation_file(file);
  const pisco::SimulationBeams made = pisco::make_beams(c);
  ASSERT_TRUE(made.detectors[0].plate_beams.has_value());
  EXPECT_FALSE(made.detectors[0].hwp.has_value());  // the plate is in the beams
  const double gamma = made.detectors[0].plate_beams->gamma;
  EXPECT_NEAR(gamma, pisco::default_hwp_gamma(c.detectors[0]), 1e-15);
  const double omega_r = made.beams[made.detectors[1].beam].omega_tilde(),
               omega_o = made.beams[made.detectors[2].beam].omega_tilde(), mean = (omega_r + omega_o) / 2;
  std::vector<double> angle;
  c.hwp.stream.generate(0, t.size(), angle);
  double worst = 0, rms = 0, apart = 0;
  for (std::size_t i = 0; i < t.size(); ++i) {
    // Four points over the period: weights (1 + 2 cos u + cos 2u) / 4 at u = x - k pi / 2.
    const double x = 2 * (angle[i] - gamma);
    double want = 0;
    for (int k = 0; k < 4; ++k) {
      const double u = x - k * std::numbers::pi / 2;
      const double w = (1 + 2 * std::cos(u) + std::cos(2 * u)) / 4;
      want += w * (k % 2 ? o[i] * omega_o : r[i] * omega_r) / mean;
    }
    worst = std::max(worst, std::abs(t[i] - want));
    apart = std::max(apart, std::abs(r[i] - o[i]));
    rms += t[i] * t[i];
  }
  rms = std::sqrt(rms / double(t.size()));
  EXPECT_LE(worst, 1e-12 * rms);
  EXPECT_GT(apart, 1e-3 * rms);

  // normalize_by: the plate beams over one beam's Omega~ (the beam without the plate, keeping the plate's
  // losses) instead of their mean: the same TOD times mean / Omega~(oval).
  pisco::Simulation::from_file(config("normalized", plate + "normalize_by = \"oval\"\n", hwp)).run();
  const std::vector<double> tn = pisco::read_tod_signal(dir_ / "normalized" / "tod.h5", "t");
  ASSERT_EQ(tn.size(), t.size());
  double off = 0;
  for (std::size_t i = 0; i < t.size(); ++i) off = std::max(off, std::abs(tn[i] - t[i] * mean / omega_o));
  EXPECT_LE(off, 1e-12 * rms);
  EXPECT_GT(std::abs(mean / omega_o - 1), 1e-3);  // the two normalizations differ

  const auto refused = [&](const std::string& name, const std::string& plate_table, const std::string& hwp_table) {
    try {
      (void)pisco::read_simulation_file(config(name, plate_table, hwp_table));
    } catch (const pisco::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(refused("no_hwp", plate, "").find("[beams.turning] type: a beam that turns with the plate needs the plate's "
                                              "angles: an [hwp] table"),
            std::string::npos);
  EXPECT_NE(refused("one", "[beams.turning]\ntype = \"plate\"\nbeams = [\"round\"]\n", hwp)
                .find("[beams.turning] beams: a beam that turns with the plate needs two or more beams"),
            std::string::npos);
  EXPECT_NE(refused("period", "[beams.turning]\ntype = \"plate\"\nbeams = [\"round\", \"oval\"]\nperiod_deg = 0\n", hwp)
                .find("[beams.turning] period_deg: expected a period in (0, 720] deg"),
            std::string::npos);
  EXPECT_NE(refused("nested",
                    "[beams.turning]\ntype = \"plate\"\nbeams = [\"round\", \"turning\"]\n", hwp)
                .find("beam 1 is \"turning\", itself a beam that turns with the plate"),
            std::string::npos);
  EXPECT_NE(refused("norm", plate + "normalize_by = \"nowhere\"\n", hwp)
                .find("[beams.turning] normalize_by: \"nowhere\" is not a [beams] table of a fixed beam"),
            std::string::npos);
  EXPECT_NE(refused("norm_self", plate + "normalize_by = \"turning\"\n", hwp)
                .find("[beams.turning] normalize_by: \"turning\" is not a [beams] table of a fixed beam"),
            std::string::npos);
}

TEST_F(SimulationTest, WritesWhatTheCommandLineWrites) {
  const fs::path file = write_config();
  const fs::path cli_dir = dir_ / "cli", lib_dir = dir_ / "lib";
  ASSERT_EQ(run_cli("run " + file.string() + " -q --no-plots -o " + cli_dir.string()), 0);

  pisco::Simulation sim = pisco::Simulation::from_file(file);
  sim.config().output.dir = lib_dir;
  Recorder recorder;
  const pisco::SimulationResult r = sim.run(&recorder);

  const std::size_t n = 12 * 16 * 16 * 3;
  EXPECT_EQ(r.detectors, 3u);
  EXPECT_EQ(r.samples_per_detector, n);
  EXPECT_EQ(r.samples, 3 * n);
  EXPECT_EQ(r.backend, "cpu");
  EXPECT_EQ(r.solved_pixels, 12u * 16 * 16);
  EXPECT_TRUE(r.nothing_solved.empty());
  EXPECT_GT(r.mean_disc_pixels, 0.0);
  EXPECT_EQ(r.tod_file, lib_dir / "tod.h5");
  const std::vector<fs::path> expected{lib_dir / "tod.h5", lib_dir / "maps.fits", lib_dir / "hits.fits",
                                       lib_dir / "spectra.txt", lib_dir / "input_spectra.txt"};
  EXPECT_EQ(r.written, expected);
  // The account pisco-vk prints, line by line, and the progress of every sample.
  EXPECT_NE(recorder.lines.find("sky: NSIDE 32, synthesized from "), std::string::npos) << recorder.lines;
  EXPECT_NE(recorder.lines.find("beam main: Gaussian FWHM 4 deg, rho_max 8 deg"), std::string::npos) << recorder.lines;
  EXPECT_NE(recorder.lines.find("backend: cpu ("), std::string::npos) << recorder.lines;
  EXPECT_NE(recorder.lines.find("scan: pixel_centres, 3 detectors x 9216 samples\n"), std::string::npos) << recorder.lines;
  EXPECT_NE(recorder.lines.find("maps: NSIDE 16, 3072 of 3072 pixels solved (rcond >= 0.001)\n"), std::string::npos)
      << recorder.lines;
  EXPECT_NE(recorder.lines.find("hwp: maps' rms Q "), std::string::npos) << recorder.lines;
  EXPECT_EQ(recorder.begun, 1);
  EXPECT_EQ(recorder.ended, 1);
  EXPECT_EQ(recorder.expected, 3 * n);
  EXPECT_EQ(recorder.done, 3 * n);

  // Maps and spectra: the same bytes.
  for (const char* name : {"maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"}) {
    ASSERT_TRUE(fs::exists(cli_dir / name)) << name;
    EXPECT_TRUE(read_bytes(cli_dir / name) == read_bytes(lib_dir / name)) << name << " differs";
  }
  // The TOD file: the same attributes but for the time it was created, the same detectors, and the same
  // samples, pointing and weights, bit for bit (the file's bytes differ by HDF5's object times too).
  const auto cli_attributes = pisco::read_tod_attributes(cli_dir / "tod.h5");
  const auto lib_attributes = pisco::read_tod_attributes(lib_dir / "tod.h5");
  ASSERT_EQ(cli_attributes.size(), lib_attributes.size());
  for (const auto& [key, value] : cli_attributes)
    if (key != "created") EXPECT_EQ(lib_attributes.at(key), value) << key;
  const auto detectors = pisco::read_tod_detectors(lib_dir / "tod.h5");
  ASSERT_EQ(detectors.size(), 3u);
  ASSERT_EQ(pisco::read_tod_detectors(cli_dir / "tod.h5").size(), 3u);
  for (const auto& d : detectors) {
    const std::vector<double> tod = pisco::read_tod_signal(lib_dir / "tod.h5", d.name);
    EXPECT_EQ(tod.size(), n);
    EXPECT_TRUE(tod == pisco::read_tod_signal(cli_dir / "tod.h5", d.name)) << d.name;
    EXPECT_TRUE(pisco::read_tod_weights(lib_dir / "tod.h5", d.name) == pisco::read_tod_weights(cli_dir / "tod.h5", d.name))
        << d.name;
    const std::vector<pisco::Quat> a = pisco::read_tod_quats(lib_dir / "tod.h5", d.name),
                                   b = pisco::read_tod_quats(cli_dir / "tod.h5", d.name);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_TRUE(std::memcmp(a.data(), b.data(), a.size() * sizeof(pisco::Quat)) == 0) << d.name;
  }
}

// The stream's host work on the process's threads (the scan generated in blocks, the map-maker's
// quaternions, binning from the boresight or, with the TOD's pointing written, the detectors' angles)
// gives the same files bit for bit on one thread and on three: constant-elevation and satellite scans,
// offsets, a plate, chunks of 20,000 samples.
TEST_F(SimulationTest, HostThreadsGiveTheSameBits) {
  const std::string scans[] = {
      "[scan]\ntype = \"ces\"\nlatitude_deg = -22.96\nlongitude_deg = -67.79\nelevation_deg = 45.0\n"
      "az_centre_deg = 180.0\naz_throw_deg = 90.0\naz_speed_deg_s = 1.0\nsample_rate_hz = 20.0\n"
      "start = \"2019-06-01T00:00:00Z\"\nduration_hours = 1.0\nnside = 16\n",
      "[scan]\ntype = \"satellite\"\nspin_sun_angle_deg = 45.0\nspin_boresight_angle_deg = 50.0\n"
      "precession_period_min = 9.6174\nspin_period_min = 1.0\nsample_rate_hz = 19.0\nduration_hours = 1.0\nnside = 16\n"};
  for (const std::string& scan : scans)
    for (const bool tod_pointing : {false, true}) {
      std::array<fs::path, 2> out;
      for (int k = 0; k < 2; ++k) {
        out[k] = dir_ / ("out" + std::to_string(k));
        fs::remove_all(out[k]);
        const fs::path p = dir_ / "threads.toml";
        std::ofstream(p) << "[sky]\nnside = 32\nlmax = 64\nseed = 3\n"
                            "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 6.0\n"
                            "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\nxi_deg = 2\n"
                            "[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"main\"\nzeta_deg = 30\nxi_deg = -1\n"
                            "eta_deg = 1.5\ngamma_deg = 10\n"
                         << scan << "[hwp]\nrpm = 60\nsample_rate_hz = " << (scan.find("ces") != std::string::npos ? "20" : "19")
                         << "\n[engine]\nbackend = \"simd\"\nchunk_samples = 20000\nthreads = " << (k == 0 ? 1 : 3)
                         << "\n[output]\ndir = \"" << out[k].string() << "\"\nplots = false\nspectra = false\n"
                         << "tod_pointing = " << (tod_pointing ? "true" : "false") << "\n";
        pisco::Simulation sim = pisco::Simulation::from_file(p);
        const pisco::SimulationResult r = sim.run();
        ASSERT_GT(r.solved_pixels, 20u);
        ASSERT_GT(r.samples_per_detector, 60000u);
      }
      for (const char* name : {"maps.fits", "hits.fits"})
        EXPECT_TRUE(read_bytes(out[0] / name) == read_bytes(out[1] / name))
            << name << " differs between one and three threads (" << scan.substr(0, 25) << ", tod_pointing "
            << tod_pointing << ")";
      for (const auto& d : pisco::read_tod_detectors(out[0] / "tod.h5"))
        EXPECT_TRUE(pisco::read_tod_signal(out[0] / "tod.h5", d.name) == pisco::read_tod_signal(out[1] / "tod.h5", d.name))
            << d.name;
    }
}

TEST_F(SimulationTest, PartsOneByOne) {
  const pisco::SimulationConfig c = pisco::read_simulation_file(write_config());
  EXPECT_EQ(c.scan.kind, pisco::ScanKind::pixel_centres);
  EXPECT_STREQ(pisco::scan_kind_name(c.scan.kind), "pixel_centres");
  ASSERT_EQ(c.beams.size(), 2u);  // by name: ell, main
  EXPECT_EQ(c.beams[0].name, "ell");
  EXPECT_EQ(c.beams[0].kind, pisco::BeamKind::elliptical);
  EXPECT_EQ(c.beams[1].kind, pisco::BeamKind::gaussian);
  EXPECT_STREQ(pisco::beam_kind_name(c.beams[0].kind), "elliptical");
  ASSERT_EQ(c.detectors.size(), 3u);
  EXPECT_EQ(c.detectors[0].name, "d");  // [[detectors]], then [[pairs]]
  EXPECT_EQ(c.detectors[0].beam, 0u);
  EXPECT_EQ(c.detectors[2].name, "pb");
  EXPECT_EQ(c.detectors[2].beam, 1u);
  // Every detector gets the plate, with the default gamma: its polarization angle in the focal plane.
  for (const auto& d : c.detectors) {
    ASSERT_TRUE(d.hwp.has_value()) << d.name;
    EXPECT_EQ(d.hwp->gamma, pisco::default_hwp_gamma(d)) << d.name;
  }
  EXPECT_NEAR(pisco::default_hwp_gamma(c.detectors[0]), 40 * pisco::deg, 1e-12);

  const pisco::Sky sky = pisco::make_sky(c.sky, pisco::default_data_dir());
  EXPECT_EQ(sky.nside(), 32);
  std::vector<std::string> said;
  const pisco::SimulationBeams beams = pisco::make_beams(c, [&](const std::string& line) { said.push_back(line); });
  ASSERT_EQ(beams.beams.size(), 2u);
  EXPECT_EQ(beams.names, (std::vector<std::string>{"ell", "main"}));
  ASSERT_EQ(said.size(), 2u);
  EXPECT_EQ(said[1].rfind("beam main: ", 0), 0u) << said[1];
  EXPECT_EQ(beams.detectors.size(), 3u);
  EXPECT_EQ(pisco::maps_nside(c, sky), 16);
  // The cost model of a run shared out between processes: the disc's pixels.
  EXPECT_DOUBLE_EQ(pisco::disc_pixels(beams.beams[1], 32, 0), 0.5 * (1 - std::cos(8 * pisco::deg)) * 12 * 32 * 32);
  ASSERT_TRUE(pisco::window_fwhm(c.beams[1]).has_value());
  EXPECT_EQ(*pisco::window_fwhm(c.beams[1]), 4.0 * pisco::deg);
  EXPECT_NEAR(*pisco::window_fwhm(c.beams[0]), std::sqrt(3.5 * 4.5) * pisco::deg, 1e-15);

  const pisco::FocalPlane fp(beams.detectors);
  pisco::Engine engine = pisco::make_engine(sky, beams.beams, fp, c);
  EXPECT_EQ(engine.backend_name(), "cpu");

  // The engine's TOD of the first pixels equals the whole run's (the cpu backend sums each sample alone).
  pisco::Simulation sim(c);
  sim.config().output.dir = dir_ / "whole";
  sim.config().output.spectra = false;
  const pisco::SimulationResult r = sim.run();
  EXPECT_EQ(r.written.size(), 3u);  // no spectra
  const pisco::Pointing all = pisco::pixel_centre_scan(16, c.scan.psi);
  const pisco::PointingView first = all.view().subspan(0, 64);
  std::vector<double> hwp(64);
  c.hwp.stream.generate(0, 64, hwp);
  for (std::size_t d = 0; d < fp.size(); ++d) {
    std::vector<double> tod(64);
    engine.convolve(d, first, std::span<double>(tod), false, hwp);
    const std::vector<double> written = pisco::read_tod_signal(r.tod_file, fp[d].name);
    ASSERT_EQ(written.size(), all.size());
    EXPECT_TRUE(std::equal(tod.begin(), tod.end(), written.begin())) << fp[d].name;
  }

  // Maps and spectra writers: whole files.
  pisco::BinnedMaps maps;
  maps.nside = 1;
  maps.I.assign(12, 1.0);
  maps.Q.assign(12, 0.0);
  maps.U.assign(12, pisco::unseen);
  maps.I[3] = pisco::unseen;
  maps.hits.assign(12, 2);
  fs::create_directories(dir_ / "parts");
  EXPECT_EQ(pisco::write_maps(dir_ / "parts", maps, 1, "K"), 11u);
  EXPECT_TRUE(fs::exists(dir_ / "parts" / "maps.fits"));
  EXPECT_TRUE(fs::exists(dir_ / "parts" / "hits.fits"));
  pisco::Spectra s;
  for (auto* v : {&s.TT, &s.EE, &s.BB, &s.TE, &s.EB, &s.TB}) v->assign(5, 1.0);
  pisco::write_spectra(dir_ / "parts" / "spectra.txt", s, 4, "test");
  const std::string text = read_bytes(dir_ / "parts" / "spectra.txt");
  EXPECT_EQ(text.rfind("# test\n# l  D_l", 0), 0u) << text;
  EXPECT_NE(text.find("\n4 "), std::string::npos) << text;
}

TEST_F(SimulationTest, StepsGoThroughTheContext) {
  const fs::path file = write_config();
  pisco::Simulation sim = pisco::Simulation::from_file(file);
  sim.config().output.tod = false;
  CountingContext context;
  const pisco::SimulationResult r = sim.run(context);
  EXPECT_GE(context.steps, 6);  // directory, sky, beams, engine, scan, maps, ...
  EXPECT_TRUE(r.tod_file.empty());
  EXPECT_FALSE(fs::exists(dir_ / "out" / "tod.h5"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "maps.fits"));
}

// [mapmaker] type = "deconvolve" (docs/config.md): a beam-mismatched pair on an unpolarized sky. The
// binned maps carry the temperature the mismatch leaks into polarization; the deconvolved ones,
// solved with each detector's own beam, much less. maps.fits holds the solution reconvolved to the
// target beam, deconvolved.fits the solution, binned_maps.fits and hits.fits the binned map-maker's.
TEST_F(SimulationTest, DeconvolvingMapmakerTakesTheBeamMismatchOut) {
  const fs::path file = dir_ / "deconvolve.toml";
  const auto write = [&](const std::string& mapmaker, const std::string& output = "", const std::string& sky = "") {
    std::ofstream(file) << "[sky]\n" << (sky.empty() ? "nside = 16\nlmax = 32\nseed = 4\nunpolarized = true\n" : sky)
                        << "[beams.a]\ntype = \"elliptical\"\nfwhm_x_deg = 9.0\nfwhm_y_deg = 7.5\nangle_deg = 20\n"
                           "rho_max_deg = 18.0\n"
                           "[beams.b]\ntype = \"elliptical\"\nfwhm_x_deg = 8.0\nfwhm_y_deg = 8.4\nangle_deg = -35\n"
                           "rho_max_deg = 18.0\n"
                           "[focal_plane]\n[[focal_plane.detectors]]\nname = \"a\"\nbeam = \"a\"\n"
                           "[[focal_plane.detectors]]\nname = \"b\"\nbeam = \"b\"\nzeta_deg = -90\n"
                           "[scan]\ntype = \"pixel_centres\"\nnside = 16\npsi_deg = [0, 45, 90]\n"
                           "[engine]\nbackend = \"simd\"\n"
                        << mapmaker << "[output]\ndir = \"" << (dir_ / "out").string()
                        << "\"\nplots = false\ntod = false\nlmax = 32\n" << output;
  };
  write("[mapmaker]\ntype = \"deconvolve\"\niterations = 40\ntarget_fwhm_deg = 10.0\n");
  pisco::Simulation sim = pisco::Simulation::from_file(file);
  Recorder recorder;
  const pisco::SimulationResult r = sim.run(&recorder);
  EXPECT_EQ(r.deconvolution_iterations, 40);
  EXPECT_GT(r.deconvolution_residual, 0.0);
  EXPECT_LT(r.deconvolution_residual, 1e-2);
  EXPECT_NE(recorder.lines.find("mapmaker: iteration 40, residual"), std::string::npos) << recorder.lines;
  for (const char* f : {"maps.fits", "deconvolved.fits", "binned_maps.fits", "hits.fits", "spectra.txt"})
    EXPECT_TRUE(fs::exists(dir_ / "out" / f)) << f;
  const pisco::Sky binned = pisco::Sky::read_fits(dir_ / "out" / "binned_maps.fits", pisco::UnseenPolicy::flag);
  const pisco::Sky maps = pisco::Sky::read_fits(dir_ / "out" / "maps.fits", pisco::UnseenPolicy::flag);
  const auto rms = [](std::span<const double> a, std::span<const double> b) {
    double s = 0;
    std::size_t n = 0;
    for (std::size_t p = 0; p < a.size(); ++p)
      if (a[p] != pisco::unseen) s += a[p] * a[p] + b[p] * b[p], ++n;
    return std::sqrt(s / double(n));
  };
  const double leak_binned = rms(binned.Q(), binned.U()), leak = rms(maps.Q(), maps.U());
  double ti = 0;
  for (double v : maps.I()) ti += v * v;
  std::cout << "polarization leaked: binned " << leak_binned << ", deconvolved " << leak << "; temperature rms "
            << std::sqrt(ti / double(maps.npix())) << "\n";
  EXPECT_GT(leak_binned, 1e-3 * std::sqrt(ti / double(maps.npix())));  // the mismatch leaks
  EXPECT_LT(leak, 0.2 * leak_binned);

  // Errors name the file and key.
  const auto fails = [&](const std::string& what) {
    try {
      pisco::Simulation::from_file(file).run(&recorder);
      ADD_FAILURE() << "no error; expected " << what;
    } catch (const pisco::Error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
    }
  };
  write("[mapmaker]\ntype = \"deconvolve\"\niteration = 4\n");
  fails("unknown key 'iteration' (did you mean 'iterations'");
  write("[mapmaker]\niterations = 4\n");
  fails("[mapmaker] iterations: only for type = \"deconvolve\"");
  write("[mapmaker]\ntype = \"deconvolved\"\n");
  fails("[mapmaker] type");
  write("[mapmaker]\ntype = \"deconvolve\"\nregularize = \"polarisation\"\n");
  fails("[mapmaker] regularize");
  write("[mapmaker]\ntype = \"deconvolve\"\n", "maps_nside = 8\n");
  fails("[output] maps_nside");
  pisco::Sky flat(16);
  flat.write_fits(dir_ / "sky.fits");
  write("[mapmaker]\ntype = \"deconvolve\"\n", "", "file = \"" + (dir_ / "sky.fits").string() + "\"\nunseen = \"flag\"\n");
  fails("[mapmaker] type: \"deconvolve\" models every sample");
}

TEST_F(SimulationTest, ErrorsNameTheFileAndKeyAndLeaveNoOutput) {
  // A misspelt key, as pisco-vk reports it.
  const fs::path bad = dir_ / "bad.toml";
  std::ofstream(bad) << "[sky]\nnside = 32\nseeed = 3\n[beams.main]\n[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\n"
                        "[scan]\n";
  try {
    (void)pisco::read_simulation_file(bad);
    FAIL() << "no error";
  } catch (const pisco::Error& e) {
    EXPECT_EQ(std::string(e.what()), bad.string() + ": [sky] unknown key 'seeed' (did you mean 'seed'?)");
  }
  EXPECT_THROW((void)pisco::Simulation::from_file(dir_ / "missing.toml"), pisco::Error);

  // An error found once the run has begun: nothing is left in the output directory.
  pisco::Simulation sim = pisco::Simulation::from_file(write_config());
  sim.config().output.lmax = 1000;  // beyond 4 maps_nside
  try {
    (void)sim.run();
    FAIL() << "no error";
  } catch (const pisco::Error& e) {
    EXPECT_NE(std::string(e.what()).find("[output] lmax: expected a multipole up to 4 maps_nside = 64, got 1000"),
              std::string::npos)
        << e.what();
  }
  ASSERT_TRUE(fs::is_directory(dir_ / "out"));
  EXPECT_TRUE(fs::is_empty(dir_ / "out"));
}

TEST_F(SimulationTest, FocalPlaneFiles) {
  const fs::path csv = dir_ / "fp.csv";
  std::ofstream(csv) << "name,zeta_deg,beam,xi_deg,hwp_gamma_deg\na,0,main,1,5\nb,90,side,0,7\n";
  std::vector<pisco::DetectorHwp> hwp;
  const std::vector<pisco::Detector> dets = pisco::read_focal_plane_file(csv, {"main", "side"}, &hwp);
  ASSERT_EQ(dets.size(), 2u);
  EXPECT_EQ(dets[1].name, "b");
  EXPECT_EQ(dets[1].beam, 1u);
  EXPECT_NEAR(dets[1].zeta, std::numbers::pi / 2, 1e-15);
  EXPECT_TRUE(dets[0].has_offset());
  ASSERT_EQ(hwp.size(), 2u);
  EXPECT_NEAR(*hwp[1].gamma, 7 * pisco::deg, 1e-15);

  const fs::path toml = dir_ / "fp.toml";
  std::ofstream(toml) << "[[pairs]]\nname = \"q\"\nbeam = \"side\"\nzeta_deg = 10\n";
  const std::vector<pisco::Detector> pair = pisco::read_focal_plane_file(toml, {"main", "side"});
  ASSERT_EQ(pair.size(), 2u);
  EXPECT_EQ(pair[0].name, "qa");
  EXPECT_EQ(pair[1].beam, 1u);

  std::ofstream(csv) << "name,beam\na,nope\n";
  try {
    (void)pisco::read_focal_plane_file(csv, {"main"});
    FAIL() << "no error";
  } catch (const pisco::Error& e) {
    EXPECT_EQ(std::string(e.what()), csv.string() + ":2: no beam named 'nope' in [beams]");
  }
}

}  // namespace

// Every kind of [mapmaker] is registered once (pipeline/mapmaker_kinds.cpp) under its MapmakerKind
// and name; no key belongs to two kinds (the reader names the kind a stray key is for), and each kind
// gives the NSIDE of its maps: binned the [output] maps_nside or the scan's, deconvolve the sky's.
TEST(MapmakerKinds, EveryKindIsRegisteredOnceWithItsOwnKeys) {
  using namespace pisco::detail;
  std::set<std::string> names, keys;
  for (const MapmakerKindEntry* k : mapmaker_kinds()) {
    EXPECT_TRUE(names.insert(k->name).second) << k->name;
    EXPECT_EQ(&mapmaker_kind(k->kind), k);
    EXPECT_EQ(mapmaker_kind_named(k->name), k);
    for (const char* key : k->keys) EXPECT_TRUE(keys.insert(key).second) << key;
  }
  EXPECT_EQ(names, (std::set<std::string>{"binned", "deconvolve"}));
  EXPECT_EQ(mapmaker_kind_named("destriped"), nullptr);
  pisco::SimulationConfig c;
  c.scan.kind = pisco::ScanKind::raster;
  c.scan.nside = 16;
  const pisco::Sky sky(32);
  EXPECT_EQ(binned_mapmaker_kind.maps_nside(c, sky), 16);
  EXPECT_EQ(deconvolve_mapmaker_kind.maps_nside(c, sky), 32);
  c.output.maps_nside = 8;
  EXPECT_EQ(binned_mapmaker_kind.maps_nside(c, sky), 8);
  pisco_test::expect_error([&] { deconvolve_mapmaker_kind.maps_nside(c, sky); },
                           "[output] maps_nside: [mapmaker] type = \"deconvolve\" solves for the sky at its NSIDE 32; got 8");
}

// Every kind of [beams.NAME] table is registered once (beams/beam_kinds.cpp) under its BeamKind and
// name, with what it is (made of other tables, turning with the detector), and makes what the
// library's own builders make.
TEST(BeamKinds, EveryKindIsRegisteredOnceAndMakesItsBeam) {
  using namespace pisco::detail;
  std::set<std::string> names;
  for (const BeamKindEntry* k : beam_kinds()) {
    EXPECT_TRUE(names.insert(k->name).second) << k->name;
    EXPECT_EQ(&beam_kind(k->kind), k);
    EXPECT_EQ(beam_kind_named(k->name), k);
    EXPECT_STREQ(pisco::beam_kind_name(k->kind), k->name);
    EXPECT_EQ(k->combines_beams, k->make == nullptr) << k->name;
    pisco::BeamConfig b;
    b.kind = k->kind;
    EXPECT_EQ(b.combines_beams(), k->kind == pisco::BeamKind::sequence || k->kind == pisco::BeamKind::plate);
    EXPECT_EQ(b.turns_with_detector(), k->kind == pisco::BeamKind::grasp || k->kind == pisco::BeamKind::blm);
  }
  EXPECT_EQ(names, (std::set<std::string>{"gaussian", "elliptical", "file", "grasp", "blm", "sequence", "plate"}));
  EXPECT_EQ(beam_kind_named("airy"), nullptr);
  pisco::BeamConfig e;
  e.kind = pisco::BeamKind::elliptical;
  e.fwhm_x = 1.0 * pisco::deg;
  e.fwhm_y = 1.5 * pisco::deg;
  e.angle = 0.3;
  e.options.rho_max = 4 * pisco::deg;
  e.options.cross_polar = 0.01;
  const pisco::Beamsor made = beam_kind(e.kind).make(e, {});
  const pisco::Beamsor direct = pisco::Beamsor::elliptical_gaussian(e.fwhm_x, e.fwhm_y, e.angle, e.options);
  EXPECT_EQ(made.omega_tilde(), direct.omega_tilde());
  for (const double x : {-0.01, 0.0, 0.004})
    for (const double y : {-0.005, 0.0, 0.012})
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) EXPECT_EQ(made.at(x, y)[i][j], direct.at(x, y)[i][j]);
}
