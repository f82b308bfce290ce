// A half-wave plate's Mueller matrix at an angle (docs/physics.md, "Half-wave plates"): plate.glsl's
// plate_rows, the one text every backend runs, on row-major 4x4 arrays for the library
// (pisco::rotated_mueller), the float64 reference and the simd and CUDA kernels.
#pragma once

#include <cmath>

#include "kernel/contribution.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail {

// out = R(-theta) m0 R(theta), both row-major 4x4, with c = cos 2 theta, s = sin 2 theta.
PISCO_HD void plate_at(const double* m0, double c, double s, double* out) {
  const auto row = [&](int r) { return Vec4<double>{m0[4 * r], m0[4 * r + 1], m0[4 * r + 2], m0[4 * r + 3]}; };
  Vec4<double> m[4];
  plate_rows(row(0), row(1), row(2), row(3), c, s, m[0], m[1], m[2], m[3]);
  for (int r = 0; r < 4; ++r) {
    out[4 * r] = m[r].x;
    out[4 * r + 1] = m[r].y;
    out[4 * r + 2] = m[r].z;
    out[4 * r + 3] = m[r].w;
  }
}

// effective_weights (v = w M, a pixel's weights behind the plate, from M by columns) is in src/kernel/pixel.glsl,
// with the other per-pixel formulas; these are a row-major M's columns as it takes them.
PISCO_HD void plate_columns(const double* m, Vec4<double> (&columns)[4]) {
  for (int c = 0; c < 4; ++c) columns[c] = {m[c], m[4 + c], m[8 + c], m[12 + c]};
}

}  // namespace pisco::detail
