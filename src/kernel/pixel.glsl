// The per-pixel and per-sample arithmetic of the convolution (docs/physics.md, "The measurement
// equation"), written once, in the common subset of GLSL and C++, for every backend:
// - the shaders include it as GLSL (float32: REAL is float, V3 vec3, V4 vec4);
// - tests/glsl_to_cpp.cmake turns it, with the rest of the kernel, into C++ on glm's types for the
//   host tests (tests/test_kernel_host.cpp);
// - src/kernel/contribution-inl.hpp includes it as C++ templates (PISCO_TEMPLATE_TEXT): REAL is the
//   template parameter T, double for the float64 reference, float for the CUDA kernels, a vector of
//   float32 lanes for the simd backend (src/simd/simd_kernel.cpp), which includes it once per
//   instruction set.
// tests/test_kernel_host.cpp runs every function here through the GLSL-as-C++ build and the C++
// template build on random inputs and requires the same bits.
//
// The derivation of pixel_geometry is in src/kernel/contribution.hpp. Rules of the common subset
// (src/kernel/common.glsl): vectors built by constructor (PISCO_VEC3, PISCO_VEC4), no swizzle assigned,
// float32 constants written with `f` and exactly representable (so that T = double sees the same
// value), no `lf` literal here (the C++ build includes this file as it is). Each backend supplies, for
// its beam-weight layout:
//   weight_pair(grid, node, w, next): the 4 weights of `node` and of `node + 1`;
//   edge_x_pair(grid, k, i, j, ex0, ex1), edge_y_pair(grid, k, ey0, ey1): the curvature terms of the
//   lower and upper edges and of the left and right edges of cell (i, j), k = j n + i
//   (src/kernel/grid_curvature.hpp);
//   node_index(u, inside, top): int(u) clamped to [0, top] (u >= 0 where `inside`);
//   select_weights(inside, w): w where `inside`, zero elsewhere.
#if defined(PISCO_TEMPLATE_TEXT) || !defined(PISCO_PIXEL_GLSL)
#ifndef PISCO_TEMPLATE_TEXT
#define PISCO_PIXEL_GLSL
#include "common.glsl"

#define PISCO_TEMPLATE
#define PISCO_TEMPLATE_GRID
#define PISCO_REAL float
#define PISCO_V3 vec3
#define PISCO_V4 vec4
#define PISCO_INDEX int
#define PISCO_MASK bool
#define PISCO_IN(T) T
#define PISCO_GRID Grid
#define PISCO_FRAME SampleFrame
#define PISCO_GEOMETRY PixelGeometry
#define PISCO_VEC3(a, b, c) vec3(a, b, c)

// The beam grid of one detector, as the shaders read it from the push constants once per sample
// (lavapipe reads a push constant inside a loop again for every invocation and iteration).
struct Grid {
  int offset;      // first texel in the weight texels
  int n;           // nodes per axis (radial: along r)
  float a;         // half-width: nodes at x_i = -a + i * step
  float inv_step;  // 1 / step
  uint offset64;   // first node in the float64 weights
  PISCO_F64 a64, inv_step64;
};

// Node k's weights and its neighbour's along x (or r), stored side by side: one texel with the
// two columns (w_I, w_Q) of each, or two texels with all four.
PISCO_FN void weight_pair(Grid g, int k, PISCO_OUT(vec4) w, PISCO_OUT(vec4) next) {
  if (COLUMNS == 2) {
    const vec4 t = uintBitsToFloat(texelFetch(weight_pairs, g.offset + k));
    w = vec4(t.x, t.y, 0.0f, 0.0f);
    next = vec4(t.z, t.w, 0.0f, 0.0f);
  } else {
    w = uintBitsToFloat(texelFetch(weight_pairs, g.offset + 2 * k));
    next = uintBitsToFloat(texelFetch(weight_pairs, g.offset + 2 * k + 1));
  }
}

// The edges' curvature terms, stored after the nodes in the nodes' layout (src/kernel/grid_curvature.hpp):
// ex of cell (i, j)'s lower and upper edges at n^2 + i n + j, ey of its left and right edges at
// 2 n^2 + k.
PISCO_FN void edge_x_pair(Grid g, int k, int i, int j, PISCO_OUT(vec4) ex0, PISCO_OUT(vec4) ex1) {
  weight_pair(g, i * g.n + j + g.n * g.n, ex0, ex1);
}
PISCO_FN void edge_y_pair(Grid g, int k, PISCO_OUT(vec4) ey0, PISCO_OUT(vec4) ey1) {
  weight_pair(g, k + 2 * g.n * g.n, ey0, ey1);
}

