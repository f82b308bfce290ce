// The per-pixel contribution of the measurement equation in float32 is pixel.glsl, the one text every
// backend runs (see the derivation in src/kernel/contribution.hpp and docs/physics.md). Here: the float64
// tables of the monopole path, read in float64 or, on devices without it, in float-float (PISCO_FF).
// Written in the common subset of GLSL and C++ (common.glsl): tests/test_kernel_host.cpp runs this
// file as C++ against the reference, and the backend parity tests hold the kernel to it. Reads the
// tables `weight_pairs` and `weights64` and the specialization constants RADIAL and COLUMNS.
#ifndef PISCO_CONTRIBUTION_GLSL
#define PISCO_CONTRIBUTION_GLSL

#include "common.glsl"
#if PISCO_FF
#include "ff.glsl"
#endif
#include "pixel.glsl"

// The float64 interpolation at (x, y): its nodes (absolute node indices) and coefficients, linear in
// r = sqrt(x^2 + y^2) for a radial profile (2 nodes), on the grid otherwise bilinear (4 nodes) less
// the curvature terms of the cell's edges (4 records after the grid's nodes,
// src/kernel/grid_curvature.hpp), as pixel.glsl's interpolate_weights; no node outside the grid or
// beyond the profile. One stencil for every float64 table a node has.
struct Stencil64 {
  uint k[8];
  PISCO_F64 c[8];
  int m;  // nodes used
};

#if !PISCO_FF

// A float64 table entry: one texel holds two float64 numbers, low word first.
PISCO_FN dvec2 texel_doubles(uvec4 t) { return dvec2(packDouble2x32(uvec2(t.x, t.y)), packDouble2x32(uvec2(t.z, t.w))); }

// (w_I, Omega_pix B_TT / Omega~) of node k.
PISCO_FN dvec2 weight64(uint k) { return texel_doubles(texelFetch(weights64, int(k))); }

PISCO_FN Stencil64 stencil64(Grid grid, double x, double y) {
  Stencil64 s;
  s.m = 0;
  const uint offset = grid.offset64, n = uint(grid.n);
  if (RADIAL) {
    const double u = sqrt(max(x * x + y * y, 0.0lf)) * grid.inv_step64;
    if (!(u <= double(n - 1u))) return s;
    const uint i = min(uint(u), n - 2u);
    const double f = u - double(i);
    s.k[0] = offset + i;
    s.k[1] = offset + i + 1u;
    s.c[0] = 1.0lf - f;
    s.c[1] = f;
    s.m = 2;
    return s;
  }
  const double u = (x + grid.a64) * grid.inv_step64;
  const double v = (y + grid.a64) * grid.inv_step64;
  const double last = double(n - 1u);
  if (!(u >= 0.0lf && v >= 0.0lf && u <= last && v <= last)) return s;
  const uint i = min(uint(u), n - 2u);
  const uint j = min(uint(v), n - 2u);
  const double fu = u - double(i);
  const double fv = v - double(j);
  const uint g00 = offset + j * n + i;
  s.k[0] = g00;
  s.k[1] = g00 + 1u;
  s.k[2] = g00 + n;
  s.k[3] = g00 + n + 1u;
  s.c[0] = (1.0lf - fu) * (1.0lf - fv);
  s.c[1] = fu * (1.0lf - fv);
  s.c[2] = (1.0lf - fu) * fv;
  s.c[3] = fu * fv;
  s.k[4] = offset + n * n + i * n + j;  // ex(i, j), ex(i, j + 1)
  s.k[5] = s.k[4] + 1u;
  s.k[6] = offset + 2u * n * n + j * n + i;  // ey(i, j), ey(i + 1, j)
  s.k[7] = s.k[6] + 1u;
  const double cu = fu * (1.0lf - fu), cv = fv * (1.0lf - fv);
  s.c[4] = -(cu * (1.0lf - fv));
  s.c[5] = -(cu * fv);
  s.c[6] = -(cv * (1.0lf - fu));
  s.c[7] = -(cv * fu);
  s.m = 8;
  return s;
}

// Half-wave plates at the aperture (docs/physics.md, "Half-wave plates"): the float64 weights of a
// plate detector are 3 texels a node, (w_I, wn), (w_Q, w_U), (w_V, 0); M0 is 8 texels, row by row.
PISCO_FN dvec4 plate_weight64(uint k) {
  const dvec2 a = texel_doubles(texelFetch(weights64, int(3u * k)));
  const dvec2 b = texel_doubles(texelFetch(weights64, int(3u * k + 1u)));
  const dvec2 c = texel_doubles(texelFetch(weights64, int(3u * k + 2u)));
  return dvec4(a.x, b.x, b.y, c.x);
}

PISCO_FN double plate_norm_at(uint k) { return texel_doubles(texelFetch(weights64, int(3u * k))).y; }

