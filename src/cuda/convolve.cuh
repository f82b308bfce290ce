// The convolution kernel's launcher: one warp per sample (sample.hpp), 8 samples a block.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>
#include <string>

#include "cuda/sample.hpp"

namespace pisco::detail::cuda {

struct ChunkArgs {
  const double* pointing;  // 4 doubles a sample: (theta, phi, psi, 0) or a quaternion (x, y, z, w)
  bool quaternions;
  const double* plate_angle;  // aperture plates: the plate's angle from the detector's axis per sample
  double* tod;
  unsigned long long* pixels;  // incremented by the disc size of every sample
  std::uint32_t count;
};

// The adjoint's scatter of one chunk (docs/cuda.md, "The adjoint"): values[i], already scaled
// (gpu/fixed_point.hpp), times each pixel's adjoint weights into `sums` (4 int64 a pixel, I Q U V).
struct AdjointArgs {
  const double* pointing;
  bool quaternions;
  const double* plate_angle;
  const double* values;
  std::int64_t* sums;
  unsigned long long* pixels;
  std::uint32_t count;
};

// Enqueues the kernel on `stream`. The variant is chosen from the beam's layout (radial profile or
// 2D grid), whether the sky's monopole is summed apart, and the normalization.
// Throws pisco::Error when the current device cannot run the kernel (an architecture the library was
// not built for: CMAKE_CUDA_ARCHITECTURES).
void check_kernel_image(const std::string& device);

void launch_convolve(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool radial,
                     bool monopole, bool per_sample, bool plate, cudaStream_t stream);
// The adjoint's first pass with the per-sample normalization: each sample's norm into chunk.tod.
void launch_norms(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool radial, bool plate,
                  cudaStream_t stream);
// The adjoint's scatter; `float64` as the forward's float64 sums (beam coordinates from float64 vectors).
void launch_scatter(const KernelSky& sky, const KernelDetector& det, const AdjointArgs& chunk, bool radial, bool float64,
                    bool plate, bool squares, cudaStream_t stream);

}  // namespace pisco::detail::cuda
