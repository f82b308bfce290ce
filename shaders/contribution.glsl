// The per-pixel contribution of the measurement equation in float32: src/core/contribution.hpp line
// for line (see the derivation there and in docs/physics.md); the backend parity tests
// (tests/test_backend_parity.cpp) hold the two to the same numbers.
#ifndef PISCO_CONTRIBUTION_GLSL
#define PISCO_CONTRIBUTION_GLSL

struct SampleFrame {
  vec3 theta_p, phi_p, p;  // theta', phi', p'
  vec3 e_c;                // cos(zeta) theta' + sin(zeta) phi'
};

// Antenna coordinates (x, y, z) of k, r2 = x^2 + y^2 (independent of psi) and (cos 2chi, sin 2chi),
// all from d = k - p' (see contribution.hpp for why).
void pixel_geometry(SampleFrame f, vec3 k, out vec3 xyz, out float r2, out float cos2chi, out float sin2chi) {
  const vec3 d = k - f.p;
  const float dz = dot(d, f.p);  // z - 1
  xyz = vec3(dot(d, f.theta_p), dot(d, f.phi_p), 1.0 + dz);
  r2 = dot(d, d) - dz * dz;
  const float t = dot(d, f.e_c);
  const float zp = 2.0 + dz;
  const float c = (k.z * t - f.e_c.z) * zp - t * (d.z + k.z * dz);
  const float s = (k.x * f.e_c.y - k.y * f.e_c.x) * zp - t * (d.x * f.p.y - d.y * f.p.x);
  const float inv = 1.0 / (c * c + s * s);
  cos2chi = (c * c - s * s) * inv;
  sin2chi = 2.0 * c * s * inv;
}

// The beam grid of one detector, read from the push constants once per sample (lavapipe reads a
// push constant inside a loop again for every invocation and iteration).
struct Grid {
  int offset;      // first texel in the weight texels
  int n;           // nodes per axis (radial: along r)
  float a;         // half-width: nodes at x_i = -a + i * step
  float inv_step;  // 1 / step
  uint offset64;   // first node in the float64 weights
  double a64, inv_step64;
};

// Node k's weights and its neighbour's along x (or r), stored side by side: one texel with the
// two columns (w_I, w_Q) of each, or two texels with all four.
void weight_pair(Grid g, int k, out vec4 w, out vec4 next) {
  if (COLUMNS == 2) {
    const vec4 t = uintBitsToFloat(texelFetch(weight_pairs, g.offset + k));
    w = vec4(t.xy, 0.0, 0.0);
    next = vec4(t.zw, 0.0, 0.0);
  } else {
    w = uintBitsToFloat(texelFetch(weight_pairs, g.offset + 2 * k));
    next = uintBitsToFloat(texelFetch(weight_pairs, g.offset + 2 * k + 1));
  }
}

// Bilinear interpolation on the n x n grid at x_i = -a + i * step (x fastest); zero outside.
// Without branches: the nodes are clamped into the grid and the result selected, which keeps
// lavapipe's vector code free of masked writes.
vec4 interpolate_weights(Grid g, float x, float y) {
  const float u = (x + g.a) * g.inv_step;
  const float v = (y + g.a) * g.inv_step;
  const float last = float(g.n - 1);
  const bool inside = u >= 0.0 && v >= 0.0 && u <= last && v <= last;
  const int i = clamp(int(u), 0, g.n - 2);
  const int j = clamp(int(v), 0, g.n - 2);
  const float fu = u - float(i);
  const float fv = v - float(j);
  const int k00 = j * g.n + i;
  vec4 w00, w10, w01, w11;
  weight_pair(g, k00, w00, w10);
  weight_pair(g, k00 + g.n, w01, w11);
  const vec4 w = ((1.0 - fu) * (1.0 - fv)) * w00 + (fu * (1.0 - fv)) * w10 + ((1.0 - fu) * fv) * w01 + (fu * fv) * w11;
  return inside ? w : vec4(0.0);
}

// Linear interpolation in r = sqrt(r2) of a radial profile at r = i * step; zero beyond.
// Signed indices: CPUs (lavapipe) convert float to int in one instruction, to uint in several.
vec4 interpolate_radial(Grid g, float r2) {
  const float u = sqrt(max(r2, 0.0)) * g.inv_step;
  const int i = clamp(int(u), 0, g.n - 2);
  const float f = u - float(i);
  vec4 w0, w1;
  weight_pair(g, i, w0, w1);
  const vec4 w = (1.0 - f) * w0 + f * w1;
  return u <= float(g.n - 1) ? w : vec4(0.0);
}