// Signed indices: CPUs (lavapipe) convert float to int in one instruction, to uint in several. Out of
// the grid the node is clamped and its weights discarded by select_weights: no branch, which keeps
// lavapipe's vector code free of masked writes.
PISCO_FN int node_index(float u, bool inside, int top) { return clamp(int(u), 0, top); }
PISCO_FN vec4 select_weights(bool inside, vec4 w) { return inside ? w : vec4(0.0f); }
#endif

// Per-sample quantities: the antenna basis and the beam-centre co-polarization vector.
PISCO_TEMPLATE
struct SampleFrame {
  PISCO_V3 theta_p, phi_p, p;  // theta', phi', p'
  PISCO_V3 e_c;                // cos(zeta) theta' + sin(zeta) phi'
};

// A pixel's antenna coordinates: (x, y) the orthographic beam coordinates, z = cos(rho), r2 =
// x^2 + y^2 (independent of psi), and the polarization rotation (cos 2chi, sin 2chi).
PISCO_TEMPLATE
struct PixelGeometry {
  PISCO_REAL x, y, z;
  PISCO_REAL r2;
  PISCO_REAL cos2chi, sin2chi;
};

// Everything from d = k - p', small across the disc (src/kernel/contribution.hpp says why).
PISCO_TEMPLATE
PISCO_FN PISCO_GEOMETRY pixel_geometry(PISCO_IN(PISCO_FRAME) f, PISCO_IN(PISCO_V3) k) {
  PISCO_GEOMETRY g;
  const PISCO_V3 d = PISCO_VEC3(k.x - f.p.x, k.y - f.p.y, k.z - f.p.z);
  g.x = dot(d, f.theta_p);
  g.y = dot(d, f.phi_p);
  const PISCO_REAL dz = dot(d, f.p);  // z - 1
  g.z = 1.0f + dz;
  g.r2 = dot(d, d) - dz * dz;
  const PISCO_REAL t = dot(d, f.e_c);
  // c and s times (1 + z): the common factor cancels in cos 2chi and sin 2chi, saving a division.
  // k_z z - p'_z = d_z + k_z dz and k_x p'_y - k_y p'_x = d_x p'_y - d_y p'_x.
  const PISCO_REAL zp = 2.0f + dz;
  const PISCO_REAL c = (k.z * t - f.e_c.z) * zp - t * (d.z + k.z * dz);
  const PISCO_REAL s = (k.x * f.e_c.y - k.y * f.e_c.x) * zp - t * (d.x * f.p.y - d.y * f.p.x);
  const PISCO_REAL inv = 1.0f / (c * c + s * s);
  g.cos2chi = (c * c - s * s) * inv;
  g.sin2chi = 2.0f * c * s * inv;
  return g;
}

#include "interpolate.glsl"

// w . Lambda(-chi) S, S = (I, Q, U, V): the detector-weighted Stokes response of one pixel.
PISCO_TEMPLATE
PISCO_FN PISCO_REAL stokes_response(PISCO_IN(PISCO_V4) w, PISCO_REAL cos2chi, PISCO_REAL sin2chi,
                                    PISCO_IN(PISCO_V4) S) {
  return w.x * S.x + w.y * (S.y * cos2chi + S.z * sin2chi) + w.z * (S.z * cos2chi - S.y * sin2chi) + w.w * S.w;
}

// The transpose of stokes_response: its gradient with respect to S = (I, Q, U, V), the weights with
// which the adjoint scatters a sample's value onto the pixel's Stokes parameters (docs/physics.md,
// "The adjoint"): stokes_response(w, c, s, S) = dot(stokes_adjoint(w, c, s), S).
PISCO_TEMPLATE
PISCO_FN PISCO_V4 stokes_adjoint(PISCO_IN(PISCO_V4) w, PISCO_REAL cos2chi, PISCO_REAL sin2chi) {
  PISCO_V4 g;
  g.x = w.x;
  g.y = w.y * cos2chi - w.z * sin2chi;
  g.z = w.y * sin2chi + w.z * cos2chi;
  g.w = w.w;
  return g;
}

// The same with w_U = w_V = 0 (detectors without a plate whose beams have no U, V rows).
PISCO_TEMPLATE
PISCO_FN PISCO_REAL stokes_response_iq(PISCO_IN(PISCO_V4) w, PISCO_REAL cos2chi, PISCO_REAL sin2chi,
                                       PISCO_IN(PISCO_V4) S) {
  return w.x * S.x + w.y * (S.y * cos2chi + S.z * sin2chi);
}

