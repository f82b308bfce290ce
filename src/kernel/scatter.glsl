// The adjoint's scatter of one pixel (docs/vulkan.md, "The adjoint"): the sample's value v times the
// pixel's adjoint weights g = stokes_adjoint(w, chi) (pixel.glsl), added to the pixel's I, Q, U, V
// as 64-bit fixed-point integers with atomicAdd. Integer addition is associative, so the sums do not
// depend on the order in which invocations arrive: the maps are the same bits on every run. The host
// scales v by a power of two S chosen so that no pixel's total can reach 2^62 in magnitude
// (src/gpu/fixed_point.hpp); a contribution is round(S v g) (fixed_point.glsl). Included by kernel.glsl in the adjoint
// build (adjoint.comp); reads the specialization constant SQUARES and writes the buffer `maps`
// (4 integers a pixel, I Q U V).
#ifndef PISCO_SCATTER_GLSL
#define PISCO_SCATTER_GLSL

#if PISCO_FF
// round(v g) as a 64-bit integer for v = hi + lo in float-float (v already carries the scale): hi g =
// p + e exactly (ff_two_prod), so v g = p + (e + lo g) to float-float precision; p's integer part
// converts exactly, and its fraction joins the rest before rounding. With a float64 v, fixed_point.glsl's.
int64_t fixed_point(vec2 v, float g) {
  const vec2 pe = ff_two_prod(v.x, g);
  const float whole = trunc(pe.x);
  PISCO_PRECISE const float rest = (pe.x - whole) + (pe.y + v.y * g);
  return int64_t(whole) + int64_t(roundEven(rest));
}
#endif
#include "fixed_point.glsl"

// Pixel p's share of a sample (fixed_share: v g, or v g^2 for the diagonal of A^T A with SQUARES),
// added to its maps.
void scatter_pixel(uint p, vec4 g, PISCO_F64 v) {
  for (int c = 0; c < 4; ++c) {
    const int64_t q = fixed_share(v, g[c], SQUARES);
    if (q != 0l) atomicAdd(maps[4u * p + uint(c)], q);
  }
}

#endif
