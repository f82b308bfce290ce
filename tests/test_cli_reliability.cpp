// `pisco-vk run` under hostile but fair conditions (docs/formats.md, "Errors and partial files"): an
// output directory full of shell syntax, a disk that fills at each writer, stop signals mid-run, masked
// skies, runs that solve no pixel, and errors that must name their file and key.
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <cstdlib>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <filesystem>
#include <fstream>
#include <regex>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "cli_runner.hpp"
#include "pisco/pisco.hpp"
#include "pisco/scan.hpp"
#include "pisco/tod_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco_test::CliResult;
using pisco_test::contains;
using pisco_test::files_under;
using pisco_test::joined;
using pisco_test::run_cli;
using pisco_test::temporaries_under;

class Reliability : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("rel");
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }
  // A small simulation (2 detectors x 3 x 3072 samples); `scan` and `extra` ([output] keys) vary it.
  std::string config(const std::string& sky = "[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                     const std::string& scan = "[scan]\ntype = \"pixel_centres\"\nnside = 16\n",
                     const std::string& extra = "plots = false\nlmax = 32\n",
                     const std::string& fp = "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n",
                     const std::string& engine = "") {
    return sky + "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n" + fp + scan +
           "[engine]\nbackend = \"cpu\"\n" + engine + "[output]\n" + extra;
  }
  // A run of a few seconds that writes its TOD as it goes (for signals mid-run).
  std::string long_config() {
    return config("[sky]\nnside = 64\nlmax = 128\nseed = 3\n", "[scan]\ntype = \"pixel_centres\"\nnside = 128\n",
                  "plots = false\n", "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n",
                  "chunk_samples = 20000\n");
  }
  // A stand-in for tools/pisco_plot.py, under a data directory of its own (PISCO_DATA_DIR).
  fs::path fake_plotter(const std::string& python) {
    const fs::path data = dir_ / "data";
    fs::create_directories(data / "tools");
    std::ofstream(data / "tools" / "pisco_plot.py") << python;
    return data;
  }
  fs::path dir_;
};

void expect_one_error(const CliResult& r, const std::string& needle) {
  EXPECT_TRUE(r.exited && r.status == 2) << r.describe() << "\n" << r.output;
  EXPECT_EQ(r.error_lines(), 1u) << r.output;
  EXPECT_TRUE(contains(r.error_line(), needle)) << "expected '" << needle << "' in: " << r.error_line();
}

// The output directory reaches the plotting tool as one argument, never through a shell: command
// substitutions, backticks, quotes, semicolons and spaces in it run nothing; and never as an option:
// a directory named "-x" (given as --output=-x) comes after "--", which ends the tool's options.
TEST_F(Reliability, HostileOutputDirectoryReachesNoShell) {
  const std::string hostile = "out $(touch PWNED1) `touch PWNED2` \"q\" 's' ; touch PWNED3 & x";
  const fs::path data = fake_plotter(
      "import os, sys\n"
      "open(os.path.join(sys.argv[-1], 'plot-args.txt'), 'w').write('\\n'.join(sys.argv[1:]) + '\\n')\n");
  const fs::path cfg = write("sim.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[scan]\ntype = \"pixel_centres\"\nnside = 16\n",
                                                "plots = true\nspectra = false\n"));
  // {the command line's output option, the directory the plotting tool must be given}; the runs' working
  // directory is dir_, so that "-x" is dir_/-x.
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
      {{"-o", (dir_ / hostile).string()}, (dir_ / hostile).string()},
      {{"--output=-x"}, "-x"},
  };
  const bool plots_possible =
      std::system("/usr/bin/python3 -c 'import healpy, matplotlib' > /dev/null 2>&1") == 0;
  for (const auto& [output, dir] : cases) {
    const fs::path out = dir_ / dir;
    const std::string option = joined(output);
    std::vector<std::string> args{"run", "-q", cfg.string()};
    args.insert(args.end(), output.begin(), output.end());
    const CliResult r = run_cli(args, {{"PISCO_DATA_DIR", data.string()}}, 120, dir_);
    ASSERT_TRUE(r.exited && r.status == 0) << option << ": " << r.describe() << "\n" << r.output;
    std::ifstream recorded(out / "plot-args.txt");
    std::vector<std::string> got;
    for (std::string line; std::getline(recorded, line);) got.push_back(line);
    // The suffix of pisco-vk's temporaries (its lock records it), then the directory after "--".
    ASSERT_EQ(got.size(), 3u) << joined(got);
    EXPECT_TRUE(std::regex_match(got[0], std::regex(R"(--temporary-suffix=\.tmp-pisco-[0-9]+-[0-9a-f]{16})"))) << got[0];
    EXPECT_EQ(std::vector<std::string>(got.begin() + 1, got.end()), (std::vector<std::string>{"--", dir}))
        << "the plotting tool's arguments, for " << option;
    // The real plotting tool on the same directory: plots, or a skip message where healpy is missing.
    args.erase(args.begin() + 1);  // not quiet: the plotting tool's messages
    const CliResult real = run_cli(args, {}, 120, dir_);
    std::cout << real.output;
    EXPECT_TRUE(real.exited && real.status == 0) << option << ": " << real.describe() << "\n" << real.output;
    // The plotting tool's interpreter (run.cpp: /usr/bin/python3) decides which outcome is right.
    if (plots_possible) {
      EXPECT_TRUE(contains(real.output, "plots: wrote")) << real.output;
      EXPECT_TRUE(fs::exists(out / "maps_mollview.png")) << option;
    } else {
      EXPECT_TRUE(contains(real.output, "plots: skipped")) << real.output;
    }
  }
  for (const auto& f : files_under(dir_))
    EXPECT_FALSE(contains(fs::path(f).filename().string(), "PWNED")) << "a shell ran: " << f;
  EXPECT_TRUE(temporaries_under(dir_).empty()) << joined(temporaries_under(dir_));
}

