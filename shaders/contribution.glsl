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

// Node g's weights and its neighbour's along x (or r), stored side by side and read in one 32-byte
// load (four 64-bit words): half the load instructions, which on lavapipe are most of the cost.
void weight_pair(int g, out vec4 w, out vec4 next) {
  const u64vec4 pair = weight_pairs[g];
  w = uintBitsToFloat(uvec4(unpack32(pair.x), unpack32(pair.y)));
  next = uintBitsToFloat(uvec4(unpack32(pair.z), unpack32(pair.w)));
}

// Bilinear interpolation on the n x n grid at x_i = -a + i * step (x fastest); zero outside.
vec4 interpolate_weights(int offset, int n, float a, float inv_step, float x, float y) {
  const float u = (x + a) * inv_step;
  const float v = (y + a) * inv_step;
  const float last = float(n - 1);
  if (!(u >= 0.0 && v >= 0.0 && u <= last && v <= last)) return vec4(0.0);
  const int i = min(int(u), n - 2);
  const int j = min(int(v), n - 2);
  const float fu = u - float(i);
  const float fv = v - float(j);
  const int g00 = offset + j * n + i;
  vec4 w00, w10, w01, w11;
  weight_pair(g00, w00, w10);
  weight_pair(g00 + n, w01, w11);
  return ((1.0 - fu) * (1.0 - fv)) * w00 + (fu * (1.0 - fv)) * w10 + ((1.0 - fu) * fv) * w01 + (fu * fv) * w11;
}

// Linear interpolation in r = sqrt(r2) of a radial profile at r = i * step; zero beyond.
// Signed indices: CPUs (lavapipe) convert float to int in one instruction, to uint in several.
vec4 interpolate_radial(int offset, int n, float inv_step, float r2) {
  const float u = sqrt(max(r2, 0.0)) * inv_step;
  if (!(u <= float(n - 1))) return vec4(0.0);
  const int i = min(int(u), n - 2);
  const float f = u - float(i);
  vec4 w0, w1;
  weight_pair(offset + i, w0, w1);
  return (1.0 - f) * w0 + f * w1;
}

// w . Lambda(-chi) S (DESIGN 3).
float stokes_response(vec4 w, float cos2chi, float sin2chi, vec4 S) {
  return w.x * S.x + w.y * (S.y * cos2chi + S.z * sin2chi) + w.z * (S.z * cos2chi - S.y * sin2chi) +
         w.w * S.w;
}

// The float64 path: (w_I, Omega_pix B_TT / Omega~) interpolated in double from double coordinates.
dvec2 interpolate_weights64(uint offset, uint n, double a, double inv_step, double x, double y) {
  const double u = (x + a) * inv_step;
  const double v = (y + a) * inv_step;
  const double last = double(n - 1u);
  if (!(u >= 0.0 && v >= 0.0 && u <= last && v <= last)) return dvec2(0.0);
  const uint i = min(uint(u), n - 2u);
  const uint j = min(uint(v), n - 2u);
  const double fu = u - double(i);
  const double fv = v - double(j);
  const uint g00 = offset + j * n + i;
  return ((1.0 - fu) * (1.0 - fv)) * weights64[g00] + (fu * (1.0 - fv)) * weights64[g00 + 1u] +
         ((1.0 - fu) * fv) * weights64[g00 + n] + (fu * fv) * weights64[g00 + n + 1u];
}

dvec2 interpolate_radial64(uint offset, uint n, double inv_step, double r2) {
  const double u = sqrt(max(r2, 0.0lf)) * inv_step;
  if (!(u <= double(n - 1u))) return dvec2(0.0);
  const uint i = min(uint(u), n - 2u);
  const double f = u - double(i);
  return (1.0 - f) * weights64[offset + i] + f * weights64[offset + i + 1u];
}

#endif
