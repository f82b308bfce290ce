// The interpolation of a beam's weights at a pixel's beam coordinates (docs/physics.md, "Interpolation
// on the grid"), written once, in the common subset of GLSL and C++, for every backend and both
// precisions. No include guard: it is included once for each number type, with the macros of
// pixel.glsl (PISCO_TEMPLATE_GRID, PISCO_REAL, PISCO_V4, PISCO_INDEX, PISCO_MASK, PISCO_IN, PISCO_GRID)
// set by its includer:
// - pixel.glsl includes it for the float32 weights: as GLSL (float), and in C++ as templates of the
//   number type T and grid type G (double for the reference's and the CUDA kernel's float64 sums, float
//   for the CUDA kernels, vectors of float32 lanes for the simd backend);
// - contribution.glsl includes it again as GLSL in float64, over the float64 tables (the shaders'
//   float64 path, the reference's own arithmetic).
// The includer supplies the grid's hooks for its layout: weight_pair, edge_x_pair, edge_y_pair,
// node_index and select_weights (pixel.glsl says what each does).

// A pixel's beam coordinates on the float64 path, from its unit vector k and the sample's antenna
// basis: x = k . theta', y = k . phi' (p' is orthogonal to both). The float32 evaluation takes them
// from d = k - p' instead (pixel.glsl's pixel_geometry), or, on the float64 path, these rounded.
PISCO_TEMPLATE
PISCO_FN void beam_coordinates(PISCO_IN(PISCO_V3) k, PISCO_IN(PISCO_V3) theta_p, PISCO_IN(PISCO_V3) phi_p,
                               PISCO_OUT(PISCO_REAL) x, PISCO_OUT(PISCO_REAL) y) {
  x = dot(k, theta_p);
  y = dot(k, phi_p);
}

// Interpolation of the 4 weights on the n x n grid at x_i = -a + i * step (x fastest): bilinear less
// the curvature terms of the cell's edges (src/kernel/grid_curvature.hpp), which leave an error of
// order step^3 instead of step^2 (docs/physics.md, "Interpolation on the grid"); zero outside the grid.
PISCO_TEMPLATE_GRID
PISCO_FN PISCO_V4 interpolate_weights(PISCO_IN(PISCO_GRID) g, PISCO_REAL x, PISCO_REAL y) {
  const PISCO_REAL u = (x + g.a) * g.inv_step;
  const PISCO_REAL v = (y + g.a) * g.inv_step;
  const PISCO_REAL last = PISCO_REAL(g.n - 1);
  const PISCO_MASK inside = u >= 0.0f && v >= 0.0f && u <= last && v <= last;
  const PISCO_INDEX i = node_index(u, inside, g.n - 2);
  const PISCO_INDEX j = node_index(v, inside, g.n - 2);
  const PISCO_REAL fu = u - PISCO_REAL(i);
  const PISCO_REAL fv = v - PISCO_REAL(j);
  const PISCO_INDEX k00 = j * g.n + i;
  // Then the curvature terms of the cell's edges (src/kernel/grid_curvature.hpp): ex of its lower and upper
  // edges, ey of its left and right ones. Each pair is used as soon as it is read.
  const PISCO_REAL gu = 1.0f - fu;
  const PISCO_REAL gv = 1.0f - fv;
  PISCO_V4 a, b;
  weight_pair(g, k00, a, b);
  PISCO_V4 w = (gu * gv) * a + (fu * gv) * b;
  weight_pair(g, k00 + g.n, a, b);
  w = w + (gu * fv) * a + (fu * fv) * b;
  edge_x_pair(g, k00, i, j, a, b);
  w = w - (fu * gu) * (gv * a + fv * b);
  edge_y_pair(g, k00, a, b);
  w = w - (fv * gv) * (gu * a + fu * b);
  return select_weights(inside, w);
}

// Linear interpolation in r = sqrt(r2) of a radial profile at r = i * step, exactly invariant under
// rotations about the beam axis; zero beyond the last node.
PISCO_TEMPLATE_GRID
PISCO_FN PISCO_V4 interpolate_radial(PISCO_IN(PISCO_GRID) g, PISCO_REAL r2) {
  const PISCO_REAL u = sqrt(max(r2, 0.0f)) * g.inv_step;
  const PISCO_MASK inside = u <= PISCO_REAL(g.n - 1);  // false for NaN
  const PISCO_INDEX i = node_index(u, inside, g.n - 2);
  const PISCO_REAL f = u - PISCO_REAL(i);
  PISCO_V4 w0, w1;
  weight_pair(g, i, w0, w1);
  return select_weights(inside, (1.0f - f) * w0 + f * w1);
}