// A full disk at each writer (PISCO_TEST_FAULT=write-fail:NAME: the writer of NAME finds the disk
// full): one error naming the file and the reason, status 2, no crash, no temporary file; the files
// written before stay whole (they read back), none after is made.
TEST_F(Reliability, FullDiskAtEachWriter) {
  const fs::path cfg = write("sim.toml", config());
  const std::vector<std::string> order{"tod.h5", "maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"};
  for (std::size_t k = 0; k < order.size(); ++k) {
    const fs::path out = dir_ / ("out-" + order[k]);
    const CliResult r = run_cli({"run", "-q", cfg.string(), "-o", out.string()}, {{"PISCO_TEST_FAULT", "write-fail:" + order[k]}});
    std::cout << order[k] << ": " << r.describe() << ": " << r.error_line() << "\n";
    expect_one_error(r, (out / order[k]).string());
    EXPECT_TRUE(contains(r.error_line(), "No space left on device")) << r.error_line();
    EXPECT_TRUE(temporaries_under(out).empty()) << joined(temporaries_under(out));
    for (std::size_t j = 0; j < order.size(); ++j)
      EXPECT_EQ(fs::exists(out / order[j]), j < k) << order[k] << " failing, " << order[j];
    if (k > 0) EXPECT_EQ(pisco::read_tod_signal(out / "tod.h5", "pb").size(), 9216u);
    if (k > 1) EXPECT_EQ(pisco::Sky::read_fits(out / "maps.fits", pisco::UnseenPolicy::flag).nside(), 16);
  }
  // The plotting tool on a full disk: its error, then pisco-vk's, no half-written PNG.
  const fs::path out = dir_ / "out-plots";
  const fs::path cfg_plots = write("plots.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                        "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = true\n"));
  const CliResult r = run_cli({"run", "-q", cfg_plots.string(), "-o", out.string()},
                              {{"PISCO_TEST_FAULT", "write-fail:hits_mollview.png"}});
  std::cout << "plots: " << r.describe() << ":\n" << r.output;
  if (contains(r.output, "cannot plot")) {
    std::cout << "(the real plotting tool cannot plot here: python3-healpy or matplotlib missing; its full disk is "
                 "checked through a stand-in)\n";
    const fs::path data = fake_plotter(
        "import os, sys\n"
        "sys.stderr.write('pisco_plot: ' + os.path.join(sys.argv[-1], 'maps_mollview.png') + ': No space left on device\\n')\n"
        "sys.exit(4)\n");
    const CliResult f = run_cli({"run", "-q", cfg_plots.string(), "-o", (dir_ / "out-fake").string()},
                                {{"PISCO_DATA_DIR", data.string()}});
    expect_one_error(f, "failed with exit status 4");
    return;
  }
  expect_one_error(r, "failed with exit status 4");
  EXPECT_TRUE(contains(r.output, "hits_mollview.png: No space left on device")) << r.output;
  EXPECT_TRUE(fs::exists(out / "maps_mollview.png"));
  EXPECT_FALSE(fs::exists(out / "hits_mollview.png"));
  EXPECT_TRUE(temporaries_under(out).empty()) << joined(temporaries_under(out));
}

// A real small file system (a tmpfs in a private mount namespace, where `unshare -rm` is allowed),
// sized to fill during each writer in turn: every run ends with all its files, or one error about
// the space, status 2 and no temporary file; never a crash (HDF5's exit handlers were one).
TEST_F(Reliability, FullDiskOnASmallFileSystem) {
  const CliResult probe = pisco_test::finish_cli(
      pisco_test::start_process("unshare", {"-rm", "sh", "-c", "mkdir -p \"$0\" && mount -t tmpfs -o size=64k tmpfs \"$0\"",
                                            (dir_ / "probe").string()}));
  if (!(probe.exited && probe.status == 0))
    GTEST_SKIP() << "no small file system can be mounted here without root (unshare -rm: " << probe.describe() << ": "
                 << probe.output << "); the fault-injection test covers every writer";
  const fs::path cfg = write("sim.toml", config());
  const fs::path whole = dir_ / "whole";
  ASSERT_EQ(run_cli({"run", "-q", cfg.string(), "-o", whole.string()}).status, 0);
  std::vector<std::uintmax_t> sizes;
  const std::vector<std::string> order{"tod.h5", "maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"};
  for (const auto& f : order) sizes.push_back(fs::file_size(whole / f));
  std::vector<std::uintmax_t> limits{4096, 16384};
  std::uintmax_t before = 0;
  for (std::uintmax_t s : sizes) {
    for (double part : {0.3, 0.6, 0.9, 0.99}) limits.push_back(before + std::uintmax_t(part * double(s)));
    before += s;
  }
  limits.push_back(before + (1 << 20));
  int failures = 0;
  for (std::uintmax_t limit : limits) {
    const std::uintmax_t kib = (limit + 4095) / 4096 * 4;
    const fs::path mnt = dir_ / "small";
    const std::string script =
        "mkdir -p \"$1\" && mount -t tmpfs -o size=$2k tmpfs \"$1\" || exit 99\n"
        "\"$0\" run -q \"$3\" -o \"$1/out\"\nrc=$?\necho \"FILES: $(ls -A \"$1/out\" 2>/dev/null | tr '\\n' ' ')\"\nexit $rc\n";
    const CliResult r = pisco_test::finish_cli(pisco_test::start_process(
        "unshare", {"-rm", "sh", "-c", script, PISCO_VK_EXE, mnt.string(), std::to_string(kib), cfg.string()}));
    const std::string files = r.output.substr(r.output.find("FILES:"));
    std::cout << kib << " KiB: " << r.describe() << "; " << (r.error_lines() ? r.error_line() : "") << " " << files;
    EXPECT_TRUE(r.exited && (r.status == 0 || r.status == 2)) << r.describe() << "\n" << r.output;
    EXPECT_FALSE(contains(files, ".tmp")) << files;
    if (r.status == 2) {
      ++failures;
      EXPECT_EQ(r.error_lines(), 1u) << r.output;
      EXPECT_TRUE(contains(r.error_line(), "space")) << r.error_line();
    } else {
      for (const auto& f : order) EXPECT_TRUE(contains(files, f)) << files;
    }
  }
  EXPECT_GE(failures, 10);
}

// Every signal that ends a process by default and can be caught, in the middle of a convolution,
// ends the run within a second or so with status 128 + signal, one line, no file left (the TOD
// temporary included) and no directory: the run made its output directory, and takes it back.
// SIGPIPE and SIGXFSZ come here by kill(); the tests below cause them as the kernel does.
TEST_F(Reliability, StopSignalsEndTheRunAndRemoveTemporaries) {
  const fs::path cfg = write("long.toml", long_config());
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGPIPE, SIGXFSZ}) {
    const fs::path out = dir_ / ("out-" + std::to_string(sig)) / "run";
    auto p = pisco_test::start_cli({"run", cfg.string(), "-o", out.string()});
    bool sent = false;
    std::chrono::steady_clock::time_point sent_at;
    const CliResult r = pisco_test::finish_cli(p, 120, [&](const std::string&) {
      if (sent || temporaries_under(out).empty()) return;
      // The TOD file is being written (its temporary exists), mid-convolution.
      ::kill(p.pid, sig);
      sent = true;
      sent_at = std::chrono::steady_clock::now();
    });
    const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent_at).count();
    std::cout << strsignal(sig) << ": " << r.describe() << " " << took << " s after the signal; "
              << r.output.substr(r.output.rfind("pisco-vk:")) ;
    ASSERT_TRUE(sent) << "the run ended before its TOD temporary appeared:\n" << r.output;
    EXPECT_TRUE(r.exited && r.status == 128 + sig) << strsignal(sig) << ": " << r.describe();
    EXPECT_LT(took, 3.0);
    EXPECT_FALSE(fs::exists(out.parent_path())) << "left: " << joined(files_under(out));
    EXPECT_TRUE(contains(r.output, "stopped by SIG")) << r.output;
  }
}