// w . Lambda(-chi) S (docs/physics.md, "The measurement equation").
float stokes_response(vec4 w, float cos2chi, float sin2chi, vec4 S) {
  return w.x * S.x + w.y * (S.y * cos2chi + S.z * sin2chi) + w.z * (S.z * cos2chi - S.y * sin2chi) +
         w.w * S.w;
}

// The float64 path: (w_I, Omega_pix B_TT / Omega~) interpolated in double from double coordinates.
dvec2 weight64(uint k) {
  const uvec4 t = texelFetch(weights64, int(k));
  return dvec2(packDouble2x32(t.xy), packDouble2x32(t.zw));
}

// The float64 interpolation at (x, y): its nodes (absolute node indices) and coefficients, linear in
// r = sqrt(x^2 + y^2) for a radial profile (2 nodes), bilinear on the grid otherwise (4 nodes); no
// node outside the grid or beyond the profile. One stencil for every float64 table a node has.
struct Stencil64 {
  uint k[4];
  double c[4];
  int m;  // nodes used
};

Stencil64 stencil64(Grid grid, double x, double y) {
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
    s.c[0] = 1.0 - f;
    s.c[1] = f;
    s.m = 2;
    return s;
  }
  const double u = (x + grid.a64) * grid.inv_step64;
  const double v = (y + grid.a64) * grid.inv_step64;
  const double last = double(n - 1u);
  if (!(u >= 0.0 && v >= 0.0 && u <= last && v <= last)) return s;
  const uint i = min(uint(u), n - 2u);
  const uint j = min(uint(v), n - 2u);
  const double fu = u - double(i);
  const double fv = v - double(j);
  const uint g00 = offset + j * n + i;
  s.k[0] = g00;
  s.k[1] = g00 + 1u;
  s.k[2] = g00 + n;
  s.k[3] = g00 + n + 1u;
  s.c[0] = (1.0 - fu) * (1.0 - fv);
  s.c[1] = fu * (1.0 - fv);
  s.c[2] = (1.0 - fu) * fv;
  s.c[3] = fu * fv;
  s.m = 4;
  return s;
}

// Half-wave plates at the aperture (docs/physics.md, "Half-wave plates"): the float64 weights of a
// plate detector are 3 texels a node, (w_I, wn), (w_Q, w_U), (w_V, 0); M0 is 8 texels, row by row.
dvec4 plate_weight64(uint k) {
  const uvec4 a = texelFetch(weights64, int(3u * k)), b = texelFetch(weights64, int(3u * k + 1u)),
              c = texelFetch(weights64, int(3u * k + 2u));
  return dvec4(packDouble2x32(a.xy), packDouble2x32(b.xy), packDouble2x32(b.zw), packDouble2x32(c.xy));
}

double plate_norm_at(uint k) { return packDouble2x32(texelFetch(weights64, int(3u * k)).zw); }

// M(theta) = R(-theta) M0 R(theta) with c = cos 2 theta, s = sin 2 theta, as columns: mt[j][i] = M_ij.
// R(theta) rows (1,0,0,0), (0,c,s,0), (0,-s,c,0), (0,0,0,1).
void plate_mueller(uint offset, double c, double s, out dmat4 mt) {
  dmat4 m0;  // m0[j][i] = (M0)_ij
  for (int r = 0; r < 4; ++r) {
    const uvec4 t0 = texelFetch(weights64, int(offset) + 2 * r), t1 = texelFetch(weights64, int(offset) + 2 * r + 1);
    m0[0][r] = packDouble2x32(t0.xy);
    m0[1][r] = packDouble2x32(t0.zw);
    m0[2][r] = packDouble2x32(t1.xy);
    m0[3][r] = packDouble2x32(t1.zw);
  }
  dmat4 rot = dmat4(1.0lf);  // rot[j][i] = R(theta)_ij
  rot[1][1] = c;
  rot[2][1] = s;
  rot[1][2] = -s;
  rot[2][2] = c;
  mt = transpose(rot) * m0 * rot;
}

#endif
