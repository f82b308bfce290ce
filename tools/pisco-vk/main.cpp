// pisco-vk: the command line of PISCO-VK (README.md, "The command line"), a thin layer over the library.
#include <cstdio>
#include <filesystem>
#include <string>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <hdf5.h>

#include "bench.hpp"
#include "cluster.hpp"
#include "config.hpp"
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
int validate(bool full, const std::string& backend) {
  using namespace pisco::validation;
  bool all = true;
  for (const auto& run_case : all_cases(backend)) {
    const CaseResult r = run_case(full ? Scale::full : Scale::test);
    std::printf("\n%s  %s  [%s, %.1f s]\n", r.id.c_str(), r.title.c_str(), r.pass() ? "pass" : "FAIL", r.seconds);
    for (const auto& n : r.notes) std::printf("    %s\n", n.c_str());
    for (const auto& f : r.figures)
      std::printf("  %-4s %-58s %11.3g %-9s (bar %.3g)\n", f.pass() ? "ok" : "FAIL", f.name.c_str(), f.value,
                  f.unit.c_str(), f.bar);
    std::fflush(stdout);
    all = all && r.pass();
  }
  std::printf("\nvalidation (%s scale): %s\n", full ? "full" : "test", all ? "all cases pass" : "FAILED");
  return all ? 0 : 1;
}

int devices() {
  std::printf("%-8s %-10s %s\n", "backend", "status", "device or reason");
  for (const auto& b : pisco::Engine::backends())
    std::printf("%-8s %-10s %s\n", b.name.c_str(), b.available ? "available" : "missing", b.detail.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // SIGINT, SIGTERM, SIGHUP: stop at once, no temporary file left, status 128 + signal (signals.hpp).
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

  auto* run = app.add_subcommand("run", "Run a simulation: sky -> TOD -> maps -> spectra (-> plots).");
  std::string config_path, output_dir, backend, device;
  bool quiet = false, no_plots = false;
  run->add_option("config", config_path,
                  "Simulation file (TOML). Without one, the bundled quick-start assets/examples/quickstart.toml.");
  run->add_option("-o,--output", output_dir, "Output directory (overrides [output] dir).");
  run->add_option("-b,--backend", backend, "Backend: auto, cpu, simd, vulkan, cuda (overrides [engine] backend).");
  run->add_option("-d,--device", device, "Device of the vulkan or cuda backend: auto, an index or part of its name; "
                                         "simd: an instruction set, e.g. AVX2 "
                                         "(overrides [engine] device; `pisco-vk devices` lists them).");
  run->add_flag("-q,--quiet", quiet, "Print nothing but errors.");
  run->add_flag("--no-plots", no_plots, "Do not run the plotting tool.");

  app.add_subcommand("devices", "List the backends compiled in, the devices found, and why a backend is missing.");

  auto* bench = app.add_subcommand("bench", "Benchmark the paper's Table 1 workload (docs/validation.md, case G).");
  pisco_cli::BenchOptions bench_options;
  bench->add_option("--rho-max", bench_options.rho_max_deg, "Disc radii in degrees (default: 5 10).");
  bench->add_option("-b,--backend", bench_options.backend, "Backend: auto, cpu, simd, vulkan, cuda (default: auto).");
  bench->add_option("-d,--device", bench_options.device, "Device of the vulkan or cuda backend, or the simd backend's instruction set (default: auto).");
  bench->add_option("--threads", bench_options.threads, "cpu and simd backend threads (default: all).");
  bench->add_option("--hwp", bench_options.hwp,
                    "A half-wave plate before both detectors, turning at 2 Hz: none, ideal, generic (default: none).")
      ->check(CLI::IsMember({"none", "ideal", "generic"}));
  bench->add_option("--monopole", bench_options.monopole_uk,
                    "A monopole added to the sky's I, in uK, e.g. 2.725e6 (default: 0): the float32 backends' "
                    "float64 path.");
  bench->add_option("--hwp-placement", bench_options.hwp_placement, "aperture or detector (default: aperture).")
      ->check(CLI::IsMember({"aperture", "detector"}));

  auto* val = app.add_subcommand("validate", "Run the paper's validation cases (docs/validation.md, cases C, D, E) and print a pass/fail table.");
  bool full = false;
  std::string validate_backend = "cpu";
  val->add_flag("--full", full, "Paper scale (C at three beam resolutions, D with an NSIDE 512 sky); minutes on a CPU.");
  val->add_option("-b,--backend", validate_backend, "Backend the cases run through (default: cpu, the reference).");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  try {
    if (app.got_subcommand("devices")) return devices();
    if (app.got_subcommand("bench")) return pisco_cli::run_bench(bench_options);
    if (app.got_subcommand("validate")) return validate(full, validate_backend);
    const fs::path data = data_dir();
    const fs::path config_file = config_path.empty() ? data / "assets" / "examples" / "quickstart.toml" : fs::path(config_path);
    pisco_cli::SimulationConfig config;
    cluster.step([&] { config = pisco_cli::load_config(config_file); });
    if (!output_dir.empty()) config.output.dir = output_dir;
    if (!backend.empty()) config.engine.options.backend = backend;
    if (!device.empty()) config.engine.options.device = device;
    pisco_cli::RunOptions options;
    options.quiet = quiet;
    options.plots = !no_plots;
    options.data_dir = data;
    return pisco_cli::run_simulation(config, options);
  } catch (const pisco_cli::AgreedError& e) {
    // Every rank has it (a single process: always): said once.
    if (cluster.leader()) std::fprintf(stderr, "pisco-vk: error: %s\n", e.what());
    std::fflush(stderr);
    cluster.finalize();
    return 2;
  } catch (const pisco::Error& e) {
    if (cluster.parallel()) {
      // One rank's error outside the collective steps: the others cannot be told, and are ended.
      std::fprintf(stderr, "pisco-vk: error: rank %d: %s\n", cluster.rank(), e.what());
      cluster.abort(2);
    }
    std::fprintf(stderr, "pisco-vk: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    if (cluster.parallel()) {
      std::fprintf(stderr, "pisco-vk: error: rank %d: %s\n", cluster.rank(), e.what());
      cluster.abort(3);
    }
    std::fprintf(stderr, "pisco-vk: error: %s\n", e.what());
    return 3;
  }
}