// nohup: a SIGHUP ignored by the parent stays ignored (the run goes on), while SIGTERM still stops it.
TEST_F(Reliability, AnIgnoredHangupStaysIgnored) {
  const fs::path cfg = write("long.toml", long_config());
  const fs::path out = dir_ / "out";
  struct sigaction ignore{}, old{};
  ignore.sa_handler = SIG_IGN;
  ::sigaction(SIGHUP, &ignore, &old);  // inherited through posix_spawn, as nohup leaves it
  auto p = pisco_test::start_cli({"run", cfg.string(), "-o", out.string()});
  ::sigaction(SIGHUP, &old, nullptr);
  int phase = 0;
  std::chrono::steady_clock::time_point hup_at;
  const CliResult r = pisco_test::finish_cli(p, 120, [&](const std::string&) {
    if (phase == 0 && !temporaries_under(out).empty()) {
      ::kill(p.pid, SIGHUP);
      hup_at = std::chrono::steady_clock::now();
      phase = 1;
    } else if (phase == 1 && std::chrono::steady_clock::now() - hup_at > std::chrono::milliseconds(500)) {
      ::kill(p.pid, SIGTERM);  // still running half a second after the hangup
      phase = 2;
    }
  });
  EXPECT_EQ(phase, 2) << "the run ended " << (phase == 1 ? "after SIGHUP" : "before its TOD temporary appeared") << ":\n"
                      << r.output;
  EXPECT_TRUE(r.exited && r.status == 128 + SIGTERM) << r.describe() << "\n" << r.output;
  EXPECT_FALSE(contains(r.output, "SIGHUP")) << r.output;
}

