// Disc selection from the ring table (docs/physics.md, "Disc selection"). In float64: src/kernel/disc.hpp's
// walk, its disc's rings, ring crossings and pixel ranges the reference's own text, rings.glsl (every
// product that feeds an addition rounded by itself, mul_rn). Without float64 (PISCO_FF): each ring's range estimated in float32 and its ends settled
// by testing the pixels there in float-float (k . p' >= cos rho_max), which selects the same pixels
// unless one lies within about 1e-14 of the disc's edge. Each ring gives at most two contiguous pixel
// ranges. Written in the common subset of GLSL and C++ (tests/test_kernel_host.cpp runs it as C++);
// reads the tables `rings`, and in float-float `sky` and `sky_lo`.
#ifndef PISCO_DISC_GLSL
#define PISCO_DISC_GLSL

#include "common.glsl"
#if PISCO_FF
#include "ff.glsl"
#else
#include "fp64.glsl"
#endif

struct RingEntry {
  PISCO_F64 z;
  uint first;
  uint count;
  bool shifted;
};

// Ring iz (1-based) of the ring table: one texel (z's two words, first pixel, pixel count with the
// shifted flag in its top bit).
PISCO_FN RingEntry ring_entry(int iz) {
  const uvec4 t = texelFetch(rings, iz - 1);
  RingEntry r;
#if PISCO_FF
  r.z = vec2(uintBitsToFloat(t.x), uintBitsToFloat(t.y));
#else
  r.z = packDouble2x32(uvec2(t.x, t.y));
#endif
  r.first = t.z;
  r.count = t.w & 0x7fffffffu;
  r.shifted = (t.w >> 31) != 0u;
  return r;
}

#if !PISCO_FF

const double PISCO_PI = 3.141592653589793238462643383279502884lf;
#include "rings.glsl"

// The rings of the disc of radius rho_max around colatitude theta: [first, last], of which those
// outside [irmin, irmax] lie whole inside it (the polar caps).
PISCO_FN void disc_rings(int nside, double theta, double rho_max, PISCO_OUT(int) first, PISCO_OUT(int) last,
                         PISCO_OUT(int) irmin, PISCO_OUT(int) irmax) {
  bool north_cap, south_cap;  // every ring north of irmin (south of irmax) entirely
  disc_ring_span(nside, theta, rho_max, irmin, irmax, north_cap, south_cap);
  first = north_cap ? 1 : irmin;
  last = south_cap ? 4 * nside - 1 : irmax;
}

// The pixel ranges of ring `ring` inside the disc of cos_rho around (z0, phi0), xa = 1 / sin(theta0):
// [b0, b0 + l0) and [b1, b1 + l1), lengths 0 when absent.
PISCO_FN void ring_ranges(RingEntry ring, double z0, double xa, double phi0, double cos_rho, PISCO_OUT(uint) b0,
                          PISCO_OUT(uint) l0, PISCO_OUT(uint) b1, PISCO_OUT(uint) l1) {
  b0 = 0u; l0 = 0u; b1 = 0u; l1 = 0u;
  const double x = ring_edge_x(ring.z, z0, xa, cos_rho);
  const double ysq = ring_edge_ysq(ring.z, x);
  if (ysq <= 0.0lf) return;
  const double dphi = ring_half_width(x, ysq);
  if (!(dphi > 0.0lf)) return;
  int lo, hi;
  ring_pixel_span(ring.count, ring.shifted, phi0, dphi, lo, hi);
  ring_pixel_ranges(ring.first, ring.count, lo, hi, b0, l0, b1, l1);
}

#else  // PISCO_FF

// HEALPix's ring_above for z in float-float.
PISCO_FN int ff_ring_above(int nside, vec2 z) {
  const vec2 az = ff_abs(z);
  if (ff_le(az, ff_div(vec2(2.0f, 0.0f), vec2(3.0f, 0.0f))))
    return int(ff_floor(ff_mul_f(ff_sub(vec2(2.0f, 0.0f), ff_mul_f(z, 1.5f)), float(nside))));
  const float rest = ff_sub(vec2(1.0f, 0.0f), az).x;  // 1 - |z|, to float32's relative precision
  const int iring = int(float(nside) * sqrt(3.0f * rest));
  return (z.x > 0.0f) ? iring : 4 * nside - iring - 1;
}

