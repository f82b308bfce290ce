// The float64 reference's adjoint (docs/physics.md, "The adjoint") spreads its scatter over threads by
// sky pixels, not by samples: each thread owns slices of whole rings and adds every sample's
// contributions to its own pixels only. No two threads write one pixel, and each pixel sums its
// samples in their order, whatever the number of threads: the result is deterministic. ring_of also
// lays out the simd adjoint's windows.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/prepared.hpp"

namespace pisco::detail {

// Pixels [lo, hi) of consecutive whole rings, and the colatitudes of its first and last rings widened
// by 1e-9 rad (acos's rounding): a disc of radius rho around colatitude theta can reach the slice only
// if theta + rho >= theta_lo and theta - rho <= theta_hi.
struct RingSlice {
  std::uint32_t lo = 0, hi = 0;
  double theta_lo = 0.0, theta_hi = 0.0;
  bool missed_by(double theta, double rho) const { return theta + rho < theta_lo || theta - rho > theta_hi; }
};

// About `count` slices of equal pixel counts.
inline std::vector<RingSlice> ring_slices(const PreparedSky& sky, std::size_t count) {
  const std::size_t per = std::max<std::size_t>(1, sky.npix / std::max<std::size_t>(1, count));
  std::vector<RingSlice> slices;
  RingSlice s;
  bool open = false;
  for (std::uint32_t k = 0; k < sky.rings.size(); ++k) {
    const RingEntry& r = sky.rings[k];
    const double theta = std::acos(std::clamp(r.z, -1.0, 1.0));
    if (!open) {
      s = {r.first, r.first, theta, theta};
      open = true;
    }
    s.hi = r.first + r.count;
    s.theta_hi = theta;
    if (s.hi - s.lo >= per) {
      slices.push_back(s);
      open = false;
    }
  }
  if (open) slices.push_back(s);
  for (RingSlice& x : slices) {
    x.theta_lo -= 1e-9;
    x.theta_hi += 1e-9;
  }
  return slices;
}

// The ring of pixel p: the last ring whose first pixel is at most p.
inline std::uint32_t ring_of(const PreparedSky& sky, std::uint32_t p) {
  const auto it = std::upper_bound(sky.rings.begin(), sky.rings.end(), p,
                                   [](std::uint32_t x, const RingEntry& r) { return x < r.first; });
  return std::uint32_t(it - sky.rings.begin()) - 1;
}

}  // namespace pisco::detail