// The file size limit (ulimit -f): the write that crosses it raises SIGXFSZ in the writing thread,
// which ends the run as any stop signal does.
TEST_F(Reliability, TheFileSizeLimitEndsTheRunCleanly) {
  const fs::path cfg = write("long.toml", long_config());
  const fs::path out = dir_ / "out";
  rlimit old{};
  ::getrlimit(RLIMIT_FSIZE, &old);
  rlimit limit = old;
  limit.rlim_cur = 200000;  // bytes: within the TOD file
  ::setrlimit(RLIMIT_FSIZE, &limit);
  auto p = pisco_test::start_cli({"run", cfg.string(), "-o", out.string()});
  ::setrlimit(RLIMIT_FSIZE, &old);
  const CliResult r = pisco_test::finish_cli(p, 120);
  EXPECT_TRUE(r.exited && r.status == 128 + SIGXFSZ) << r.describe() << "\n" << r.output;
  EXPECT_TRUE(contains(r.output, "stopped by SIGXFSZ (the file size limit)")) << r.output;
  EXPECT_FALSE(fs::exists(out)) << "left: " << joined(files_under(out));
}

// A closed standard error (the reader of a pipe gone): the first message written raises SIGPIPE,
// which ends the run (status 141) without a file left.
TEST_F(Reliability, AClosedPipeEndsTheRunCleanly) {
  const fs::path cfg = write("long.toml", long_config());
  const fs::path out = dir_ / "out";
  auto p = pisco_test::start_cli({"run", cfg.string(), "-o", out.string()});
  ::close(p.out);  // nobody reads stdout and stderr any more
  p.out = -1;
  int status = 0;
  const auto start = std::chrono::steady_clock::now();
  while (::waitpid(p.pid, &status, WNOHANG) == 0 && std::chrono::steady_clock::now() - start < std::chrono::seconds(60))
    ::usleep(20000);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 128 + SIGPIPE)
      << "status " << status << (WIFSIGNALED(status) ? std::string(", killed by ") + strsignal(WTERMSIG(status)) : "");
  EXPECT_FALSE(fs::exists(out)) << "left: " << joined(files_under(out));
}

