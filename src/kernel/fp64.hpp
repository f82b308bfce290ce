// The float64 functions the shaders compute themselves (src/kernel/fp64.glsl: pisco_cos, pisco_sin,
// pisco_atan2_nonneg_y), under the same names for the C++ side of the texts that call them
// (frame.glsl, rings.glsl): the C library's, on the host and on CUDA devices.
#pragma once

#include <cmath>

#include "kernel/hd.hpp"

namespace pisco::detail {

PISCO_HD double pisco_cos(double x) { return cos(x); }
PISCO_HD double pisco_sin(double x) { return sin(x); }
// atan2(y, x) for y >= 0: fabs takes -0.0 to the angle of +0.0, as fp64.glsl's does.
PISCO_HD double pisco_atan2_nonneg_y(double y, double x) { return atan2(fabs(y), x); }

}  // namespace pisco::detail