// stokes_adjoint with w_U = w_V = 0: the same I, Q, U weights (w_U terms are signed zeros, which
// change no sum that starts at +0), and no V weight (zero).
PISCO_TEMPLATE
PISCO_FN PISCO_V3 stokes_adjoint_iq(PISCO_IN(PISCO_V4) w, PISCO_REAL cos2chi, PISCO_REAL sin2chi) {
  return PISCO_VEC3(w.x, w.y * cos2chi, w.y * sin2chi);
}

// w M (a row vector times the plate's Mueller matrix, given by its columns c0 ... c3): a pixel's
// effective weights behind a half-wave plate at the aperture (docs/physics.md, "Half-wave plates").
PISCO_TEMPLATE
PISCO_FN PISCO_V4 effective_weights(PISCO_IN(PISCO_V4) w, PISCO_IN(PISCO_V4) c0, PISCO_IN(PISCO_V4) c1,
                                    PISCO_IN(PISCO_V4) c2, PISCO_IN(PISCO_V4) c3) {
  PISCO_V4 v;
  v.x = w.x * c0.x + w.y * c0.y + w.z * c0.z + w.w * c0.w;
  v.y = w.x * c1.x + w.y * c1.y + w.z * c1.z + w.w * c1.w;
  v.z = w.x * c2.x + w.y * c2.y + w.z * c2.z + w.w * c2.w;
  v.w = w.x * c3.x + w.y * c3.y + w.z * c3.z + w.w * c3.w;
  return v;
}

// One step of a Kahan-compensated sum: sum += value, the rounding error kept in comp.
PISCO_TEMPLATE
PISCO_FN void kahan_add(PISCO_INOUT(PISCO_REAL) sum, PISCO_INOUT(PISCO_REAL) comp, PISCO_REAL value) {
  PISCO_PRECISE const PISCO_REAL y = value - comp;
  PISCO_PRECISE const PISCO_REAL t = sum + y;
  PISCO_PRECISE const PISCO_REAL e = (t - sum) - y;
  comp = e;
  sum = t;
}

// The rings NSIDE and 3 NSIDE, where the polar caps meet the equatorial belt (docs/physics.md, "The
// quadrature"), and their neighbours: the first pixels of rings NSIDE and 3 NSIDE, and which of the
// six rings about them pixel p lies on: CAP_LAST_RING for NSIDE - 1 and 3 NSIDE + 1 (the caps' last,
// 4 (NSIDE - 1) pixels each), CAP_EDGE_RING for NSIDE and 3 NSIDE, CAP_BELT_RING for NSIDE + 1 and
// 3 NSIDE - 1 (the belt's first, 4 NSIDE pixels each, like the edges), 0 for every other pixel.
// NSIDE must be at most 16384 (12 NSIDE^2 < 2^32).
const uint CAP_LAST_RING = 1u;
const uint CAP_EDGE_RING = 2u;
const uint CAP_BELT_RING = 3u;
PISCO_FN uint cap_boundary_north(uint nside) { return 2u * nside * (nside - 1u); }
PISCO_FN uint cap_boundary_south(uint nside) { return cap_boundary_north(nside) + 8u * nside * nside; }
PISCO_FN uint cap_boundary_ring(uint p, uint nside) {
  // The six rings are two runs of pixels: rings NSIDE - 1 to NSIDE + 1 from the north's first, 3 NSIDE
  // - 1 to 3 NSIDE + 1 from the south's; p - first < length exactly when p lies in the run (unsigned).
  const uint edge = 4u * nside, last = edge - 4u;  // the pixels of an edge ring, of a cap's last ring
  const uint n = p - (cap_boundary_north(nside) - last), s = p - (cap_boundary_south(nside) - edge);
  if (n < last + 2u * edge) return n < last ? CAP_LAST_RING : n < last + edge ? CAP_EDGE_RING : CAP_BELT_RING;
  if (s < last + 2u * edge) return s < edge ? CAP_BELT_RING : s < 2u * edge ? CAP_EDGE_RING : CAP_LAST_RING;
  return 0u;
}

#if !PISCO_FF
// A sample's TOD value from its float32 part d, its monopole weight s0 = sum_k w_I(k) (taken times
// the sky's monopole I0) and its normalization n0 = sum_k wn(k) (docs/physics.md, "Normalization").
PISCO_FN double finish_sample(double d, double monopole, double s0, double n0, bool per_sample) {
  const double v = d + monopole * s0;
  return per_sample ? (n0 > 0.0f ? v / n0 : 0.0f) : v;
}
#endif

#endif
