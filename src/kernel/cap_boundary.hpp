// The rings about the edges of HEALPix's polar caps and their quadrature weights (docs/physics.md, "The
// quadrature"; core/poles.hpp), in one struct for the host and the CUDA kernel; the ring test is
// src/kernel/pixel.glsl's cap_boundary_ring, which the shaders run too.
#pragma once

#include <cstdint>

#include "kernel/contribution.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail {

// Euler-Maclaurin's jump term at a cap's edge, -1/12 of the jump in the rule's slope, as weights
// 1 - c_j / (ring spacing in NSIDE units) on the edge ring (j = 0) and its neighbours (j = 1): for a
// field that varies across rings with frequency w (radians per ring) the rule misses the jump times
// h(w) = 1 / (4 sin^2(w / 2)) - 1 / w^2 (1/12 at w = 0), and c_0 + 2 c_1 cos w is h's least-squares
// fit up to w = 0.9 pi with c_0 + 2 c_1 = 1/12 (a uniform sky's term exact). docs/physics.md, "The
// quadrature".
inline constexpr double cap_edge_c1 = -0.008437066150776872;
inline constexpr double cap_edge_c0 = 1.0 / 12.0 - 2.0 * cap_edge_c1;

// The weights of the six rings about the caps' edges of an NSIDE, by cap_boundary_ring's answer:
// 1 - c_0 / NSIDE on rings NSIDE and 3 NSIDE (CAP_EDGE_RING), 1 - c_1 / NSIDE on NSIDE + 1 and
// 3 NSIDE - 1 (CAP_BELT_RING, the belt's), 1 - c_1 / (NSIDE - 1) on NSIDE - 1 and 3 NSIDE + 1
// (CAP_LAST_RING, the caps' last, whose spacing in z is (NSIDE - 1) / NSIDE of the belt's); 1 for
// every other pixel, and for all with the plain quadrature (nside 0). Computed where asked, from
// nside alone, so that the CUDA kernels hold one register for them. The float32 backends, which take
// the monopole I0 out of the sky (prepared.hpp), take weight x I0 out of those pixels and add I0
// sum_k weight(k) w_I(k) back in float64, so that the monopole is weighted too without putting
// -I0 c / NSIDE into float32 (whose weights' own rounding would turn it into 1e-4 of micro-kelvin
// anisotropies).
struct CapBoundary {
  std::uint32_t nside = 0;
  // 1 for ring 0, and for every ring with the plain quadrature or where it has no pixels (the caps'
  // last at NSIDE 1).
  PISCO_HD double weight(uint ring) const {
    const uint spacing = ring == CAP_LAST_RING ? nside - 1u : nside;
    if (ring == 0u || nside == 0u || spacing == 0u) return 1.0;
    return 1.0 - (ring == CAP_EDGE_RING ? cap_edge_c0 : cap_edge_c1) / double(spacing);
  }
  PISCO_HD double at(std::uint64_t pixel) const {
    return nside == 0 ? 1.0 : weight(cap_boundary_ring(static_cast<uint>(pixel), nside));
  }
};

}  // namespace pisco::detail
