// The adjoint's scatter of one pixel (docs/vulkan.md, "The adjoint"): the sample's value v times the
// pixel's adjoint weights g = stokes_adjoint(w, chi) (pixel.glsl), added to the pixel's I, Q, U, V
// as 64-bit fixed-point integers with atomicAdd. Integer addition is associative, so the sums do not
// depend on the order in which invocations arrive: the maps are the same bits on every run. The host
// scales v by a power of two S chosen so that no pixel's total can reach 2^62 in magnitude
// (src/gpu/fixed_point.hpp); a contribution is round(S v g). Included by kernel.glsl in the adjoint
// build (adjoint.comp); reads the specialization constant SQUARES and writes the buffer `maps`
// (4 integers a pixel, I Q U V).
#ifndef PISCO_SCATTER_GLSL
#define PISCO_SCATTER_GLSL

// round(v g) as a 64-bit integer; v already carries the scale.
#if PISCO_FF
// v = hi + lo in float-float: hi g = p + e exactly (ff_two_prod), so v g = p + (e + lo g) to float-float
// precision; p's integer part converts exactly, and its fraction joins the rest before rounding.
int64_t fixed_point(vec2 v, float g) {
  const vec2 pe = ff_two_prod(v.x, g);
  const float whole = trunc(pe.x);
  PISCO_PRECISE const float rest = (pe.x - whole) + (pe.y + v.y * g);
  return int64_t(whole) + int64_t(roundEven(rest));
}
#else
int64_t fixed_point(double v, float g) { return int64_t(roundEven(v * double(g))); }
#endif

// Pixel p's share of a sample: v g, or v g^2 for the diagonal of A^T A (SQUARES; the host then gives
// v = S d^2).
void scatter_pixel(uint p, vec4 g, PISCO_F64 v) {
  for (int c = 0; c < 4; ++c) {
    const float gc = SQUARES ? g[c] * g[c] : g[c];
    if (gc == 0.0f) continue;
    const int64_t q = fixed_point(v, gc);
    if (q != 0l) atomicAdd(maps[4u * p + uint(c)], q);
  }
}

#endif
