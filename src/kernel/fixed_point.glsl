// The adjoint's contribution of one pixel in 64-bit fixed point (docs/vulkan.md and docs/cuda.md,
// "The adjoint"; the scale in src/gpu/fixed_point.hpp), written once, in the common subset of GLSL and
// C++ (common.glsl): scatter.glsl includes it as GLSL, src/kernel/contribution-inl.hpp as C++ for the
// CUDA kernel (src/cuda/sample.hpp) on the device and in its host emulation. The float-float kernel
// (PISCO_FF) brings its own fixed_point for a float-float v (scatter.glsl).
#if defined(PISCO_TEMPLATE_TEXT) || !defined(PISCO_FIXED_POINT_GLSL)
#ifndef PISCO_TEMPLATE_TEXT
#define PISCO_FIXED_POINT_GLSL
#include "common.glsl"
#endif

#if defined(PISCO_TEMPLATE_TEXT) || !PISCO_FF
// round(v g) as a 64-bit integer, to nearest even; v already carries the scale.
PISCO_FN int64_t fixed_point(double v, float g) { return int64_t(roundEven(v * double(g))); }
#endif

// A pixel's share of a sample in one Stokes component, g = stokes_adjoint(w, chi)'s component
// (pixel.glsl): round(v g), or round(v g^2) for the diagonal of A^T A (squares, where the host gives
// v = S d^2); zero where that weight is zero.
PISCO_FN int64_t fixed_share(PISCO_F64 v, float g, bool squares) {
  const float gc = squares ? g * g : g;
  return gc == 0.0f ? int64_t(0) : fixed_point(v, gc);
}

#endif
