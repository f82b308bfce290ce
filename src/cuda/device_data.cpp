#include "cuda/device_data.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <thread>

#include "pisco/error.hpp"

namespace pisco::detail::cuda {

namespace {

// Calls f(i, n, xyz) for pixels first_pixel + [i, i + n) of [0, count), a piece at a time, with xyz their
// unit vectors (3 doubles a pixel) made on all hardware threads.
template <class F>
void for_each_vector_piece(int nside, std::size_t first_pixel, std::size_t count, F&& f) {
  const PixelVectors vectors(nside);
  constexpr std::size_t piece = std::size_t(1) << 16;
  std::vector<double> xyz(3 * piece);
  for (std::size_t first = 0; first < count; first += piece) {
    const std::size_t n = std::min(piece, count - first);
    vectors.get(first_pixel + first, n, xyz.data(), std::max(1u, std::thread::hardware_concurrency()));
    f(first, n, xyz.data());
  }
}

}  // namespace

std::vector<PixelRecord> pixel_records(int nside, std::size_t first_pixel,
                                       const std::array<std::span<const double>, 4>& maps, double monopole,
                                       const CapBoundary& boundary) {
  const std::size_t count = maps[0].size();
  std::vector<PixelRecord> out(count);
  for_each_vector_piece(nside, first_pixel, count, [&](std::size_t first, std::size_t n, const double* xyz) {
    for (std::size_t j = 0; j < n; ++j) {
      const std::size_t i = first + j;
      out[i] = {float(xyz[3 * j]),   float(xyz[3 * j + 1]), float(xyz[3 * j + 2]),
                float(maps[0][i] - monopole * boundary.at(first_pixel + i)),
                float(maps[1][i]),   float(maps[2][i]),     float(maps[3][i]), 0.0f};
    }
  });
  return out;
}

std::vector<PixelRecord> pixel_records(const SkyView& sky, double monopole, const CapBoundary& boundary) {
  return pixel_records(sky.nside(), 0, {sky.I(), sky.Q(), sky.U(), sky.V()}, monopole, boundary);
}

std::vector<double> pixel_vectors(int nside, std::size_t first_pixel, std::size_t count) {
  std::vector<double> out(count * 4, 0.0);
  for_each_vector_piece(nside, first_pixel, count, [&](std::size_t first, std::size_t n, const double* xyz) {
    for (std::size_t j = 0; j < n; ++j)
      for (int c = 0; c < 3; ++c) out[(first + j) * 4 + c] = xyz[3 * j + c];
  });
  return out;
}

std::vector<double> pixel_vectors(const SkyView& sky) { return pixel_vectors(sky.nside(), 0, sky.npix()); }

int kernel_columns(const PreparedDetector& det) {
  return det.plate == PreparedDetector::Plate::aperture ? 4 : weight_columns(det);
}

std::vector<float> float_weights(const PreparedDetector& det, int columns) {
  std::vector<float> w = float32_weights(det);
  if (columns == 4) return w;
  const std::size_t nodes = w.size() / 4;
  std::vector<float> pairs(w.size(), 0.0f);
  for (std::size_t k = 0; k < nodes; ++k) {
    pairs[4 * k] = w[4 * k];
    pairs[4 * k + 1] = w[4 * k + 1];
    if (k + 1 < nodes) {
      pairs[4 * k + 2] = w[4 * k + 4];
      pairs[4 * k + 3] = w[4 * k + 5];
    }
  }
  return pairs;
}

std::vector<double> float64_weights(const PreparedDetector& det) {
  const std::size_t nodes = det.weights.size() / 4;
  std::vector<double> out(nodes * 4, 0.0);
  for (std::size_t k = 0; k < nodes; ++k) {
    out[k * 4] = det.weights[k * 4];
    if (!det.norm_weights.empty()) out[k * 4 + 1] = det.norm_weights[k * 4];
  }
  return out;
}

std::vector<double> plate_weights(const PreparedDetector& det) {
  const std::size_t nodes = det.weights.size() / 4;
  std::vector<double> out(nodes * 4, 0.0);
  for (std::size_t k = 0; k < nodes; ++k)
    for (int c = 0; c < 3; ++c) out[k * 4 + c] = det.weights[k * 4 + 1 + c];
  return out;
}

KernelDetector kernel_detector(const PreparedDetector& det, const float* weights, int columns,
                               const double* weights64, const double* plate) {
  if (columns != 4 && (columns != 2 || kernel_columns(det) != 2))
    throw Error("cuda backend: " + std::to_string(columns) + " weight columns for a detector that needs " +
                std::to_string(kernel_columns(det)));
  // The kernel reads each node's weights with 16-byte loads (contribution-inl.hpp, weight_pair).
  for (const void* table : {static_cast<const void*>(weights), static_cast<const void*>(weights64),
                            static_cast<const void*>(plate)})
    if (reinterpret_cast<std::uintptr_t>(table) % 16 != 0)
      throw Error("cuda backend: a detector's weight table is not 16-byte aligned");
  KernelDetector k{};
  k.weights = weights;
  k.columns = columns;
  k.weights64 = weights64;
  k.plate_weights = plate;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) k.plate_mueller[4 * i + j] = det.plate_mueller[i][j];
  k.grid_n = det.grid_n;
  k.grid_a = float(det.grid_a);
  k.grid_inv_step = float(det.grid_inv_step);
  k.grid_a_d = det.grid_a;
  k.grid_inv_step_d = det.grid_inv_step;
  k.rho_max = det.rho_max;
  k.cos_rho_max = det.cos_rho_max;
  k.cos_zeta = det.cos_zeta;
  k.sin_zeta = det.sin_zeta;
  k.offset = det.offset;
  return k;
}

}  // namespace pisco::detail::cuda
