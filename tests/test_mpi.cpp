// `mpirun -n N pisco-vk run` (docs/scaling.md), in the MPI build (PISCO_WITH_MPI): N ranks give the
// TOD of one process bit for bit (cpu backend) and the same maps to rounding; a failing rank ends every
// rank with its message and leaves no output; the class_like example runs under 2 ranks.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <optional>
#include <fstream>
#include <string>
#include <vector>

#include "pisco/pisco.hpp"
#include "pisco/tod_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;

struct Result {
  int status;
  std::string output;  // stdout and stderr
};

Result shell(const std::string& cmd) {
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  while (std::size_t n = std::fread(buf.data(), 1, buf.size(), p)) out.append(buf.data(), n);
  const int rc = pclose(p);
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, out};
}

// `pisco-vk args` under `mpirun -n ranks` (ranks 0: started without mpirun).
Result pisco(int ranks, const std::string& args, const std::string& env = "") {
  const std::string exe = PISCO_VK_EXE;
  const std::string cmd = ranks == 0 ? env + " " + exe + " " + args
                                     : env + " " + PISCO_MPIEXEC + " --oversubscribe --allow-run-as-root -n " +
                                           std::to_string(ranks) + " " + exe + " " + args;
  Result r = shell(cmd);
  std::cout << "$ " << cmd << "\n" << r.output;
  return r;
}

class Mpi : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("mpi");
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }
  fs::path dir_;
};

// Two pairs with discs of different sizes (the work is balanced by disc pixels), offset from the
// boresight, a satellite scan in chunks of 700 samples (the spans of the ranks' jobs are shorter), TOD
// with pointing.
std::string config(const std::string& extra = "") {
  return R"([sky]
nside = 64
lmax = 128
seed = 5
[beams.small]
type = "gaussian"
fwhm_deg = 2.0
rho_max_deg = 4.0
[beams.large]
type = "elliptical"
fwhm_x_deg = 3.0
fwhm_y_deg = 2.6
angle_deg = 20.0
rho_max_deg = 8.0
[focal_plane]
[[focal_plane.pairs]]
name = "a"
beam = "small"
xi_deg = -2.0
eta_deg = 1.0
[[focal_plane.pairs]]
name = "b"
zeta_deg = 45.0
beam = "large"
xi_deg = 2.0
eta_deg = -1.0
[scan]
type = "satellite"
spin_sun_angle_deg = 45.0
spin_boresight_angle_deg = 50.0
precession_period_min = 9.6174
spin_period_min = 1.0
sample_rate_hz = 10.0
duration_hours = 0.5
nside = 8
[engine]
backend = "cpu"
chunk_samples = 700
[output]
tod = true
tod_pointing = true
tod_weights = true
maps = true
spectra = false
plots = false
)" + extra;
}

struct Output {
  std::vector<pisco::TodFileDetector> detectors;
  std::vector<std::vector<double>> signal;
  std::vector<std::vector<pisco::Quat>> quats;
  std::vector<std::vector<double>> weights;
  std::optional<pisco::Sky> maps;
};

Output read_output(const fs::path& dir) {
  Output o;
  const fs::path tod = dir / "tod.h5";
  o.detectors = pisco::read_tod_detectors(tod);
  for (const auto& d : o.detectors) {
    o.signal.push_back(pisco::read_tod_signal(tod, d.name));
    o.quats.push_back(pisco::read_tod_quats(tod, d.name));
    o.weights.push_back(pisco::read_tod_weights(tod, d.name));
  }
  o.maps.emplace(pisco::Sky::read_fits(dir / "maps.fits", pisco::UnseenPolicy::flag));
  return o;
}

