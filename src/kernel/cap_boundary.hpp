// The rings where HEALPix's polar caps meet its equatorial belt and their quadrature weight
// (docs/physics.md, "The quadrature"; core/poles.hpp), in one struct for the host and the CUDA kernel;
// the ring test is src/kernel/pixel.glsl's on_cap_boundary, which the shaders run too.
#pragma once

#include <cstdint>

#include "kernel/contribution.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail {

// The rings NSIDE and 3 NSIDE as pixel ranges [north, north + count), [south, south + count), and
// their weight: 1 - 1/(12 NSIDE) with the corrected quadrature, 1 with the plain one. The float32
// backends, which take the monopole I0 out of the sky (prepared.hpp), take weight x I0 out of those
// pixels and add I0 sum_k weight(k) w_I(k) back in float64, so that the monopole is weighted too
// without putting -I0 / (12 NSIDE) into float32 (whose weights' own rounding would turn it into 1e-4
// of micro-kelvin anisotropies).
struct CapBoundary {
  std::uint32_t north = 0, south = 0, count = 0;
  double weight = 1.0;
  PISCO_HD double at(std::uint64_t pixel) const {
    return on_cap_boundary(static_cast<uint>(pixel), north, south, count) ? weight : 1.0;
  }
};

}  // namespace pisco::detail
