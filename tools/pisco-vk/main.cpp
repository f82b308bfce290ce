// pisco-vk: the command line of PISCO-VK (README.md, "The command line"), a thin layer over the library.
#include <new>
#include <algorithm>
#include <cstdio>
#include <functional>
#include <vector>
#include <filesystem>
#include <string>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <hdf5.h>

#include "bench.hpp"
#include "cluster.hpp"
#include "run.hpp"
#include "signals.hpp"
#include "validation/validation.hpp"

namespace {

namespace fs = std::filesystem;

// Where the bundled examples and tools live: $PISCO_DATA_DIR, an installation's share/pisco, or
// the source tree the program was built from.
fs::path data_dir() {
  if (const char* env = std::getenv("PISCO_DATA_DIR")) return env;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path installed = exe.parent_path().parent_path() / "share" / "pisco";
    if (fs::exists(installed / "assets")) return installed;
  }
  return PISCO_SOURCE_DIR;
}

// A pass/fail table of the validation cases with their figures; the exit status says whether all passed.
struct ValidateOptions {
  bool full = false;
  std::string backend = "cpu";
  std::vector<std::string> cases;  // empty: all
  std::string report_dir;          // F's report; --full defaults to docs/validation
  pisco::validation::SurveyOptions survey;
  std::string spectra_python;      // NaMaster's python for F's report; default <data>/build/spectra-venv
};

int validate(const ValidateOptions& o, const fs::path& data) {
  using namespace pisco::validation;
  const Scale scale = o.full ? Scale::full : Scale::test;
  SurveyOptions survey = o.survey;
  survey.assets_dir = data / "assets";
  survey.report_dir = !o.report_dir.empty() ? fs::path(o.report_dir) : o.full ? fs::path("docs/validation") : fs::path();
  const std::vector<std::pair<std::string, std::function<CaseResult()>>> cases{
      {"C", [&] { return point_source(scale, o.backend); }},
      {"D", [&] { return ideal_cmb(scale, o.backend); }},
      {"E", [&] { return pointing_offsets(scale, o.backend); }},
      {"F", [&] { return class_survey(scale, o.backend, survey); }},
      {"M", [&] { return deconvolved_survey(scale, o.backend, survey); }}};
  for (const auto& c : o.cases)
    if (c != "C" && c != "D" && c != "E" && c != "F" && c != "M")
      throw pisco::Error("validate --case: expected C, D, E, F or M, got '" + c + "'");
  bool all = true;
  for (const auto& [id, run_case] : cases) {
    if (!o.cases.empty() && std::find(o.cases.begin(), o.cases.end(), id) == o.cases.end()) continue;
    const CaseResult r = run_case();
    std::printf("\n%s  %s  [%s, %.1f s]\n", r.id.c_str(), r.title.c_str(), r.pass() ? "pass" : "FAIL", r.seconds);
    for (const auto& n : r.notes) std::printf("    %s\n", n.c_str());
    for (const auto& f : r.figures)
      std::printf("  %-4s %-58s %11.3g %-9s (bar %.3g)\n", f.pass() ? "ok" : "FAIL", f.name.c_str(), f.value,
                  f.unit.c_str(), f.bar);
    std::fflush(stdout);
    all = all && r.pass();
    if (id == "F" && !survey.report_dir.empty()) {
      // NaMaster's mask-corrected spectra and the report's figures (tools/pisco_spectra.py).
      const fs::path python = !o.spectra_python.empty() ? fs::path(o.spectra_python)
                                                        : data / "build" / "spectra-venv" / "bin" / "python";
      if (!fs::exists(python)) {
        std::printf("    spectra: skipped (%s not found: make it with tools/spectra_env.py, or give --spectra-python)\n",
                    python.c_str());
      } else {
        const auto st = pisco_cli::run_child(
            {python.string(), (data / "tools" / "pisco_spectra.py").string(), "--report", (survey.report_dir / "F").string()},
            false);
        if (st.spawn_error || st.code || st.signal) {
          std::printf("    spectra: tools/pisco_spectra.py failed (status %d)\n", st.code);
          all = false;
        }
      }
    }
  }
  std::printf("\nvalidation (%s scale): %s\n", o.full ? "full" : "test", all ? "all cases pass" : "FAILED");
  return all ? 0 : 1;
}