// The TOD bit for bit; the maps to `map_tolerance` of their largest value (the ranks' normal equations
// are summed in another order).
void expect_same(const Output& one, const Output& many, int ranks, double map_tolerance = 1e-15) {
  ASSERT_EQ(one.detectors.size(), many.detectors.size());
  for (std::size_t d = 0; d < one.detectors.size(); ++d) {
    EXPECT_EQ(one.detectors[d].name, many.detectors[d].name);
    ASSERT_EQ(one.signal[d].size(), many.signal[d].size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < one.signal[d].size(); ++i)
      differ += std::memcmp(&one.signal[d][i], &many.signal[d][i], sizeof(double)) != 0;
    EXPECT_EQ(differ, 0u) << ranks << " ranks: detector " << one.detectors[d].name << ": samples not bitwise equal";
    ASSERT_EQ(one.quats[d].size(), many.quats[d].size());
    for (std::size_t i = 0; i < one.quats[d].size(); ++i)
      ASSERT_EQ(std::memcmp(&one.quats[d][i], &many.quats[d][i], sizeof(pisco::Quat)), 0) << "pointing of sample " << i;
    EXPECT_EQ(one.weights[d], many.weights[d]) << ranks << " ranks: detector " << one.detectors[d].name << "'s weights";
  }
  double worst = 0, scale = 0;
  std::size_t solved = 0;
  for (int k = 0; k < 3; ++k) {
    const auto a = one.maps->stokes(static_cast<pisco::StokesIndex>(k));
    const auto b = many.maps->stokes(static_cast<pisco::StokesIndex>(k));
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t p = 0; p < a.size(); ++p) {
      ASSERT_EQ(a[p] == pisco::unseen, b[p] == pisco::unseen) << "pixel " << p << " solved in one run only";
      if (a[p] == pisco::unseen) continue;
      ++solved;
      scale = std::max(scale, std::abs(a[p]));
      worst = std::max(worst, std::abs(a[p] - b[p]));
    }
  }
  EXPECT_GT(solved, 100u);
  std::cout << ranks << " ranks: largest map difference " << worst << " = " << worst / scale
            << " of the largest value\n";
  EXPECT_LE(worst, map_tolerance * scale) << ranks << " ranks";
}

TEST_F(Mpi, RanksGiveTheTodAndMapsOfOneProcess) {
  const fs::path cfg = write("sim.toml", config());
  // One process: started without mpirun, and as one rank.
  ASSERT_EQ(pisco(0, "run -q " + cfg.string() + " -o " + (dir_ / "plain").string()).status, 0);
  const Output one = read_output(dir_ / "plain");
  for (int ranks : {1, 2, 3}) {
    const fs::path out = dir_ / ("ranks" + std::to_string(ranks));
    const Result r = pisco(ranks, "run " + cfg.string() + " -o " + out.string());
    ASSERT_EQ(r.status, 0);
    if (ranks > 1) {
      EXPECT_NE(r.output.find(std::to_string(ranks) + " ranks:"), std::string::npos) << "the summary names the ranks";
      // Logs from rank 0 only: one banner.
      EXPECT_EQ(r.output.find("pisco-vk "), r.output.rfind("pisco-vk ")) << "one banner";
    }
    expect_same(one, read_output(out), ranks);
    for (const auto& e : fs::directory_iterator(out))
      EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << "left behind: " << e.path();
    const auto attrs = pisco::read_tod_attributes(out / "tod.h5");
    EXPECT_EQ(attrs.at("pisco_format"), "pisco-tod-1");
    EXPECT_EQ(attrs.at("backend"), "cpu");
  }
}

// [mapmaker] type = "deconvolve" under 2 and 3 ranks: each rank replays its own jobs every iteration
// and the maps are summed over the ranks (a fixed tree, then a broadcast), so that every rank runs the
// same iterations on the whole survey. The maps equal one process's to rounding: the ranks add their
// chunks' adjoints in other groupings.
TEST_F(Mpi, DeconvolvingMapmakerUnderRanksGivesTheMapsOfOneProcess) {
  const fs::path cfg = write("sim.toml", config("[mapmaker]\ntype = \"deconvolve\"\niterations = 5\n"
                                                "target_fwhm_deg = 4.0\n"));
  // Five iterations stop short of the default tolerance: every file written, a warning, status 5.
  ASSERT_EQ(pisco(0, "run -q " + cfg.string() + " -o " + (dir_ / "plain").string()).status, 5);
  const pisco::Sky one = pisco::Sky::read_fits(dir_ / "plain" / "deconvolved.fits", pisco::UnseenPolicy::flag);
  for (int ranks : {2, 3}) {
    const fs::path out = dir_ / ("ranks" + std::to_string(ranks));
    const Result r = pisco(ranks, "run " + cfg.string() + " -o " + out.string());
    ASSERT_EQ(r.status, 5) << r.output;
    const std::string warning = "pisco-vk: warning: the deconvolving map-maker did not converge";
    EXPECT_NE(r.output.find(warning), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find(warning), r.output.rfind(warning)) << "said once";
    EXPECT_NE(r.output.find("mapmaker: iteration 5,"), std::string::npos);
    EXPECT_EQ(r.output.find("mapmaker: iteration 1,"), r.output.rfind("mapmaker: iteration 1,")) << "said once";
    const pisco::Sky many = pisco::Sky::read_fits(out / "deconvolved.fits", pisco::UnseenPolicy::flag);
    double worst = 0, scale = 0;
    std::size_t seen = 0;
    for (int k = 0; k < 3; ++k) {
      const auto a = one.stokes(pisco::StokesIndex(k)), b = many.stokes(pisco::StokesIndex(k));
      for (std::size_t p = 0; p < a.size(); ++p) {
        ASSERT_EQ(a[p] == pisco::unseen, b[p] == pisco::unseen) << "pixel " << p;
        if (a[p] == pisco::unseen) continue;
        ++seen;
        scale = std::max(scale, std::abs(a[p]));
        worst = std::max(worst, std::abs(a[p] - b[p]));
      }
    }
    std::cout << ranks << " ranks: deconvolved maps differ by " << worst / scale << " of the largest value\n";
    EXPECT_GT(seen, 1000u);
    EXPECT_LE(worst, 1e-9 * scale) << ranks << " ranks";
    EXPECT_TRUE(fs::exists(out / "maps.fits") && fs::exists(out / "binned_maps.fits") && fs::exists(out / "hits.fits"));
  }
}

