// Disc selection from the ring table (docs/physics.md, "Disc selection"): src/core/disc.hpp line for line, in float64, with
// `precise` so that the compiler contracts nothing the reference computes in two roundings. One
// invocation handles one ring and produces at most two contiguous pixel ranges.
#ifndef PISCO_DISC_GLSL
#define PISCO_DISC_GLSL

#include "fp64.glsl"

const double PISCO_PI = 3.141592653589793238462643383279502884lf;

// Ring iz (1-based) of the ring table: one texel (z's low and high words, first pixel, pixel count
// with the shifted flag in its top bit).
RingEntry ring_entry(int iz) {
  const uvec4 t = texelFetch(rings, iz - 1);
  return RingEntry(packDouble2x32(t.xy), t.z, t.w & 0x7fffffffu, (t.w >> 31) != 0u);
}

// HEALPix's ring_above: the ring just north of z (0 north of ring 1).
int ring_above(int nside, double z) {
  const double az = abs(z);
  if (az <= 2.0lf / 3.0lf) return int(double(nside) * (2.0lf - 1.5lf * z));
  const int iring = int(double(nside) * sqrt(3.0lf * (1.0lf - az)));
  return (z > 0.0lf) ? iring : 4 * nside - iring - 1;
}

// The pixel ranges of ring `ring` inside the disc of cos_rho around (z0, phi0), xa = 1 / sin(theta0):
// [b0, b0 + l0) and [b1, b1 + l1), lengths 0 when absent.
void ring_ranges(RingEntry ring, double z0, double xa, double phi0, double cos_rho, out uint b0, out uint l0,
                 out uint b1, out uint l1) {
  b0 = 0u; l0 = 0u; b1 = 0u; l1 = 0u;
  const double z = ring.z;
  precise const double x = (cos_rho - z * z0) * xa;
  precise const double ysq = 1.0lf - z * z - x * x;
  if (ysq <= 0.0lf) return;
  const double dphi = pisco_atan2_nonneg_y(sqrt(ysq), x);
  if (!(dphi > 0.0lf)) return;
  const int nr = int(ring.count);
  const uint first = ring.first;
  const double shift = ring.shifted ? 0.5lf : 0.0lf;
  const double inv_twopi = 0.5lf / PISCO_PI;
  precise const double lo = double(nr) * inv_twopi * (phi0 - dphi) - shift;
  precise const double hi = double(nr) * inv_twopi * (phi0 + dphi) - shift;
  int ip_lo = int(floor(lo)) + 1;
  int ip_hi = int(floor(hi));
  if (ip_lo > ip_hi) return;
  if (ip_hi >= nr) {
    ip_lo -= nr;
    ip_hi -= nr;
  }
  if (ip_lo < 0) {
    b0 = first; l0 = uint(ip_hi + 1);
    b1 = first + uint(ip_lo + nr); l1 = uint(-ip_lo);
  } else {
    b0 = first + uint(ip_lo); l0 = uint(ip_hi - ip_lo + 1);
  }
}

#endif
