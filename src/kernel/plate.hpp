// A half-wave plate's Mueller matrix at an angle (docs/physics.md, "Half-wave plates"), written once
// for the library (pisco::rotated_mueller), the float64 reference and the CUDA kernel;
// src/kernel/kernel.glsl's plate_matrix computes the same product in float32 (and its column 0 in float64)
// from the plate's rows.
#pragma once

#include <cmath>

#include "kernel/contribution.hpp"
#include "kernel/hd.hpp"

namespace pisco::detail {

// out = R(-theta) m0 R(theta), all row-major 4x4, with c = cos 2 theta, s = sin 2 theta and R(theta)
// rows (1,0,0,0), (0,c,s,0), (0,-s,c,0), (0,0,0,1).
PISCO_HD void plate_at(const double* m0, double c, double s, double* out) {
  double mr[16];  // m0 R(theta): columns 1 and 2 mix
  for (int i = 0; i < 4; ++i) {
    const double* row = m0 + 4 * i;
    mr[4 * i] = row[0];
    mr[4 * i + 1] = c * row[1] - s * row[2];
    mr[4 * i + 2] = s * row[1] + c * row[2];
    mr[4 * i + 3] = row[3];
  }
  for (int j = 0; j < 4; ++j) {  // R(-theta) (m0 R): rows 1 and 2 mix
    out[j] = mr[j];
    out[4 + j] = c * mr[4 + j] - s * mr[8 + j];
    out[8 + j] = s * mr[4 + j] + c * mr[8 + j];
    out[12 + j] = mr[12 + j];
  }
}

// effective_weights (v = w M, a pixel's weights behind the plate, from M by columns) is in src/kernel/pixel.glsl,
// with the other per-pixel formulas; these are a row-major M's columns as it takes them.
PISCO_HD void plate_columns(const double* m, Vec4<double> (&columns)[4]) {
  for (int c = 0; c < 4; ++c) columns[c] = {m[c], m[4 + c], m[8 + c], m[12 + c]};
}

}  // namespace pisco::detail
