// `pisco-vk bench`: the paper's Table 1 workload (docs/validation.md, "G"): a full-sky NSIDE 128 sky, every
// pixel centre at psi = 0, 45, 90 deg for two detectors (1,179,648 samples), a 1.5 deg Gaussian beam
// on a grid as fine as a beam NSIDE of 512.
#include "bench.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <thread>

#include "core/detector_pointing.hpp"
#include "core/thread_pool.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/pisco.hpp"
#include "pisco/scan.hpp"
#include "validation/validation.hpp"

namespace pisco_cli {
namespace {

using pisco::deg;

// The paper's GTX 1080 wall times (Table 1), ms, by rho_max in degrees.
const std::map<double, std::pair<int, double>> paper = {
    {5.0, {374, 1471.41}},   {7.5, {832, 3135.19}},   {10.0, {1506, 5560.25}}, {15.0, {3360, 12719.56}},
    {20.0, {5938, 23190.68}}, {25.0, {9218, 39447.70}}, {30.0, {13174, 53800.74}}};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The one-name settings of the command line, on the backend they apply to (an error for one without
// them), through the library's table of settings; an error names the flag.
pisco::EngineOptions bench_engine_options(const BenchOptions& options) {
  pisco::EngineOptions engine_options;
  const std::pair<const char*, pisco::EngineValue> given[] = {
      {"backend", options.backend},
      {"device", options.device},
      {"threads", static_cast<long long>(options.threads)},
      {"arithmetic", options.arithmetic}};
  for (const auto& [name, value] : given) {
    try {
      pisco::set_engine_option(engine_options, name, value);
    } catch (const pisco::Error& e) {
      const std::string key = e.key().empty() ? name : e.key();
      throw pisco::Error((key == "device" ? "-d/--device" : key == "backend" ? "-b/--backend" : "--" + key) + ": " +
                         e.what());
    }
  }
  return engine_options;
}

// The benchmark's sky: I the monopole (uK) plus 100 uK of white noise, Q and U 5 uK of it.
pisco::Sky bench_sky(int nside, double monopole_uk) {
  pisco::Sky sky(nside, "uK_CMB");
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0, 1);
  for (std::size_t i = 0; i < sky.npix(); ++i) {
    sky.I()[i] = monopole_uk + 100 * g(rng);
    sky.Q()[i] = 5 * g(rng);
    sky.U()[i] = 5 * g(rng);
  }
  return sky;
}

// --hwp: the plate (ideal, or generic) before each detector of `fp`, and its angle at each of the scan's
// samples, turning at 2 Hz.
void add_bench_plate(const BenchOptions& options, std::size_t scan_samples, pisco::FocalPlane& fp,
                     std::vector<double>& hwp_angle) {
  pisco::Mueller m = pisco::ideal_hwp_mueller();
  if (options.hwp == "generic") {
    // Every entry perturbed, the plate a little lossy (M00 < 1) so that it stays passive
    // (docs/physics.md, "Physical bounds on Mueller matrices").
    const double leak[4][4] = {{-0.02, 0.012, -0.008, 0.005},
                               {0.021, -0.03, 0.017, -0.011},
                               {-0.015, 0.009, 0.025, 0.04},
                               {0.007, -0.02, 0.033, 0.02}};
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) m[i][j] += leak[i][j];
  }
  std::vector<pisco::Detector> dets = fp.detectors();
  for (auto& d : dets)
    d.hwp = pisco::HalfWavePlate{m, options.hwp_placement == "detector" ? pisco::HwpPlacement::detector
                                                                        : pisco::HwpPlacement::aperture,
                                 d.zeta};
  fp = pisco::FocalPlane(dets);
  pisco::HwpAngleStream stream;
  stream.frequency_hz = 2.0;
  stream.sample_rate = 200.0;
  stream.generate(0, scan_samples, hwp_angle);
}

// The workload each disc radius is timed on.
struct BenchWorkload {
  int nside;
  const pisco::Sky& sky;
  const pisco::Pointing& scan;
  const pisco::FocalPlane& fp;
  const std::vector<double>& hwp_angle;
  std::size_t samples;  // pointings x detectors
  double beam_step;     // radians
};

// The workload's description and the table's header.
void print_bench_header(const BenchOptions& options, const BenchWorkload& w) {
  const std::string monopole =
      options.monopole_uk != 0.0 ? ", monopole " + std::to_string(options.monopole_uk) + " uK" : std::string();
  std::printf("Table 1 workload: NSIDE %d sky, %zu samples (%zu pointings x %zu detectors), "
              "%s, beam grid step %.2f arcmin%s%s\n",
              w.nside, w.samples, w.scan.size(), w.fp.size(),
              options.beam == "elliptical" ? "elliptical beam 1.52 x 1.46 deg FWHM (2D grid)" : "FWHM 1.5 deg",
              w.beam_step / deg * 60,
              options.hwp == "none" ? "" : (", " + options.hwp + " half-wave plate at the " + options.hwp_placement).c_str(),
              monopole.c_str());
  std::printf("%8s %9s %10s %10s %12s %12s %10s\n", "rho_max", "pixels", "setup_s", "conv_s",
              "evals/s", "paper_ms", "speedup");
}

// The best time of each path over --repeat runs, seconds.
struct BenchTimes {
  double conv, forward, adjoint, take, normal, iteration, host;
};

// The best of `repeat` runs of each path, the two alternating. conv: the convolution alone (Table
// 1's figure): every detector submitted on the shared pointing, then one wait. With --adjoint the forward path also loads
// the sky (Engine::set_sky: the backend's sky and the polar copy's transform, completed by
// Engine::prepare), as the adjoint path includes take_adjoint (the polar copy's transpose): a
// map-maker's iteration runs both.
BenchTimes time_bench_paths(pisco::Engine& engine, const BenchWorkload& w, const BenchOptions& options) {
  const pisco::FocalPlane& fp = w.fp;
  const pisco::Pointing& scan = w.scan;
  std::vector<double> tod(scan.size());
  std::vector<std::vector<double>> tods(fp.size(), std::vector<double>(scan.size()));
  const double inf = std::numeric_limits<double>::infinity();
  double conv = inf, forward = inf, adjoint = inf, take = inf, normal = inf, iteration = inf, host = inf;
  for (unsigned rep = 0; rep < options.repeat; ++rep) {
    const auto t0 = std::chrono::steady_clock::now();
    if (options.adjoint) {
      engine.set_sky(w.sky);
      engine.prepare();
    }
    const double host0 = engine.host_seconds();
    const auto t1 = std::chrono::steady_clock::now();
    // The detectors read the same pointing: shared, it is checked once (Engine::share).
    const pisco::SharedPointing shared = engine.share(scan.view());
    for (std::size_t d = 0; d < fp.size(); ++d) engine.submit(d, shared, tods[d], false, w.hwp_angle);
    engine.wait();
    conv = std::min(conv, seconds_since(t1));
    host = std::min(host, engine.host_seconds() - host0);
    const double f = seconds_since(t0);
    forward = std::min(forward, f);
    if (!options.adjoint) continue;
    pisco::Sky back(w.nside);
    double a = 0.0;
    for (std::size_t d = 0; d < fp.size(); ++d) {
      engine.convolve(d, scan, tod, false, w.hwp_angle);  // each detector's own TOD, outside the timing
      const auto t3 = std::chrono::steady_clock::now();
      engine.adjoint(d, scan, tod, w.hwp_angle);
      a += seconds_since(t3);
    }
    const auto t4 = std::chrono::steady_clock::now();
    engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
    const double t = seconds_since(t4);
    if (a + t < adjoint) {
      adjoint = a + t;
      take = t;
    }
    iteration = std::min(iteration, f + a + t);
    // The same iteration through Engine::normal (one pass where the backend evaluates each disc once).
    const auto t5 = std::chrono::steady_clock::now();
    engine.set_sky(w.sky);
    for (std::size_t d = 0; d < fp.size(); ++d) engine.normal(d, scan, w.hwp_angle);
    engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
    normal = std::min(normal, seconds_since(t5));
  }
  return {conv, forward, adjoint, take, normal, iteration, host};
}

// A disc radius's row of the table (beside the paper's time where it has one), and its notes.
void print_bench_row(double rho, const pisco::Engine& engine, double setup, const BenchTimes& t, std::size_t samples,
                     const BenchOptions& options) {
  const double evals = engine.mean_disc_pixels() * double(samples);
  const auto it = paper.find(rho);
  if (it != paper.end())
    std::printf("%8.1f %9.1f %10.3f %10.3f %12.3e %12.1f %10.3f\n", rho, engine.mean_disc_pixels(), setup,
                t.conv, evals / t.conv, it->second.second, it->second.second / 1e3 / (setup + t.conv));
  else
    std::printf("%8.1f %9.1f %10.3f %10.3f %12.3e %12s %10s\n", rho, engine.mean_disc_pixels(), setup, t.conv,
                evals / t.conv, "-", "-");
  if (options.repeat > 1) std::printf("         best of %u runs of each path\n", options.repeat);
  std::printf("         set-up %.3f s (the engine and the polar copy), apart from conv; the engine's own host work in "
              "conv: %.1f ns/sample (%.3f s)\n",
              setup, t.host / double(samples) * 1e9, t.host);
  if (options.adjoint)
    std::printf("         adjoint: %.3f s (take_adjoint %.3f s), %.3e evals/s; forward path with set_sky: %.3f s; "
                "adjoint / forward: %.2f\n",
                t.adjoint, t.take, evals / t.adjoint, t.forward, t.adjoint / t.forward);
  if (options.adjoint)
    std::printf("         map-maker iteration (set_sky, then A^T A s): normal pass %.3f s; forward path, then "
                "adjoint: %.3f s; normal / two passes: %.2f\n",
                t.normal, t.iteration, t.normal / t.iteration);
  std::printf("         device: %s\n", engine.device_name().c_str());
}

// One disc radius: the beam and the engine set up (timed apart), the paths timed, the row printed.
void bench_radius(double rho, const BenchWorkload& w, const pisco::EngineOptions& engine_options,
                  const BenchOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  pisco::BeamOptions o;
  o.rho_max = rho * deg;
  o.grid_step = w.beam_step;
  std::vector<pisco::Beamsor> beams{options.beam == "elliptical"
                                        ? pisco::Beamsor::elliptical_gaussian(1.52 * deg, 1.46 * deg, 10 * deg, o)
                                        : pisco::Beamsor::gaussian(1.5 * deg, o)};
  pisco::Engine engine(w.sky, beams, w.fp, engine_options);
  engine.prepare();  // the polar copy, which would otherwise be made by the first convolution
  const double setup = seconds_since(t0);
  const BenchTimes t = time_bench_paths(engine, w, options);
  print_bench_row(rho, engine, setup, t, w.samples, options);
}

}  // namespace