// The rings that can meet the disc of cos_rho around p (z0 = p.z, sin_theta0 = sqrt(1 - z0^2)): a
// ring of margin on either side of HEALPix's, since each ring's pixels are settled below.
PISCO_FN void ff_disc_rings(int nside, vec2 z0, vec2 sin_theta0, vec2 cos_rho, PISCO_OUT(int) first,
                            PISCO_OUT(int) last) {
  const int nrings = 4 * nside - 1;
  const vec2 one = vec2(1.0f, 0.0f);
  const vec2 sin_rho = ff_sqrt(ff_mul(ff_sub(one, cos_rho), ff_add(one, cos_rho)));
  const vec2 a = ff_mul(z0, cos_rho), b = ff_mul(sin_theta0, sin_rho);
  // theta0 <= rho: the north pole is in the disc; theta0 + rho >= pi: the south pole.
  first = ff_le(cos_rho, z0) ? 1 : max(1, ff_ring_above(nside, ff_add(a, b)));
  last = ff_le(z0, ff_neg(cos_rho)) ? nrings : min(nrings, ff_ring_above(nside, ff_sub(a, b)) + 1);
}

// A sky pixel's float64 unit vector, as float-float: its float32 vector and the residual. The tables
// start at pixel SKY_FIRST.
PISCO_FN ff3 sky_vector_ff(uint pix) {
  const uint t = pix - SKY_FIRST;
  const uvec4 a = texelFetch(sky, int(2u * t)), b = texelFetch(sky_lo, int(t));
  return ff3_from_parts(vec3(uintBitsToFloat(a.x), uintBitsToFloat(a.y), uintBitsToFloat(a.z)),
                        vec3(uintBitsToFloat(b.x), uintBitsToFloat(b.y), uintBitsToFloat(b.z)));
}

// Whether pixel ip of the ring (any ip > -2 nr, taken modulo nr) lies in the disc: k . p >= cos rho,
// decided in float32 where that is certain (its error is below 1e-6) and in float-float otherwise.
PISCO_FN bool ff_in_disc(RingEntry ring, int ip, ff3 p, vec2 cos_rho) {
  const int nr = int(ring.count);
  const ff3 k = sky_vector_ff(ring.first + uint((ip + 2 * nr) % nr));
  const float d = dot(ff3_hi(k), ff3_hi(p));
  if (d > cos_rho.x + 1e-5f) return true;
  if (d < cos_rho.x - 1e-5f) return false;
  return ff_le(cos_rho, ff_dot(k, p));
}

// The pixel ranges of `ring` inside the disc of cos_rho around p (phi0: p's longitude in float32):
// [b0, b0 + l0) and [b1, b1 + l1), in the order of ring_ranges.
PISCO_FN void ff_ring_ranges(RingEntry ring, ff3 p, vec2 sin_theta0, float phi0, vec2 cos_rho, PISCO_OUT(uint) b0,
                             PISCO_OUT(uint) l0, PISCO_OUT(uint) b1, PISCO_OUT(uint) l1) {
  b0 = 0u; l0 = 0u; b1 = 0u; l1 = 0u;
  const int nr = int(ring.count);
  const vec2 one = vec2(1.0f, 0.0f);
  // A pixel at longitude phi is inside when sin(theta) sin(theta0) cos(phi - phi0) >= cos rho - z z0.
  const vec2 t = ff_sub(cos_rho, ff_mul(ring.z, p.z));
  const vec2 s = ff_mul(ff_sqrt(ff_mul(ff_sub(one, ring.z), ff_add(one, ring.z))), sin_theta0);
  if (ff_le(t, ff_neg(s))) {  // the whole ring
    b0 = ring.first;
    l0 = ring.count;
    return;
  }
  if (ff_lt(s, t)) return;  // none
  // If any pixel is inside, the one nearest phi0 is: it is m or m + 1.
  const float scale = float(nr) * 0.15915494309189533577f;  // nr / (2 pi)
  const float shift = ring.shifted ? 0.5f : 0.0f;
  int m = int(floor(scale * phi0 - shift));
  if (!ff_in_disc(ring, m, p, cos_rho)) {
    m += 1;
    if (!ff_in_disc(ring, m, p, cos_rho)) return;
  }
  // The ends estimated in float32, then settled pixel by pixel in float-float.
  const float dphi = acos(clamp(t.x / s.x, -1.0f, 1.0f));
  int lo = min(m, int(floor(scale * (phi0 - dphi) - shift)) + 1);
  int hi = min(max(m, int(floor(scale * (phi0 + dphi) - shift))), lo + nr - 1);
  while (lo < m && !ff_in_disc(ring, lo, p, cos_rho)) ++lo;
  while (hi - lo + 1 < nr && ff_in_disc(ring, lo - 1, p, cos_rho)) --lo;
  while (hi > m && !ff_in_disc(ring, hi, p, cos_rho)) --hi;
  while (hi - lo + 1 < nr && ff_in_disc(ring, hi + 1, p, cos_rho)) ++hi;
  const int q = (lo + 2 * nr) / nr - 2;  // floor(lo / nr)
  lo -= q * nr;
  hi -= q * nr;
  if (hi >= nr) {
    b0 = ring.first; l0 = uint(hi - nr + 1);
    b1 = ring.first + uint(lo); l1 = uint(nr - lo);
  } else {
    b0 = ring.first + uint(lo); l0 = uint(hi - lo + 1);
  }
}

#endif

#endif