int devices() {
  std::printf("%-8s %-10s %s\n", "backend", "status", "device or reason");
  for (const auto& b : pisco::Engine::backends())
    std::printf("%-8s %-10s %s\n", b.name.c_str(), b.available ? "available" : "missing", b.detail.c_str());
  return 0;
}

// An error's text as one printable line: control characters that came from a file or an argument
// (a newline, an escape sequence) are shown as \xNN rather than acted on by the terminal.
std::string printable(const char* text) {
  std::string out;
  for (const char* p = text; *p; ++p) {
    const auto c = static_cast<unsigned char>(*p);
    if (c < 0x20 || c == 0x7f) {
      char code[5];
      std::snprintf(code, sizeof code, "\\x%02X", c);
      out += code;
    } else {
      out += char(c);
    }
  }
  return out;
}

// The `run` subcommand's arguments.
struct RunArgs {
  std::string config_path, output_dir, backend, device;
  bool quiet = false, no_plots = false;
};

// `pisco-vk run`'s options, read into r; returns the subcommand.
CLI::App* add_run_command(CLI::App& app, RunArgs& r) {
  auto* run = app.add_subcommand("run", "Run a simulation: sky -> TOD -> maps -> spectra (-> plots).");
  run->add_option("config", r.config_path,
                  "Simulation file (TOML). Without one, the bundled quick-start assets/examples/quickstart.toml.");
  run->add_option("-o,--output", r.output_dir, "Output directory (overrides [output] dir).");
  run->add_option("-b,--backend", r.backend, "Backend: auto, cpu, simd, vulkan, cuda (overrides [engine] backend).");
  run->add_option("-d,--device", r.device, "Device of the vulkan or cuda backend: auto, an index or part of its name; "
                                           "simd: an instruction set, e.g. AVX2 "
                                           "(overrides [engine] device; `pisco-vk devices` lists them).");
  run->add_flag("-q,--quiet", r.quiet, "Print nothing but errors.");
  run->add_flag("--no-plots", r.no_plots, "Do not run the plotting tool.");
  return run;
}

// `pisco-vk bench`'s options, read into bench_options.
void add_bench_command(CLI::App& app, pisco_cli::BenchOptions& bench_options) {
  auto* bench = app.add_subcommand("bench", "Benchmark the paper's Table 1 workload (docs/validation.md, case G).");
  bench->add_option("--rho-max", bench_options.rho_max_deg, "Disc radii in degrees (default: 5 10).");
  bench->add_option("-b,--backend", bench_options.backend, "Backend: auto, cpu, simd, vulkan, cuda (default: auto).");
  bench->add_option("-d,--device", bench_options.device, "Device of the vulkan or cuda backend, or the simd backend's instruction set (default: auto).");
  bench->add_option("--threads", bench_options.threads, "cpu and simd backend threads (default: all).");
  // Its values are checked by the library's table of settings (pisco::set_engine_option), as a
  // simulation file's and Python's are.
  bench->add_option("--arithmetic", bench_options.arithmetic,
                    "Vulkan kernel's float64 work: auto, float64, float-float (default: auto).");
  bench->add_option("--hwp", bench_options.hwp,
                    "A half-wave plate before both detectors, turning at 2 Hz: none, ideal, generic (default: none).")
      ->check(CLI::IsMember({"none", "ideal", "generic"}));
  bench->add_option("--monopole", bench_options.monopole_uk,
                    "A monopole added to the sky's I, in uK, e.g. 2.725e6 (default: 0): the float32 backends' "
                    "float64 path.");
  bench->add_flag("--adjoint", bench_options.adjoint,
                  "Also time the adjoint (Engine::adjoint) of the same TOD and its ratio to the forward path.");
  bench->add_option("--beam", bench_options.beam,
                    "The beam: gaussian (round, a radial profile) or elliptical (1.52 x 1.46 deg at 10 deg, CLASS-like: "
                    "the 2D grid) (default: gaussian).")
      ->check(CLI::IsMember({"gaussian", "elliptical"}));
  bench->add_option("--hwp-placement", bench_options.hwp_placement, "aperture or detector (default: aperture).")
      ->check(CLI::IsMember({"aperture", "detector"}));
  bench->add_flag("--stream", bench_options.stream,
                  "Instead: the streamed run's host work per detector-sample (boresight, detector pointing, binning; "
                  "no convolution) on one thread and on --threads.");
  bench->add_option("--repeat", bench_options.repeat,
                    "Time the forward path (and the adjoint) this many times, alternately, and report the best "
                    "of each (default: 1).")
      ->check(CLI::Range(1u, 1000u));
}