// One run per output directory: a second run into it is refused, naming the first's process, and
// leaves the first's files alone; a temporary file of a killed run is removed by the next run there.
TEST_F(Reliability, OneRunPerDirectoryAndStaleTemporariesRemoved) {
  const fs::path cfg = write("long.toml", long_config());
  const fs::path out = dir_ / "out";
  // A user's files whose names look temporary: the killed run's clean-up leaves them.
  fs::create_directories(out);
  std::ofstream(out / "notes.tmp-20261127") << "a user's notes\n";
  std::ofstream(out / "tod.h5.tmp-1") << "a user's file\n";
  auto first = pisco_test::start_cli({"run", cfg.string(), "-o", out.string()});
  bool tried = false;
  CliResult second;
  const CliResult r = pisco_test::finish_cli(first, 120, [&](const std::string&) {
    if (tried || temporaries_under(out).size() <= 2) return;  // the user's two, and none of the run's yet
    second = run_cli({"run", "-q", cfg.string(), "-o", out.string()}, {}, 60);
    tried = true;
    ::kill(first.pid, SIGKILL);  // as a crash or the OOM killer would: the temporary stays
  });
  ASSERT_TRUE(tried) << r.output;
  EXPECT_TRUE(second.exited && second.status == 2 && second.error_lines() == 1 &&
              contains(second.error_line(), "another pisco-vk run (process " + std::to_string(first.pid) + ")"))
      << second.describe() << "\n" << second.output;
  const auto stale = temporaries_under(out);
  ASSERT_GT(stale.size(), 2u) << "the killed run left no temporary file";
  // The next run takes the lock the kernel released, and removes what the killed run left.
  const CliResult third = run_cli({"run", "-q", "--no-plots", cfg.string(), "-o", out.string()}, {}, 120);
  EXPECT_TRUE(third.exited && third.status == 0) << third.describe() << "\n" << third.output;
  EXPECT_TRUE(contains(third.output, "a temporary file left by process " + std::to_string(first.pid) + ", which has ended"))
      << third.output;
  auto left = temporaries_under(out);
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"notes.tmp-20261127", "tod.h5.tmp-1"})) << joined(left);
  EXPECT_FALSE(fs::exists(out / ".pisco-vk.lock"));
}

// The lock file is never opened through a link: a `.pisco-vk.lock` that links to a user's file stops
// the run with one error naming it, and the file keeps every byte.
TEST_F(Reliability, ALinkedLockFileStopsTheRunAndItsTargetSurvives) {
  const fs::path cfg = write("sim.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[scan]\ntype = \"pixel_centres\"\nnside = 16\n"));
  const fs::path out = dir_ / "out", victim = dir_ / "thesis.tex";
  fs::create_directories(out);
  std::ofstream(victim) << "Chapter 1\n";
  for (const bool hard : {false, true}) {
    fs::remove(out / ".pisco-vk.lock");
    if (hard)
      fs::create_hard_link(victim, out / ".pisco-vk.lock");
    else
      fs::create_symlink(victim, out / ".pisco-vk.lock");
    const CliResult r = run_cli({"run", "-q", "--no-plots", cfg.string(), "-o", out.string()});
    EXPECT_TRUE(r.exited && r.status == 2 && r.error_lines() == 1 &&
                contains(r.error_line(), (out / ".pisco-vk.lock").string() + ": ") &&
                contains(r.error_line(), "not a lock file of pisco-vk"))
        << r.describe() << "\n" << r.output;
    std::ifstream in(victim);
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line, "Chapter 1");
    EXPECT_EQ(std::distance(fs::directory_iterator(out), fs::directory_iterator()), 1) << joined(files_under(out));
    EXPECT_TRUE(hard ? fs::is_regular_file(fs::symlink_status(out / ".pisco-vk.lock"))
                     : fs::is_symlink(out / ".pisco-vk.lock"));
  }
}

// A stop signal while the plotting tool runs reaches it: it removes its temporary PNG, and pisco-vk
// exits with 128 + signal; the files written before stay whole.
TEST_F(Reliability, StopSignalReachesThePlottingTool) {
  const fs::path data = fake_plotter(
      "import os, signal, sys, time\n"
      "tmp = os.path.join(sys.argv[-1], 'maps_mollview.png.tmp-%d' % os.getpid())\n"
      "def stop(signum, frame):\n"
      "    os.remove(tmp)\n"
      "    print('fake plotter: stopped by signal %d' % signum, flush=True)\n"
      "    sys.exit(128 + signum)\n"
      "signal.signal(signal.SIGTERM, stop)\n"
      "open(tmp, 'w').write('half a plot')\n"
      "print('fake plotter: plotting', flush=True)\n"
      // Short sleeps: a signal that lands between the print and a long sleep's system call would
      // otherwise wait for that sleep to end before Python runs its handler.
      "for _ in range(600):\n"
      "    time.sleep(0.1)\n");
  const fs::path cfg = write("sim.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = true\n"));
  const fs::path out = dir_ / "out";
  auto p = pisco_test::start_cli({"run", cfg.string(), "-o", out.string()}, {{"PISCO_DATA_DIR", data.string()}});
  bool sent = false;
  const CliResult r = pisco_test::finish_cli(p, 120, [&](const std::string& output) {
    if (!sent && contains(output, "fake plotter: plotting")) {
      ::kill(p.pid, SIGTERM);
      sent = true;
    }
  });
  ASSERT_TRUE(sent) << r.output;
  EXPECT_TRUE(r.exited && r.status == 128 + SIGTERM) << r.describe() << "\n" << r.output;
  EXPECT_TRUE(temporaries_under(out).empty()) << joined(temporaries_under(out)) << "\n" << r.output;
  EXPECT_TRUE(contains(r.output, "fake plotter: stopped by signal 15")) << r.output;
  EXPECT_EQ(pisco::read_tod_signal(out / "tod.h5", "pa").size(), 9216u);
}