// Row r of the plate's M0.
PISCO_FN dvec4 plate_row(uint offset, int r) {
  const dvec2 a = texel_doubles(texelFetch(weights64, int(offset) + 2 * r));
  const dvec2 b = texel_doubles(texelFetch(weights64, int(offset) + 2 * r + 1));
  return dvec4(a.x, a.y, b.x, b.y);
}

#else  // PISCO_FF: every float64 number of the tables is a float-float pair, hi then lo

PISCO_FN vec2 texel_ff(uvec4 t, int half_) {
  return half_ == 0 ? vec2(uintBitsToFloat(t.x), uintBitsToFloat(t.y)) : vec2(uintBitsToFloat(t.z), uintBitsToFloat(t.w));
}

PISCO_FN Stencil64 stencil64(Grid grid, vec2 x, vec2 y) {
  Stencil64 s;
  s.m = 0;
  const uint offset = grid.offset64, n = uint(grid.n);
  const vec2 one = vec2(1.0f, 0.0f);
  if (RADIAL) {
    const vec2 u = ff_mul(ff_sqrt(ff_add(ff_mul(x, x), ff_mul(y, y))), grid.inv_step64);
    if (!ff_le(u, vec2(float(n - 1u), 0.0f))) return s;
    const uint i = min(uint(ff_floor(u)), n - 2u);
    const vec2 f = ff_sub(u, vec2(float(i), 0.0f));
    s.k[0] = offset + i;
    s.k[1] = offset + i + 1u;
    s.c[0] = ff_sub(one, f);
    s.c[1] = f;
    s.m = 2;
    return s;
  }
  const vec2 u = ff_mul(ff_add(x, grid.a64), grid.inv_step64);
  const vec2 v = ff_mul(ff_add(y, grid.a64), grid.inv_step64);
  const vec2 last = vec2(float(n - 1u), 0.0f);
  const vec2 zero = vec2(0.0f, 0.0f);
  if (!(ff_le(zero, u) && ff_le(zero, v) && ff_le(u, last) && ff_le(v, last))) return s;
  const uint i = min(uint(ff_floor(u)), n - 2u);
  const uint j = min(uint(ff_floor(v)), n - 2u);
  const vec2 fu = ff_sub(u, vec2(float(i), 0.0f));
  const vec2 fv = ff_sub(v, vec2(float(j), 0.0f));
  const uint g00 = offset + j * n + i;
  s.k[0] = g00;
  s.k[1] = g00 + 1u;
  s.k[2] = g00 + n;
  s.k[3] = g00 + n + 1u;
  s.c[0] = ff_mul(ff_sub(one, fu), ff_sub(one, fv));
  s.c[1] = ff_mul(fu, ff_sub(one, fv));
  s.c[2] = ff_mul(ff_sub(one, fu), fv);
  s.c[3] = ff_mul(fu, fv);
  s.k[4] = offset + n * n + i * n + j;  // ex(i, j), ex(i, j + 1)
  s.k[5] = s.k[4] + 1u;
  s.k[6] = offset + 2u * n * n + j * n + i;  // ey(i, j), ey(i + 1, j)
  s.k[7] = s.k[6] + 1u;
  const vec2 cu = ff_mul(fu, ff_sub(fu, one)), cv = ff_mul(fv, ff_sub(fv, one));  // -u (1 - u), -v (1 - v)
  s.c[4] = ff_mul(cu, ff_sub(one, fv));
  s.c[5] = ff_mul(cu, fv);
  s.c[6] = ff_mul(cv, ff_sub(one, fu));
  s.c[7] = ff_mul(cv, fu);
  s.m = 8;
  return s;
}

// (w_I, Omega_pix B_TT / Omega~) of node k.
PISCO_FN void weight64(uint k, PISCO_OUT(vec2) w, PISCO_OUT(vec2) wn) {
  const uvec4 t = texelFetch(weights64, int(k));
  w = texel_ff(t, 0);
  wn = texel_ff(t, 1);
}

// Plate detectors: 3 texels a node, (w_I, wn), (w_Q, w_U), (w_V, 0); M0 8 texels, row by row.
PISCO_FN void plate_weight64(uint k, PISCO_OUT(vec2) wi, PISCO_OUT(vec2) wq, PISCO_OUT(vec2) wu, PISCO_OUT(vec2) wv,
                             PISCO_OUT(vec2) wn) {
  const uvec4 a = texelFetch(weights64, int(3u * k)), b = texelFetch(weights64, int(3u * k + 1u)),
              c = texelFetch(weights64, int(3u * k + 2u));
  wi = texel_ff(a, 0);
  wn = texel_ff(a, 1);
  wq = texel_ff(b, 0);
  wu = texel_ff(b, 1);
  wv = texel_ff(c, 0);
}

// M0_{r c} of the plate whose M0 starts at texel `offset`.
PISCO_FN vec2 plate_entry(uint offset, int r, int c) {
  return texel_ff(texelFetch(weights64, int(offset) + 2 * r + c / 2), c % 2);
}

#endif

#endif