TEST_F(Mpi, RanksGiveTheTodAndMapsOfOneProcessWithAHalfWavePlate) {
  // The plate's angle per sample, made for each rank's spans.
  const fs::path cfg = write("sim.toml", config("[hwp]\nrpm = 46.0\nplacement = \"aperture\"\n"));
  ASSERT_EQ(pisco(0, "run -q " + cfg.string() + " -o " + (dir_ / "plain").string()).status, 0);
  const Output one = read_output(dir_ / "plain");
  const fs::path out = dir_ / "ranks2";
  ASSERT_EQ(pisco(2, "run " + cfg.string() + " -o " + out.string()).status, 0);
  expect_same(one, read_output(out), 2);
}

// [ground] (docs/ground.md) under 2 ranks: each rank's jobs add the ground engine's TOD at their own
// spans' horizon pointing, the ground's maps and the account's figures are summed over the ranks.
TEST_F(Mpi, TheGroundUnderRanksIsOneProcesss) {
  std::string text = config("[ground]\ntemperature_k = 270\nfrequency_ghz = 90\nhorizon_deg = [2, 9, 4]\n"
                            "horizon_width_deg = 2\nnside = 32\n");
  const std::string scan = text.substr(text.find("[scan]"), text.find("[engine]") - text.find("[scan]"));
  text.replace(text.find(scan), scan.size(),
               "[scan]\ntype = \"ces\"\nelevation_deg = 40\naz_throw_deg = 120\nsample_rate_hz = 2\n"
               "duration_hours = 0.5\nnside = 16\n");
  const std::string large = "rho_max_deg = 8.0\n[focal_plane]";
  text.replace(text.find(large), large.size(),
               "rho_max_deg = 60.0\nsidelobe_split_deg = 16\nfar_sidelobe_db = -40\nfar_sidelobe_deg = 50\n"
               "far_sidelobe_width_deg = 6\nfar_sidelobe_angle_deg = 180\n[focal_plane]");
  text.replace(text.find("backend = \"cpu\""), 15, "backend = \"cpu\"\nnormalization = \"integral\"");
  const fs::path cfg = write("sim.toml", text);
  const Result plain = pisco(0, "run " + cfg.string() + " -o " + (dir_ / "plain").string());
  ASSERT_EQ(plain.status, 0) << plain.output;
  const Output one = read_output(dir_ / "plain");
  const fs::path out = dir_ / "ranks2";
  const Result r = pisco(2, "run " + cfg.string() + " -o " + out.string());
  ASSERT_EQ(r.status, 0) << r.output;
  // The ground's pickup is a large offset (its mean), whose sums in another order round differently.
  expect_same(one, read_output(out), 2, 1e-12);
  const auto line = [](const std::string& output) {
    const std::size_t at = output.find("ground: picked up");
    return at == std::string::npos ? std::string() : output.substr(at, output.find('\n', at) - at);
  };
  EXPECT_FALSE(line(plain.output).empty()) << plain.output;
  EXPECT_EQ(line(plain.output), line(r.output));
  const pisco::Sky a = pisco::Sky::read_fits(dir_ / "plain" / "ground_maps.fits", pisco::UnseenPolicy::flag);
  const pisco::Sky b = pisco::Sky::read_fits(out / "ground_maps.fits", pisco::UnseenPolicy::flag);
  double worst = 0, scale = 0;
  for (std::size_t p = 0; p < a.npix(); ++p) {
    ASSERT_EQ(a.I()[p] == pisco::unseen, b.I()[p] == pisco::unseen) << "pixel " << p;
    if (a.I()[p] == pisco::unseen) continue;
    scale = std::max(scale, std::abs(a.I()[p]));
    worst = std::max(worst, std::abs(a.I()[p] - b.I()[p]));
  }
  EXPECT_GT(scale, 0.0);
  EXPECT_LE(worst, 1e-12 * scale);
}

