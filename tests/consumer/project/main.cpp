// A consumer of the installed package: an ideal detector on a constant I = 1 sky measures I / 2.
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include <pisco/pisco.hpp>

int main() {
  constexpr double deg = std::numbers::pi / 180;
  pisco::Sky sky(64);
  for (double& v : sky.I()) v = 1.0;
  pisco::BeamOptions options;
  options.rho_max = 5 * deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(1.5 * deg, options)};
  pisco::FocalPlane fp;
  fp.add({"det", 0.0, 0.0, 1.0, 0});
  pisco::Engine engine(sky, beams, fp);
  pisco::Pointing pointing;
  for (int i = 0; i < 8; ++i) pointing.push_back(0.3 + 0.3 * i, 0.7 * i, 0.1 * i);
  std::vector<double> tod(pointing.size());
  engine.convolve(0, pointing, tod);
  int bad = 0;
  for (double d : tod) {
    std::printf("%.6f\n", d);
    bad += std::abs(d - 0.5) > 1e-2;
  }
  std::printf("pisco %s: %d of %zu samples off I/2\n", pisco::version, bad, tod.size());
  return bad ? 1 : 0;
}