int run_bench(const BenchOptions& options) {
  const pisco::EngineOptions engine_options = bench_engine_options(options);
  const int nside = 128;
  const pisco::Sky sky = bench_sky(nside, options.monopole_uk);
  const pisco::Pointing scan = pisco::pixel_centre_scan(nside, {0.0, 45 * deg, 90 * deg});
  pisco::FocalPlane fp;
  fp.add_pair("psb", 0.0, 0, 0);
  std::vector<double> hwp_angle;
  if (options.hwp != "none") add_bench_plate(options, scan.size(), fp, hwp_angle);
  const double beam_step = std::sqrt(4 * std::numbers::pi / (12.0 * 512 * 512));  // beam NSIDE 512
  const BenchWorkload w{nside, sky, scan, fp, hwp_angle, scan.size() * fp.size(), beam_step};
  print_bench_header(options, w);
  for (double rho : options.rho_max_deg) bench_radius(rho, w, engine_options, options);
  return 0;
}

// The streamed run's host work (docs/simd.md, "The stream's host work"): what JobStream does per
// detector-sample besides the convolution, for a CLASS-like run (paper section 7: constant-elevation
// scans from the Atacama at 20 Hz, 36 PSB pairs over a 10 deg focal plane, maps at NSIDE 128). The
// boresight (here on one thread) and its quaternions are made once per time chunk for all detectors;
// then per detector-sample the binning from the boresight, which a run does, and beside it the path
// before (each detector's angles, then BinnedMapmaker::add), on one thread and on the host's threads.
// Then the engine's own host work per detector-sample (Engine::host_seconds: the checks, the polar
// test, completing and checking each TOD), each detector's submission checking its pointing or the
// chunk shared (Engine::share), over a beam of a few pixels so that the convolution stays small.
int run_stream_bench(const BenchOptions& options) {
  const std::size_t chunk = std::size_t(1) << 16, chunks = 4;
  const pisco::CesScan ces = pisco::validation::class_like_scan(chunk * chunks);
  std::vector<pisco::Detector> dets;
  for (int k = 0; k < 36; ++k) {
    pisco::FocalPlane pair;
    std::string name = "p";  // (not "p" + to_string: GCC 12 warns, -Wrestrict, of a memcpy it cannot reach)
    name += std::to_string(k);
    pair.add_pair(name, (k % 2) * 45 * deg, 0, 0);
    for (pisco::Detector d : pair.detectors()) {
      d.set_offset((k % 6 - 2.5) * 2 * deg, (k / 6 - 2.5) * 2 * deg, 0.0);
      dets.push_back(d);
    }
  }
  const unsigned threads = options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  std::printf("streamed host work: CLASS-like constant-elevation scan, %zu detectors x %zu samples in chunks of %zu, "
              "maps NSIDE 128, no convolution (the backend's work left out); ns per detector-sample\n",
              dets.size(), ces.samples, chunk);
  std::printf("  boresight: the scan's angles, once per chunk; quaternions: those as quaternions, once per chunk;\n"
              "  from_boresight: BinnedMapmaker::add_from_boresight, what a run does (total = the three);\n"
              "  pointing + binning: each detector's angles, then BinnedMapmaker::add, the path before\n");
  std::printf("%8s %12s %12s %15s %12s %12s %10s\n", "threads", "boresight", "quaternions", "from_boresight",
              "pointing", "binning", "total");
  pisco::Pointing boresight, own;
  std::vector<pisco::Quat> quats;
  std::vector<double> tod(chunk, 1.0);
  const double per = double(dets.size()) * double(ces.samples);  // detector-samples
  const double inf = std::numeric_limits<double>::infinity();
  for (const unsigned n : threads > 1 ? std::vector<unsigned>{1u, threads} : std::vector<unsigned>{1u}) {
    pisco::BinnedMapmaker mapper(128), before(128);
    mapper.set_threads(n);
    before.set_threads(n);
    pisco::detail::ThreadPool pool(n);
    double best[5] = {inf, inf, inf, inf, inf};
    for (unsigned rep = 0; rep < std::max(1u, options.repeat); ++rep) {
      double t[5] = {0, 0, 0, 0, 0};
      for (std::size_t c = 0; c < chunks; ++c) {
        auto t0 = std::chrono::steady_clock::now();
        ces.generate(c * chunk, chunk, boresight);
        t[0] += seconds_since(t0);
        t0 = std::chrono::steady_clock::now();
        pisco::detail::pointing_quats(boresight.view(), quats, pool);
        t[1] += seconds_since(t0);
        for (const pisco::Detector& d : dets) {
          t0 = std::chrono::steady_clock::now();
          mapper.add_from_boresight(d, pisco::QuatPointingView{quats}, tod);
          t[2] += seconds_since(t0);
          t0 = std::chrono::steady_clock::now();
          pisco::detail::detector_pointing(boresight.view(), d.offset, own, pool);
          t[3] += seconds_since(t0);
          t0 = std::chrono::steady_clock::now();
          before.add(d, own, tod);
          t[4] += seconds_since(t0);
        }
      }
      for (int k = 0; k < 5; ++k) best[k] = std::min(best[k], t[k]);
    }
    const auto ns = [&](double s) { return s / per * 1e9; };
    std::printf("%8u %12.2f %12.2f %15.2f %12.2f %12.2f %10.2f\n", n, ns(best[0]), ns(best[1]), ns(best[2]), ns(best[3]),
                ns(best[4]), ns(best[0] + best[1] + best[2]));
  }
  if (options.repeat > 1) std::printf("         best of %u runs\n", options.repeat);

  // The engine on the chosen backend with its own threads: --threads sets the host work's above,
  // and a device backend takes none.
  BenchOptions engine_bench = options;
  engine_bench.threads = 0;
  const pisco::EngineOptions engine_options = bench_engine_options(engine_bench);
  pisco::BeamOptions small;
  small.rho_max = 0.5 * deg;
  pisco::Engine engine(bench_sky(128, 0.0), {pisco::Beamsor::gaussian(0.5 * deg, small)}, pisco::FocalPlane(dets),
                       engine_options);
  engine.prepare();
  std::printf("engine host work (%s backend): ns per detector-sample on the calling thread; pointing staged\n"
              "  for the device per detector-sample (0: a backend that reads the caller's pointing where it lies)\n",
              engine.backend_name().c_str());
  std::printf("%26s %12s %12s\n", "", "host work", "staged");
  const char* forms[] = {"a detector at a time", "the chunk shared"};
  double best_host[2] = {inf, inf}, staged[2] = {0, 0};
  std::vector<std::vector<double>> tods(dets.size(), std::vector<double>(chunk));
  for (unsigned rep = 0; rep < std::max(1u, options.repeat); ++rep)
    for (int form = 0; form < 2; ++form) {
      const double host0 = engine.host_seconds();
      const std::uint64_t staged0 = engine.staged_samples();
      for (std::size_t c = 0; c < chunks; ++c) {
        ces.generate(c * chunk, chunk, boresight);
        if (form == 0) {
          for (std::size_t d = 0; d < dets.size(); ++d) engine.submit(d, boresight.view(), tods[d]);
        } else {
          const pisco::SharedPointing shared = engine.share(boresight.view());
          for (std::size_t d = 0; d < dets.size(); ++d) engine.submit(d, shared, tods[d]);
        }
        engine.wait();
      }
      best_host[form] = std::min(best_host[form], engine.host_seconds() - host0);
      staged[form] = double(engine.staged_samples() - staged0) / per;
    }
  for (int form = 0; form < 2; ++form)
    std::printf("%26s %12.2f %12.3f\n", forms[form], best_host[form] / per * 1e9, staged[form]);
  std::printf("  mean disc: %.1f pixels\n", engine.mean_disc_pixels());
  return 0;
}

}  // namespace pisco_cli