TEST_F(Mpi, RanksReadPerDetectorPointingFilesAsOneProcess) {
  // Per-detector pointing (detectors outermost in the jobs): the pointing of a first run's TOD file,
  // which is a pointing file, read back by the same detectors without offsets.
  ASSERT_EQ(pisco(0, "run -q " + write("first.toml", config()).string() + " -o " + (dir_ / "first").string()).status, 0);
  std::string text = config("maps_nside = 8\n");
  for (const char* offset : {"xi_deg = -2.0\neta_deg = 1.0\n", "xi_deg = 2.0\neta_deg = -1.0\n"})
    text.erase(text.find(offset), std::string(offset).size());
  const auto scan = text.find("[scan]"), engine = text.find("[engine]");
  text.replace(scan, engine - scan, "[scan]\ntype = \"file\"\nfile = \"" + (dir_ / "first" / "tod.h5").string() + "\"\n");
  const fs::path cfg = write("sim.toml", text);
  ASSERT_EQ(pisco(0, "run -q " + cfg.string() + " -o " + (dir_ / "plain").string()).status, 0);
  const Output one = read_output(dir_ / "plain");
  for (int ranks : {2, 3}) {
    const fs::path out = dir_ / ("ranks" + std::to_string(ranks));
    ASSERT_EQ(pisco(ranks, "run " + cfg.string() + " -o " + out.string()).status, 0);
    expect_same(one, read_output(out), ranks);
  }
}

TEST_F(Mpi, AFailingRankEndsEveryRankAndLeavesNoOutput) {
  const fs::path cfg = write("sim.toml", config());
  for (int ranks : {2, 3}) {
    const fs::path out = dir_ / ("out" + std::to_string(ranks));
    const Result r = pisco(ranks, "run " + cfg.string() + " -o " + out.string(), "PISCO_TEST_RANK_FAIL=1");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.output.find("pisco-vk: error: rank 1: injected failure on rank 1"), std::string::npos);
    std::size_t errors = 0;
    for (auto at = r.output.find("pisco-vk: error:"); at != std::string::npos; at = r.output.find("pisco-vk: error:", at + 1))
      ++errors;
    EXPECT_EQ(errors, 1u) << "one message, from rank 0";
    if (fs::exists(out))
      for (const auto& e : fs::directory_iterator(out)) ADD_FAILURE() << "left behind: " << e.path();
  }
}

TEST_F(Mpi, AnErrorOnEveryRankIsSaidOnce) {
  const fs::path cfg = write("sim.toml", config("[hwp]\nfrobnicate = 1\n"));
  const Result r = pisco(2, "run " + cfg.string() + " -o " + (dir_ / "out").string());
  EXPECT_EQ(r.status, 2);
  std::size_t errors = 0;
  for (auto at = r.output.find("pisco-vk: error:"); at != std::string::npos; at = r.output.find("pisco-vk: error:", at + 1))
    ++errors;
  EXPECT_EQ(errors, 1u);
  EXPECT_FALSE(fs::exists(dir_ / "out" / "tod.h5"));
}

TEST_F(Mpi, ClassLikeExampleUnderTwoRanks) {
  const fs::path example = fs::path(PISCO_SOURCE_DIR) / "assets" / "examples" / "class_like.toml";
  const fs::path out = dir_ / "class_like";
  const Result r = pisco(2, "run " + example.string() + " -b cpu --no-plots -o " + out.string());
  ASSERT_EQ(r.status, 0);
  EXPECT_NE(r.output.find("2 ranks:"), std::string::npos);
  for (const char* f : {"maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  // The solved pixels it prints are those of the maps it wrote, and README.md's row for the example
  // quotes the same number.
  const pisco::Sky maps = pisco::Sky::read_fits(out / "maps.fits", pisco::UnseenPolicy::flag);
  const std::size_t solved = maps.npix() - maps.unseen_pixels().size();
  EXPECT_GT(solved, maps.npix() / 10);
  EXPECT_NE(r.output.find(std::to_string(solved) + " of " + std::to_string(maps.npix()) + " pixels solved"),
            std::string::npos)
      << solved << " solved in maps.fits";
  std::ifstream readme(fs::path(PISCO_SOURCE_DIR) / "README.md");
  const std::string text((std::istreambuf_iterator<char>(readme)), std::istreambuf_iterator<char>());
  std::string grouped = std::to_string(solved);  // 40066 -> 40,066
  for (int at = int(grouped.size()) - 3; at > 0; at -= 3) grouped.insert(std::size_t(at), ",");
  EXPECT_NE(text.find("| class_like.toml |"), std::string::npos);
  EXPECT_NE(text.find(grouped + " NSIDE 128 pixels solved"), std::string::npos) << "README.md's row for class_like.toml";
}

}  // namespace
