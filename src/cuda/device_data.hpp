// The engine inputs in the layout the CUDA kernel reads (sample.hpp), built on the host: the sky in
// float32 with its monopole removed, double pixel vectors and double (w_I, wn) weights where the
// float64 sums need them. Plain C++: the unit tests use it without a GPU.
#pragma once

#include <array>
#include <span>
#include <vector>

#include "core/prepared.hpp"
#include "cuda/sample.hpp"

namespace pisco::detail::cuda {


// One record per pixel, I - monopole in float32.
// The sky's pixels with monopole x boundary.at(p) taken out of I (kernel/cap_boundary.hpp).
std::vector<PixelRecord> pixel_records(const SkyView& sky, double monopole, const CapBoundary& boundary = {});
// The same for pixels [first, first + count) of maps of count values each (a band, core/polar_copy.hpp).
std::vector<PixelRecord> pixel_records(int nside, std::size_t first, const std::array<std::span<const double>, 4>& maps,
                                       double monopole, const CapBoundary& boundary);

// 4 doubles per pixel (kx, ky, kz, 0), the unit vectors of the reference.
std::vector<double> pixel_vectors(const SkyView& sky);
std::vector<double> pixel_vectors(int nside, std::size_t first, std::size_t count);

// The float32 weights' columns the kernels read for `det`: 2 (IQPairGrid, one 16-byte load a node pair)
// where its w_U and w_V vanish (weight_columns) and no plate stands at the aperture (a plate mixes
// the columns: its kernels take all four); 4 otherwise.
int kernel_columns(const PreparedDetector& det);

// The detector's weights converted to float32 (float32_weights): with 4 columns, 4 per node as in the
// reference; with 2, entry k holds (w_I, w_Q) of node k and of node k + 1 (the last node's neighbour
// zero), 4 floats a node as well.
std::vector<float> float_weights(const PreparedDetector& det, int columns);

// (w_I, wn, 0, 0) per node in double: the I weight and the per-sample normalization weight (zero
// unless the inputs were prepared for per-sample normalization).
std::vector<double> float64_weights(const PreparedDetector& det);

// Aperture plates: (w_Q, w_U, w_V, 0) per node in double, for the monopole's float64 sum.
std::vector<double> plate_weights(const PreparedDetector& det);

// The kernel's view of a detector, given its uploaded weights (float_weights(det, columns)).
KernelDetector kernel_detector(const PreparedDetector& det, const float* weights, int columns,
                               const double* weights64, const double* plate = nullptr);

}  // namespace pisco::detail::cuda
