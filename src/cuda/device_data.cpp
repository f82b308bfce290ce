#include "cuda/device_data.hpp"

#include <cmath>

namespace pisco::detail::cuda {

std::vector<PixelRecord> pixel_records(const PreparedSky& sky, double monopole) {
  const std::size_t npix = sky.pixels.size() / 8;
  std::vector<PixelRecord> out(npix);
  for (std::size_t i = 0; i < npix; ++i) {
    const double* px = &sky.pixels[i * 8];
    out[i] = {float(px[0]), float(px[1]), float(px[2]), float(px[4] - monopole),
              float(px[5]),  float(px[6]), float(px[7]), 0.0f};
  }
  return out;
}

std::vector<double> pixel_vectors(const PreparedSky& sky) {
  const std::size_t npix = sky.pixels.size() / 8;
  std::vector<double> out(npix * 4);
  for (std::size_t i = 0; i < npix; ++i)
    for (int c = 0; c < 3; ++c) out[i * 4 + c] = sky.pixels[i * 8 + c];
  return out;
}

std::vector<float> float_weights(const PreparedDetector& det) {
  return std::vector<float>(det.weights.begin(), det.weights.end());
}

std::vector<double> exact_weights(const PreparedDetector& det) {
  const std::size_t nodes = det.weights.size() / 4;
  std::vector<double> out(nodes * 4, 0.0);
  for (std::size_t k = 0; k < nodes; ++k) {
    out[k * 4] = det.weights[k * 4];
    if (!det.norm_weights.empty()) out[k * 4 + 1] = det.norm_weights[k * 4];
  }
  return out;
}

KernelDetector kernel_detector(const PreparedDetector& det, const float* weights, const double* exact) {
  KernelDetector k{};
  k.weights = weights;
  k.exact_weights = exact;
  k.grid_n = det.grid_n;
  k.grid_a = float(det.grid_a);
  k.grid_inv_step = float(det.grid_inv_step);
  k.grid_a_d = det.grid_a;
  k.grid_inv_step_d = det.grid_inv_step;
  k.rho_max = det.rho_max;
  k.cos_rho_max = det.cos_rho_max;
  k.cos_zeta = det.cos_zeta;
  k.sin_zeta = det.sin_zeta;
  return k;
}

}  // namespace pisco::detail::cuda