// `pisco-vk validate`'s options, read into vo.
void add_validate_command(CLI::App& app, ValidateOptions& vo) {
  auto* val = app.add_subcommand("validate", "Run the paper's validation cases (docs/validation.md, cases C, D, E, F) and the deconvolving map-maker's (M), and print a pass/fail table.");
  val->add_flag("--full", vo.full, "Paper scale (C at three beam resolutions, D and E with an NSIDE 512 sky, F a week of 36 pairs at NSIDE 128); hours on a CPU.");
  val->add_option("-b,--backend", vo.backend, "Backend the cases run through (default: cpu, the reference).");
  val->add_option("--case", vo.cases, "Only these cases (C, D, E, F, M; repeatable).");
  val->add_option("--report-dir", vo.report_dir, "Where F writes its maps, spectra and report.md, and M its spectra and report.md (default with --full: docs/validation).");
  val->add_option("--f-hours", vo.survey.hours, "F: hours of scan instead of the scale's (test 4, full 168).")->check(CLI::PositiveNumber);
  val->add_option("--f-pairs", vo.survey.pairs, "F: PSB pairs instead of the scale's (test 4, full 36).")->check(CLI::Range(1, 400));
  val->add_option("--f-nside", vo.survey.nside, "F: NSIDE of sky and maps instead of the scale's (test 64, full 128).")->check(CLI::IsMember({16, 32, 64, 128, 256, 512}));
  val->add_flag("--f-polarized", vo.survey.polarized, "F: run the polarized case at test scale too.");
  val->add_option("--m-iterations", vo.survey.deconvolve_iterations, "M: conjugate-gradient iterations instead of the case's.")->check(CLI::Range(1, 100000));
  val->add_option("--m-regularization", vo.survey.deconvolve_regularization, "M: the regularization instead of the case's.")->check(CLI::Range(0.0, 1.0));
  val->add_option("--spectra-python", vo.spectra_python, "F: the Python of the NaMaster environment (tools/spectra_env.py; default build/spectra-venv).");
}

// `pisco-vk run`: the simulation file (or the quick-start), the command line's overrides on it, the run.
int run_command(const CLI::App& run, const RunArgs& r, pisco_cli::Cluster& cluster) {
  const fs::path data = data_dir();
  const fs::path config_file =
      r.config_path.empty() ? data / "assets" / "examples" / "quickstart.toml" : fs::path(r.config_path);
  if (run.count("--output") > 0 && r.output_dir.empty())
    throw pisco::Error("-o/--output: expected a directory name, got an empty string");
  pisco::SimulationConfig config;
  cluster.step([&] { config = pisco::read_simulation_file(config_file); });
  if (!r.output_dir.empty()) config.output.dir = r.output_dir;
  if (!r.backend.empty()) config.engine.set_backend(r.backend, config.source);
  if (!r.device.empty()) {
    try {
      pisco::set_engine_option(config.engine.options, "device", r.device);
    } catch (const pisco::Error& e) {
      throw pisco::Error(std::string("-d/--device: ") + e.what());
    }
  }
  pisco_cli::RunOptions options;
  options.quiet = r.quiet;
  options.plots = !r.no_plots;
  options.data_dir = data;
  return pisco_cli::run_simulation(config, options);
}

}  // namespace