// The deconvolving map-maker's warnings: a solve that stops short of its tolerance, and one angle per
// pixel (polarization constrained nowhere: the maps hold I alone) each end the run with a warning
// naming what happened and status 5, every file written.
TEST_F(Reliability, DeconvolutionWarningsExitWithStatus5) {
  const std::string mapmaker = "[mapmaker]\ntype = \"deconvolve\"\niterations = 3\n";
  const fs::path cfg = write("short.toml", config("[sky]\nnside = 16\nlmax = 32\nseed = 3\n",
                                                  "[scan]\ntype = \"pixel_centres\"\nnside = 16\n" + mapmaker));
  const fs::path out = dir_ / "out";
  CliResult r = run_cli({"run", "-q", "--no-plots", cfg.string(), "-o", out.string()});
  std::cout << r.output;
  EXPECT_TRUE(r.exited && r.status == 5) << r.describe();
  EXPECT_TRUE(contains(r.output, "pisco-vk: warning: the deconvolving map-maker did not converge: residual ")) << r.output;
  EXPECT_TRUE(fs::exists(out / "maps.fits") && fs::exists(out / "tod.h5"));

  const fs::path one = write("one.toml", config("[sky]\nnside = 16\nlmax = 32\nseed = 3\n",
                                                "[scan]\ntype = \"pixel_centres\"\nnside = 16\npsi_deg = [0]\n" +
                                                    mapmaker + "tolerance = 0.5\n"));
  r = run_cli({"run", "-q", "--no-plots", one.string(), "-o", (dir_ / "one").string()});
  std::cout << r.output;
  EXPECT_TRUE(r.exited && r.status == 5) << r.describe();
  EXPECT_TRUE(contains(r.output, "pisco-vk: warning: the scan's polarization angles constrain Q and U in no pixel")) << r.output;
  EXPECT_FALSE(contains(r.output, "did not converge")) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "one" / "maps.fits"));
}

// Settings that would make a run quietly wrong or pointless are refused before it starts, naming the
// key: a grid step that does not sample the beam, a disc narrower than the sky's pixels (a TOD of 0),
// a run with nothing to write, and a setting of the file that a backend named on the command line
// does not have (the file form refuses it, so -b does too). No output directory is left behind.
TEST_F(Reliability, RangesOfSettingsAreCheckedBeforeTheRun) {
  const std::string sky = "[sky]\nnside = 32\nlmax = 64\nseed = 3\n";
  const std::string scan = "[scan]\ntype = \"pixel_centres\"\nnside = 16\n";
  const auto refused = [&](const std::string& name, const std::string& text, const std::vector<std::string>& extra,
                           const std::string& needle) {
    const fs::path cfg = write(name, text);
    const fs::path out = dir_ / ("out-" + name);
    std::vector<std::string> args{"run", "-q", "--no-plots", cfg.string(), "-o", out.string()};
    args.insert(args.end(), extra.begin(), extra.end());
    const CliResult r = run_cli(args);
    EXPECT_TRUE(r.exited && r.status == 2 && r.error_lines() == 1 && contains(r.error_line(), needle))
        << name << ": " << r.describe() << "\n" << r.output;
    EXPECT_FALSE(fs::exists(out)) << name;
  };
  const std::string beam = "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n";
  const std::string fp = "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n";
  const auto file = [&](const std::string& beams, const std::string& engine, const std::string& output) {
    return sky + beams + fp + scan + "[engine]\n" + engine + "[output]\nplots = false\nlmax = 32\n" + output;
  };
  refused("step.toml", file(beam + "grid_step_arcmin = 1e6\n", "backend = \"cpu\"\n", ""), {},
          "[beams.main] grid_step_arcmin: a step of 1000000 arcmin is coarser than half of rho_max_deg = 8");
  refused("fwhm.toml", file(beam + "grid_step_arcmin = 150\n", "backend = \"cpu\"\n", ""), {},
          "grid_step_arcmin: a step of 150 arcmin is coarser than half of fwhm_deg = 4 deg");
  refused("narrow.toml",
          file("[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 0.5\nrho_max_deg = 0.5\n", "backend = \"cpu\"\n", ""), {},
          "detector 'pa': its beam's rho_max, 0.5 deg, is below the largest pixel radius of the sky (NSIDE 32)");
  refused("nothing.toml", file(beam, "backend = \"cpu\"\n", "tod = false\nmaps = false\nspectra = false\n"), {},
          "[output] tod = false and maps = false: the run would write nothing");
  refused("b.toml", file(beam, "threads = 2\n", ""), {"-b", "vulkan"},
          "[engine] threads: the vulkan backend has no threads setting (it applies to cpu and simd); the backend "
          "was named after the file (vulkan)");
  // The file form of the same, for comparison: the same refusal.
  refused("bfile.toml", file(beam, "backend = \"vulkan\"\nthreads = 2\n", ""), {},
          "the vulkan backend has no threads setting (it applies to cpu and simd)");
}

