// The device backends' adjoint in 64-bit fixed point (docs/vulkan.md, "The adjoint"): every pixel's
// share of a sample, v g, is rounded to an integer multiple of 1/S and added with an integer atomic.
// Integer addition is associative, so the maps come out the same bits whatever order the device's
// threads arrive in, on devices with or without float64 atomics. S is a power of two chosen per batch
// of samples from a bound on every pixel's total, sum_s |v_s| times the largest |g| a detector can
// give, so that no total reaches 2^62; after the batch the host adds the integers, times 1/S, into
// float64 maps. A contribution is then exact to 2^-62 of that bound: far below float32's rounding of
// the weights themselves for batches of up to millions of samples.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/backend.hpp"
#include "core/prepared.hpp"

namespace pisco::detail {

// Samples folded into the float64 maps at a time: the bound, and with it the resolution, covers at
// most this many samples.
constexpr std::size_t fixed_point_batch = std::size_t(1) << 22;

// A bound on |g_c|, every Stokes component c of stokes_adjoint(w M(theta), chi), over every pixel and
// sample of the detector, twice over: the weights are interpolated linearly between nodes (a convex
// combination, in float32 that may round up by an ulp), the rotation by chi mixes w_Q and w_U, and a
// plate's M(theta) = R(-theta) M0 R(theta) has entries at most 4 max |M0|, so that each component of
// w M is at most 4 max |M0| sum_c |w_c|, and each of g at most the sum of those.
inline double adjoint_weight_bound(const PreparedDetector& det) {
  std::array<double, 4> peak{};
  for (std::size_t k = 0; k < det.weights.size(); ++k) peak[k % 4] = std::max(peak[k % 4], std::abs(det.weights[k]));
  double bound = peak[0] + peak[1] + peak[2] + peak[3];
  if (det.plate == PreparedDetector::Plate::aperture) {
    double m = 0.0;
    for (const auto& row : det.plate_mueller)
      for (double x : row) m = std::max(m, std::abs(x));
    bound *= 16.0 * m;
  }
  return 2.0 * bound;
}

// The scale S = 2^k for values v (already squared for the diagonal) and a bound g on |g| (squared
// likewise): the largest power of two with S sum |v| g <= 2^62. Zero when there is nothing to scatter.
inline double fixed_point_scale(std::span<const double> values, double g) {
  double total = 0.0;
  for (double v : values) total += std::abs(v);
  total *= g;
  if (!(total > 0.0)) return 0.0;
  int e = 0;
  std::frexp(total, &e);  // total < 2^e
  return std::ldexp(1.0, 62 - e);
}

// Adds the device's sums (4 integers a pixel, I Q U V) times 1/scale into the float64 maps.
inline void fold_fixed_point(const std::int64_t* sums, std::size_t npix, double scale,
                             std::array<std::vector<double>, 4>& maps) {
  const double inv = 1.0 / scale;  // exact: scale is a power of two
  for (std::size_t p = 0; p < npix; ++p)
    for (int c = 0; c < 4; ++c)
      if (const std::int64_t q = sums[4 * p + std::size_t(c)]) maps[c][p] += double(q) * inv;
}

// A device backend's Backend::adjoint, batch by batch: each batch's values (the TOD, divided by each
// sample's normalization where per_sample, from norms(part, out), as the forward computes it; squared
// for the diagonal), its scale, then scatter(part, scaled values), which returns the pixels, and
// fold(scale). `bound` is adjoint_weight_bound's.
template <class Norms, class Scatter, class Fold>
std::uint64_t fixed_point_adjoint(const PointingInput& pointing, std::span<const double> tod, double bound,
                                  bool squares, bool per_sample, Norms&& norms, Scatter&& scatter, Fold&& fold) {
  if (squares) bound *= bound;
  std::uint64_t pixels = 0;
  std::vector<double> values, n;
  for (std::size_t b0 = 0; b0 < pointing.size(); b0 += fixed_point_batch) {
    const std::size_t m = std::min(fixed_point_batch, pointing.size() - b0);
    const PointingInput part = pointing.subspan(b0, m);
    values.assign(tod.begin() + std::ptrdiff_t(b0), tod.begin() + std::ptrdiff_t(b0 + m));
    if (per_sample) {
      n.assign(m, 0.0);
      norms(part, std::span<double>(n));
      for (std::size_t i = 0; i < m; ++i) values[i] = n[i] > 0.0 ? values[i] / n[i] : 0.0;
    }
    if (squares)
      for (double& v : values) v *= v;
    const double scale = fixed_point_scale(values, bound);
    if (scale == 0.0) continue;
    for (double& v : values) v *= scale;
    pixels += scatter(part, std::span<double>(values));
    fold(scale);
  }
  return pixels;
}

}  // namespace pisco::detail