static int main_body(int argc, char** argv) {
  // The stop signals (SIGINT, SIGTERM, SIGHUP, ...): stop at once, no temporary file left, status
  // 128 + signal (signals.hpp).
  pisco_cli::handle_stop_signals();
  // HDF5's exit-time clean-up is not needed (every file is closed or abandoned by then), and after a
  // full disk HDF5 1.10's can crash or loop on its own state (docs/formats.md, "Errors and partial
  // files"): the program ends without it. Before any other HDF5 call.
  H5dont_atexit();
  // The processes of the run: MPI's ranks in the MPI build (docs/scaling.md), else this one.
  pisco_cli::Cluster cluster(argc, argv);
  CLI::App app{"PISCO-VK: pixel-space convolution of polarized skies with beamsors, for CMB simulations.",
               "pisco-vk"};
  app.set_version_flag("--version", std::string("pisco-vk ") + pisco::version);
  app.require_subcommand(1);

  RunArgs run_args;
  const CLI::App* run = add_run_command(app, run_args);
  app.add_subcommand("devices", "List the backends, the devices found, and why a backend is missing (not built, or no device).");
  pisco_cli::BenchOptions bench_options;
  add_bench_command(app, bench_options);
  ValidateOptions vo;
  add_validate_command(app, vo);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  try {
    if (app.got_subcommand("devices")) return devices();
    if (app.got_subcommand("bench"))
      return bench_options.stream ? pisco_cli::run_stream_bench(bench_options) : pisco_cli::run_bench(bench_options);
    if (app.got_subcommand("validate")) return validate(vo, data_dir());
    return run_command(*run, run_args, cluster);
  } catch (const pisco_cli::AgreedError& e) {
    pisco_cli::wait_for_stop();  // an error caused by a stop signal (a write cut off): the signal's status
    // Every rank has it (a single process: always): said once.
    if (cluster.leader()) std::fprintf(stderr, "pisco-vk: error: %s\n", printable(e.what()).c_str());
    std::fflush(stderr);
    cluster.finalize();
    return 2;
  } catch (const pisco::Error& e) {
    pisco_cli::wait_for_stop();
    if (cluster.parallel()) {
      // One rank's error outside the collective steps: the others cannot be told, and are ended.
      std::fprintf(stderr, "pisco-vk: error: rank %d: %s\n", cluster.rank(), printable(e.what()).c_str());
      cluster.abort(2);
    }
    std::fprintf(stderr, "pisco-vk: error: %s\n", printable(e.what()).c_str());
    return 2;
  } catch (const std::bad_alloc&) {
    // Memory that ran out where no reader named what it was allocating: not a bug, an input or a
    // machine too large for each other.
    pisco_cli::wait_for_stop();
    const char* what = "this machine's memory ran out (std::bad_alloc); a smaller sky, beam grid or chunk, or a "
                       "machine with more memory, is needed";
    if (cluster.parallel()) {
      std::fprintf(stderr, "pisco-vk: error: rank %d: %s\n", cluster.rank(), what);
      cluster.abort(2);
    }
    std::fprintf(stderr, "pisco-vk: error: %s\n", what);
    return 2;
  } catch (const std::exception& e) {
    pisco_cli::wait_for_stop();
    if (cluster.parallel()) {
      std::fprintf(stderr, "pisco-vk: error: rank %d: %s\n", cluster.rank(), printable(e.what()).c_str());
      cluster.abort(3);
    }
    std::fprintf(stderr, "pisco-vk: error: %s\n", printable(e.what()).c_str());
    return 3;
  }
}

int main(int argc, char** argv) {
  const int status = main_body(argc, argv);
  pisco_cli::wait_for_stop();  // a stop signal came: the watcher ends the process with 128 + signal
  return status;
}