// A run whose maps solve no pixel (one polarization angle per pixel) says so on stderr and exits with
// status 4; its TOD and maps are written, no spectra.
TEST_F(Reliability, NoPixelSolvedExitsWithStatus4) {
  const fs::path cfg = write("one.toml", config("[sky]\nnside = 32\nlmax = 64\nseed = 3\n",
                                                "[scan]\ntype = \"pixel_centres\"\nnside = 16\npsi_deg = [0]\n"));
  const fs::path out = dir_ / "out";
  const CliResult r = run_cli({"run", "-q", cfg.string(), "-o", out.string()});
  std::cout << r.output;
  EXPECT_TRUE(r.exited && r.status == 4) << r.describe();
  EXPECT_EQ(r.error_lines(), 0u);
  EXPECT_TRUE(contains(r.output, "pisco-vk: warning: the maps solve no pixel: 3072 of 3072 NSIDE 16 pixels are hit"))
      << r.output;
  EXPECT_TRUE(fs::exists(out / "maps.fits"));
  EXPECT_FALSE(fs::exists(out / "spectra.txt"));
}

// Masked skies through the command line: an error by default (file, column, count, first pixel);
// [sky] unseen = "zero" runs; "flag" flags the samples whose disc holds an UNSEEN pixel in the TOD
// file (as the library flags them) and leaves them out of the maps.
TEST_F(Reliability, MaskedSkies) {
  pisco::Sky sky(16, "K");
  for (std::size_t p = 0; p < sky.npix(); ++p) sky.I()[p] = 1e-3 * std::sin(0.01 * double(p));
  const std::size_t source = pisco::ang2pix(16, 1.0, 2.0);
  std::vector<std::size_t> mask{source, source + 1, 1500};
  for (std::size_t p : mask) sky.I()[p] = pisco::unseen;
  sky.write_fits(dir_ / "masked.fits");
  const std::string beam = "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n";
  auto cfg = [&](const std::string& unseen) {
    return write("m.toml", "[sky]\nfile = \"masked.fits\"\n" + unseen + beam +
                               "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
                               "[scan]\ntype = \"pixel_centres\"\nnside = 16\n[engine]\nbackend = \"cpu\"\n"
                               "[output]\nplots = false\nlmax = 32\n");
  };
  const fs::path out = dir_ / "out";
  const CliResult e = run_cli({"run", "-q", cfg("").string(), "-o", out.string()});
  expect_one_error(e, (dir_ / "masked.fits").string() + ": column 1 (I_STOKES) has 3 UNSEEN pixels");
  EXPECT_TRUE(contains(e.error_line(), "the first at pixel " + std::to_string(std::min(source, std::size_t(1500)))));
  EXPECT_TRUE(files_under(out).empty());
  expect_one_error(run_cli({"run", "-q", write("bad.toml", "[sky]\nnside = 16\nunseen = \"zero\"\n" + beam).string(),
                            "-o", out.string()}),
                   "[sky] unseen: only for a map file");

  const CliResult z = run_cli({"run", cfg("unseen = \"zero\"\n").string(), "-o", out.string()});
  EXPECT_TRUE(z.exited && z.status == 0) << z.output;
  EXPECT_TRUE(contains(z.output, "sky: 3 UNSEEN pixels taken as 0")) << z.output;
  EXPECT_TRUE(pisco::read_tod_flags(out / "tod.h5", "pa").empty());

  const CliResult f = run_cli({"run", cfg("unseen = \"flag\"\n").string(), "-o", out.string()});
  std::cout << f.output;
  ASSERT_TRUE(f.exited && f.status == 0) << f.output;
  // The library's flags for the same scan.
  pisco::Sky kept = pisco::Sky::read_fits(dir_ / "masked.fits", pisco::UnseenPolicy::flag);
  pisco::BeamOptions o;
  o.rho_max = 8 * pisco::deg;
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  pisco::Engine engine(kept, {pisco::Beamsor::gaussian(4 * pisco::deg, o)}, fp, {.unseen = pisco::UnseenPolicy::flag});
  const pisco::Pointing scan = pisco::pixel_centre_scan(16, {0.0, pisco::deg * 45, pisco::deg * 90});
  std::vector<std::uint8_t> want(scan.size());
  const std::size_t n = engine.flag_samples(0, scan.view(), want);
  EXPECT_GT(n, 0u);
  EXPECT_EQ(pisco::read_tod_flags(out / "tod.h5", "pa"), want);
  EXPECT_TRUE(contains(f.output, "flags: " + std::to_string(2 * n) + " of " + std::to_string(2 * scan.size()) +
                                     " samples flagged"))
      << f.output;
  const pisco::Sky hits = pisco::Sky::read_fits(out / "hits.fits");
  const double binned = std::accumulate(hits.I().begin(), hits.I().end(), 0.0);
  EXPECT_EQ(binned, double(2 * (scan.size() - n))) << "flagged samples are left out of the maps";
}

