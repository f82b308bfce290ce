// pisco-setup-bench: the time and host memory an engine takes to set up on a large sky, per backend.
//   pisco-setup-bench NSIDE BACKEND [DEVICE]
// Builds a random full-sky I, Q, U map of NSIDE (what a Planck-resolution sky costs, without reading
// one), one 5 arcmin Gaussian beam and a PSB pair, then constructs pisco::Engine and convolves 1000
// samples. Prints the sky's own float64 size, the set-up time, and the process's peak resident memory
// (getrusage) before and after the engine, so that runs of different backends (one process each)
// compare as ratios to the sky's size. Uses only the public API.
#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "pisco/pisco.hpp"

namespace {

double peak_gib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / (1024.0 * 1024.0);  // ru_maxrss is in KiB on Linux
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s NSIDE BACKEND [DEVICE]\n", argv[0]);
    return 2;
  }
  try {
    const int nside = std::atoi(argv[1]);
    const std::string backend = argv[2];
    const std::string device = argc > 3 ? argv[3] : "auto";
    using pisco::deg;
    pisco::Sky sky(nside, "K_CMB");
    std::uint64_t x = 88172645463325252ull;  // xorshift: a cheap, deterministic noise sky
    auto next = [&] {
      x ^= x << 13;
      x ^= x >> 7;
      x ^= x << 17;
      return double(x >> 11) * 0x1.0p-53 - 0.5;
    };
    for (std::size_t i = 0; i < sky.npix(); ++i) {
      sky.I()[i] = 1e-4 * next();
      sky.Q()[i] = 1e-5 * next();
      sky.U()[i] = 1e-5 * next();
    }
    const double sky_gib = double(sky.npix()) * 4 * sizeof(double) / (1024.0 * 1024.0 * 1024.0);
    pisco::BeamOptions o;
    o.rho_max = 0.5 * deg;
    std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(5.0 / 60 * deg, o)};
    pisco::FocalPlane fp;
    fp.add_pair("p", 0.0, 0, 0);
    const double before = peak_gib();
    const auto t0 = std::chrono::steady_clock::now();
    pisco::EngineOptions options{.backend = backend};
    options.set("device", device);
    pisco::Engine engine(sky, beams, fp, options);
    const double setup = seconds_since(t0);
    const double after_setup = peak_gib();
    pisco::Pointing p;
    for (int i = 0; i < 1000; ++i) p.push_back(0.1 + 2.9 * i / 1000.0, 0.37 * i, 0.0);
    std::vector<double> tod(p.size());
    const auto t1 = std::chrono::steady_clock::now();
    engine.convolve(0, p, tod);
    const double conv = seconds_since(t1);
    std::printf("nside %d backend %s: sky %.2f GiB (float64 I,Q,U,V), set-up %.2f s, peak RSS %.2f GiB before the "
                "engine, %.2f GiB after set-up (%.2f x the sky), 1000 samples in %.3f s\n  device: %s\n",
                nside, engine.backend_name().c_str(), sky_gib, setup, before, after_setup, after_setup / sky_gib, conv,
                engine.device_name().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pisco-setup-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
