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

#include "pisco/pisco.hpp"
#include "pisco/scan.hpp"

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

}  // namespace

int run_bench(const BenchOptions& options) {
  const std::vector<double>& radii = options.rho_max_deg;
  // The one-name settings of the command line, on the backend they apply to (an error for one without them).
  pisco::EngineOptions engine_options{.backend = options.backend};
  const auto route = [](const char* flag, auto set) {
    try {
      set();
    } catch (const pisco::Error& e) {
      throw pisco::Error(std::string(flag) + ": " + e.what());
    }
  };
  route("-d/--device", [&] { engine_options.set_device(options.device); });
  route("--threads", [&] { engine_options.set_threads(options.threads); });
  const pisco::Arithmetic arithmetic = pisco::arithmetic_from(options.arithmetic);
  route("--arithmetic", [&] { engine_options.set_arithmetic(arithmetic); });

  const int nside = 128;
  pisco::Sky sky(nside, "uK_CMB");
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0, 1);
  for (std::size_t i = 0; i < sky.npix(); ++i) {
    sky.I()[i] = options.monopole_uk + 100 * g(rng);
    sky.Q()[i] = 5 * g(rng);
    sky.U()[i] = 5 * g(rng);
  }
  const pisco::Pointing scan = pisco::pixel_centre_scan(nside, {0.0, 45 * deg, 90 * deg});
  pisco::FocalPlane fp;
  fp.add_pair("psb", 0.0, 0, 0);
  std::vector<double> hwp_angle;
  if (options.hwp != "none") {
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
    stream.generate(0, scan.size(), hwp_angle);
  }
  const std::size_t samples = scan.size() * fp.size();
  const double beam_step = std::sqrt(4 * std::numbers::pi / (12.0 * 512 * 512));  // beam NSIDE 512

  const std::string monopole =
      options.monopole_uk != 0.0 ? ", monopole " + std::to_string(options.monopole_uk) + " uK" : std::string();
  std::printf("Table 1 workload: NSIDE %d sky, %zu samples (%zu pointings x %zu detectors), "
              "FWHM 1.5 deg, beam grid step %.2f arcmin%s%s\n",
              nside, samples, scan.size(), fp.size(), beam_step / deg * 60,
              options.hwp == "none" ? "" : (", " + options.hwp + " half-wave plate at the " + options.hwp_placement).c_str(),
              monopole.c_str());
  std::printf("%8s %9s %10s %10s %12s %12s %10s\n", "rho_max", "pixels", "setup_s", "conv_s",
              "evals/s", "paper_ms", "speedup");
  for (double rho : radii) {
    const auto t0 = std::chrono::steady_clock::now();
    pisco::BeamOptions o;
    o.rho_max = rho * deg;
    o.grid_step = beam_step;
    std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(1.5 * deg, o)};
    pisco::Engine engine(sky, beams, fp, engine_options);
    const double setup = seconds_since(t0);
    std::vector<double> tod(scan.size());
    // The best of `repeat` runs of each path, the two alternating. conv: the convolution alone (Table
    // 1's figure). With --adjoint the forward path also loads the sky (Engine::set_sky: the backend's
    // sky and the polar copy's transform, made at the first convolution that needs it), as the
    // adjoint path includes take_adjoint (the polar copy's transpose): a map-maker's iteration runs both.
    const double inf = std::numeric_limits<double>::infinity();
    double conv = inf, forward = inf, adjoint = inf, take = inf, normal = inf, iteration = inf;
    for (unsigned rep = 0; rep < options.repeat; ++rep) {
      const auto t0 = std::chrono::steady_clock::now();
      if (options.adjoint) engine.set_sky(sky);
      const auto t1 = std::chrono::steady_clock::now();
      for (std::size_t d = 0; d < fp.size(); ++d) engine.convolve(d, scan, tod, false, hwp_angle);
      conv = std::min(conv, seconds_since(t1));
      const double f = seconds_since(t0);
      forward = std::min(forward, f);
      if (!options.adjoint) continue;
      pisco::Sky back(nside);
      double a = 0.0;
      for (std::size_t d = 0; d < fp.size(); ++d) {
        engine.convolve(d, scan, tod, false, hwp_angle);  // each detector's own TOD, outside the timing
        const auto t3 = std::chrono::steady_clock::now();
        engine.adjoint(d, scan, tod, hwp_angle);
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
      engine.set_sky(sky);
      for (std::size_t d = 0; d < fp.size(); ++d) engine.normal(d, scan, hwp_angle);
      engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
      normal = std::min(normal, seconds_since(t5));
    }
    const double evals = engine.mean_disc_pixels() * double(samples);
    const auto it = paper.find(rho);
    if (it != paper.end())
      std::printf("%8.1f %9.1f %10.3f %10.3f %12.3e %12.1f %10.3f\n", rho, engine.mean_disc_pixels(), setup,
                  conv, evals / conv, it->second.second, it->second.second / 1e3 / (setup + conv));
    else
      std::printf("%8.1f %9.1f %10.3f %10.3f %12.3e %12s %10s\n", rho, engine.mean_disc_pixels(), setup, conv,
                  evals / conv, "-", "-");
    if (options.repeat > 1) std::printf("         best of %u runs of each path\n", options.repeat);
    if (options.adjoint)
      std::printf("         adjoint: %.3f s (take_adjoint %.3f s), %.3e evals/s; forward path with set_sky: %.3f s; "
                  "adjoint / forward: %.2f\n",
                  adjoint, take, evals / adjoint, forward, adjoint / forward);
    if (options.adjoint)
      std::printf("         map-maker iteration (set_sky, then A^T A s): normal pass %.3f s; forward path, then "
                  "adjoint: %.3f s; normal / two passes: %.2f\n",
                  normal, iteration, normal / iteration);
    std::printf("         device: %s\n", engine.device_name().c_str());
  }
  return 0;
}

}  // namespace pisco_cli