// Errors that name their file and key.
TEST_F(Reliability, ErrorsNameFileAndKey) {
  const fs::path out = dir_ / "out";
  auto run = [&](const std::string& name, const std::string& text, const std::string& needle) {
    const CliResult r = run_cli({"run", "-q", write(name, text).string(), "-o", out.string()});
    std::cout << r.error_line() << "\n";
    expect_one_error(r, needle);
    EXPECT_TRUE(files_under(out).empty()) << joined(files_under(out));
  };
  const std::string sky = "[sky]\nnside = 32\nlmax = 64\nseed = 3\n";
  run("psi.toml", config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\npsi_deg = [0, nan, 90]\n"),
      "psi.toml: [scan] psi_deg[1]: expected a finite number");
  run("ps.toml", config("[sky]\nnside = 32\npoint_source = [190, 0, 1, 0, 0, 0]\n"),
      "ps.toml: [sky] point_source: theta_deg = 190 is outside [0, 180]");
  run("threads.toml", config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\n",
                             "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n", "threads = 1000000\n"),
      "threads.toml: [engine] threads: expected 0 (all hardware threads) or a number of threads up to");
  run("nside.toml", config("[sky]\nnside = 4294967312\n"), "nside.toml: [sky] nside: expected a power of two");
  run("eps.toml",
      config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\n",
             "[focal_plane]\n[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"main\"\nepsilon = -0.1\n"),
      "eps.toml: [focal_plane.detectors[0]] epsilon: expected a cross-polar leakage in [0, 1]");
  run("dup.toml",
      config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\n",
             "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
             "[[focal_plane.detectors]]\nname = \"pb\"\nbeam = \"main\"\n"),
      "dup.toml: [focal_plane.pairs[0]] detector 'pb' is also defined by [focal_plane.detectors[0]]");
  write("fp.csv", "name,zeta_deg,epsilon,beam\nd1,0,0,main\nd2,90,0,main\n# comment\nd1,45,0,main\n");
  run("csv.toml", config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\n",
                         "[focal_plane]\nfile = \"fp.csv\"\n"),
      (dir_ / "fp.csv").string() + ":5: detector 'd1' is also on line 2");
  write("eps.csv", "name,zeta_deg,epsilon,beam\nd1,0,2,main\n");
  run("csv2.toml", config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\n",
                          "[focal_plane]\nfile = \"eps.csv\"\n"),
      (dir_ / "eps.csv").string() + ":2: column 'epsilon': expected a cross-polar leakage in [0, 1], got '2'");
  fs::create_directories(dir_ / "fpdir");
  run("fpdir.toml", config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\n",
                           "[focal_plane]\nfile = \"fpdir\"\n"),
      (dir_ / "fpdir").string() + ": is a directory");
  run("lmax.toml", config(sky, "[scan]\ntype = \"pixel_centres\"\nnside = 16\n", "plots = false\nlmax = 4097\n"),
      "[output] lmax");
  fs::create_directories(dir_ / "conf.d");
  expect_one_error(run_cli({"run", (dir_ / "conf.d").string(), "-o", out.string()}),
                   (dir_ / "conf.d").string() + ": is a directory (expected a TOML file)");
  std::ofstream(dir_ / "afile") << "x";
  expect_one_error(run_cli({"run", "-q", write("ok.toml", config()).string(), "-o", (dir_ / "afile").string()}),
                   (dir_ / "afile").string() + ": cannot create the output directory");
}

}  // namespace
