// The per-pixel contribution of the measurement equation in float32 is pixel.glsl, the one text every
// backend runs (see the derivation in src/kernel/contribution.hpp and docs/physics.md). Here: the float64
// tables of the monopole path, read in float64 or, on devices without it, in float-float (PISCO_FF).
// Written in the common subset of GLSL and C++ (common.glsl): tests/test_kernel_host.cpp runs this
// file as C++ against the reference, and the backend parity tests hold the kernel to it. Reads the
// tables `weight_pairs` and `weights64` and the specialization constants RADIAL, COLUMNS and PLATE.
#ifndef PISCO_CONTRIBUTION_GLSL
#define PISCO_CONTRIBUTION_GLSL

#include "common.glsl"
#if PISCO_FF
#include "ff.glsl"
#endif
#include "pixel.glsl"

#if !PISCO_FF

// A float64 table entry: one texel holds two float64 numbers, low word first.
PISCO_FN dvec2 texel_doubles(uvec4 t) { return dvec2(packDouble2x32(uvec2(t.x, t.y)), packDouble2x32(uvec2(t.z, t.w))); }

// The float64 weights of a detector (docs/vulkan.md, "Precision"), as the float64 interpolation reads
// them: from node `offset` on, one texel a node, (w_I, Omega_pix B_TT / Omega~); behind a half-wave
// plate at the aperture (docs/physics.md, "Half-wave plates") three texels a node, (w_I, wn),
// (w_Q, w_U), (w_V, 0), of which `part` 0 reads the first and part 1 the other two.
struct Grid64 {
  uint offset;
  int n;
  double a, inv_step;  // nodes at x_i = -a + i * step (radial: r_i = i * step)
  int part;
};

// Node k's float64 weights: (w_I, wn, 0, 0), or a plate detector's part 1, (w_Q, w_U, w_V, 0).
PISCO_FN dvec4 node64(Grid64 g, int k) {
  const uint node = g.offset + uint(k);
  if (!PLATE) {
    const dvec2 t = texel_doubles(texelFetch(weights64, int(node)));
    return dvec4(t.x, t.y, 0.0lf, 0.0lf);
  }
  if (g.part == 0) {
    const dvec2 t = texel_doubles(texelFetch(weights64, int(3u * node)));
    return dvec4(t.x, t.y, 0.0lf, 0.0lf);
  }
  const dvec2 b = texel_doubles(texelFetch(weights64, int(3u * node + 1u)));
  const dvec2 c = texel_doubles(texelFetch(weights64, int(3u * node + 2u)));
  return dvec4(b.x, b.y, c.x, 0.0lf);
}

// interpolate.glsl's hooks for the float64 tables: the node and the next, the edges' curvature terms
// after the nodes (src/kernel/grid_curvature.hpp), the node index and the weights where inside.
PISCO_FN void weight_pair(Grid64 g, int k, PISCO_OUT(dvec4) w, PISCO_OUT(dvec4) next) {
  w = node64(g, k);
  next = node64(g, k + 1);
}
PISCO_FN void edge_x_pair(Grid64 g, int k, int i, int j, PISCO_OUT(dvec4) ex0, PISCO_OUT(dvec4) ex1) {
  weight_pair(g, i * g.n + j + g.n * g.n, ex0, ex1);
}
PISCO_FN void edge_y_pair(Grid64 g, int k, PISCO_OUT(dvec4) ey0, PISCO_OUT(dvec4) ey1) {
  weight_pair(g, k + 2 * g.n * g.n, ey0, ey1);
}
PISCO_FN int node_index(double u, bool inside, int top) { return clamp(int(u), 0, top); }
PISCO_FN dvec4 select_weights(bool inside, dvec4 w) { return inside ? w : dvec4(0.0lf); }

// The float64 beam coordinates and interpolation (beam_coordinates; interpolate_weights and
// interpolate_radial over a Grid64): interpolate.glsl again, in float64, the reference's own arithmetic.
#undef PISCO_REAL
#undef PISCO_V3
#undef PISCO_V4
#undef PISCO_GRID
#define PISCO_REAL double
#define PISCO_V3 dvec3
#define PISCO_V4 dvec4
#define PISCO_GRID Grid64
#include "interpolate.glsl"
#undef PISCO_REAL
#undef PISCO_V3
#undef PISCO_V4
#undef PISCO_GRID
#define PISCO_REAL float
#define PISCO_V3 vec3
#define PISCO_V4 vec4
#define PISCO_GRID Grid

// Row r of the plate's M0.
PISCO_FN dvec4 plate_row(uint offset, int r) {
  const dvec2 a = texel_doubles(texelFetch(weights64, int(offset) + 2 * r));
  const dvec2 b = texel_doubles(texelFetch(weights64, int(offset) + 2 * r + 1));
  return dvec4(a.x, a.y, b.x, b.y);
}

#else  // PISCO_FF: every float64 number of the tables is a float-float pair, hi then lo

// The float-float interpolation at (x, y): its nodes (absolute node indices) and coefficients, linear in
// r = sqrt(x^2 + y^2) for a radial profile (2 nodes), on the grid otherwise bilinear (4 nodes) less
// the curvature terms of the cell's edges (4 records after the grid's nodes,
// src/kernel/grid_curvature.hpp), as interpolate.glsl's interpolate_weights; no node outside the grid or
// beyond the profile. One stencil for every float-float table a node has.
struct Stencil64 {
  uint k[8];
  vec2 c[8];
  int m;  // nodes used
};

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
