// A consumer of the installed package: an ideal detector on a constant I = 1 sky measures I / 2.
#include <cmath>
#include <cstdio>
#include <exception>
#include <span>
#include <vector>

// Every installed header must compile from the prefix: the operator's umbrella, then the pipeline's.
#include <pisco/pisco.hpp>
#include <pisco/deconvolution.hpp>
#include <pisco/mapmaker.hpp>
#include <pisco/mismatch.hpp>
#include <pisco/output_file.hpp>
#include <pisco/pointing_file.hpp>
#include <pisco/scan.hpp>
#include <pisco/simulation.hpp>
#include <pisco/simulation_config.hpp>
#include <pisco/spectra.hpp>
#include <pisco/time_ranges.hpp>
#include <pisco/tod_file.hpp>

int main() try {
  using pisco::deg;  // pisco/units.hpp: radians per degree
  // NSIDE 64 (0.92 deg pixels) resolves the 1.5 deg beam: with the default integral normalization
  // the TOD is then within ~2e-3 of I/2; at NSIDE 16 (3.7 deg pixels) it is off by up to 0.9.
  pisco::Sky sky(64);
  for (double& v : sky.I()) v = 1.0;

  pisco::BeamOptions options;
  options.rho_max = 5 * deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(1.5 * deg, options)};

  pisco::FocalPlane focal_plane;
  focal_plane.add({"det", 0.0, 0.0, 1.0, 0});  // name, zeta, epsilon, gain, beam

  pisco::Engine engine(sky, beams, focal_plane);

  pisco::Pointing pointing;
  for (int i = 0; i < 8; ++i) pointing.push_back(0.3 + 0.3 * i, 0.7 * i, 0.1 * i);
  std::vector<double> tod(pointing.size());
  engine.convolve(0, pointing.view(), std::span<double>(tod));

  int bad = 0;
  for (std::size_t i = 0; i < tod.size(); ++i) {
    const bool off = !(std::abs(tod[i] - 0.5) <= 1e-2);  // NaN counts as off
    bad += off;
    std::printf("sample %zu: tod = %.6f%s\n", i, tod[i], off ? "  <-- expected 0.5 +- 1e-2" : "");
  }
  std::printf("pisco %s (backend %s): %d of %zu samples off I/2\n", pisco::version,
              engine.backend_name().c_str(), bad, tod.size());
  return bad ? 1 : 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "consumer: %s\n", e.what());
  return 2;
}
