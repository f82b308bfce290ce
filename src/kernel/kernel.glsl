// The convolution of one sample (docs/vulkan.md, "The kernel"): its antenna basis, its disc walked
// ring by ring as the float64 reference does (src/cpu/cpu_backend.cpp), and every pixel through the
// float32 contribution (pixel.glsl, every backend's one text) with a Kahan-compensated sum; a float64 path adds the sky's
// monopole, I0 sum_k w_I(k), and the per-sample normalization when asked for. On devices without
// float64 (PISCO_FF) the frame, the disc and that path run in float-float (ff.glsl).
// convolve.comp runs it for every sample; tests/test_kernel_host.cpp compiles this same file as C++
// and holds it to the reference. Reads the push constants `pc`, the buffers `pointing` and
// `plate_angle`, the tables, and the specialization constants RADIAL, FLOAT64, PARTS, COLUMNS, PLATE.
#ifndef PISCO_KERNEL_GLSL
#define PISCO_KERNEL_GLSL

#ifndef PISCO_ADJOINT
#define PISCO_ADJOINT 0  // adjoint.comp sets it: the scatter instead of the sum
#endif

#include "common.glsl"
#include "contribution.glsl"
#include "disc.glsl"
#include "frame.glsl"
#include "plate.glsl"
#if PISCO_ADJOINT
#include "scatter.glsl"
#endif

// The running sums of one sample: Kahan-compensated float32, float64 monopole weight and norm.
struct Sums {
  float sum, comp;
  PISCO_F64 s0, n0;
};

// What the pixel loop needs of a sample.
struct Sample {
  SampleFrame f;  // the float32 frame: the float64 one, rounded
  Grid g;
  mat4 m;  // PLATE: M(theta), m[j] its column j (w * m = w M)
#if PISCO_FF
  ff3 theta_p, phi_p;
  vec2 m0[4];  // PLATE: M(theta)'s column 0, for the monopole's weight sum_a w_a M_a0
#else
  dvec3 theta_p, phi_p;
  dvec4 m0;
  Grid64 g64;  // the float64 weights, part 0
#endif
#if PISCO_ADJOINT
  PISCO_F64 value;  // the scaled value the sample scatters (scatter.glsl)
#endif
};

PISCO_FN Grid sample_grid() {
  // Push constants read once, outside the pixel loops (lavapipe would read them again per lane and
  // per pixel).
  Grid g;
  g.offset = int(pc.grid_offset);
  g.offset64 = pc.grid_offset64;
  g.n = int(pc.grid_n);
  g.a = pc.grid_a32;
  g.inv_step = pc.grid_inv_step32;
  g.a64 = pc.grid_a;
  g.inv_step64 = pc.grid_inv_step;
  return g;
}

// M(theta) by columns in float32 (w * m = w M, effective_weights) from its rows (plate.glsl's plate_rows).
PISCO_FN mat4 plate_matrix(vec4 m0, vec4 m1, vec4 m2, vec4 m3) { return transpose(mat4(m0, m1, m2, m3)); }

// The monopole's weight on ring `ring` of cap_boundary_ring (pixel.glsl; src/core/poles.hpp): the
// ring table keeps the four weights (1, then the caps' last rings', the edges', the belt's) in the two
// texels after its 4 NSIDE - 1 rings, float64 or float-float, low word first.
PISCO_FN uvec2 cap_weight_bits(uint ring) {
  const uvec4 t = texelFetch(rings, int(4u * pc.nside - 1u + (ring >> 1u)));
  return (ring & 1u) != 0u ? uvec2(t.z, t.w) : uvec2(t.x, t.y);
}
#if PISCO_FF
PISCO_FN vec2 cap_weight(uint ring) {
  const uvec2 b = cap_weight_bits(ring);
  return vec2(uintBitsToFloat(b.x), uintBitsToFloat(b.y));
}
#else
PISCO_FN double cap_weight(uint ring) { return packDouble2x32(cap_weight_bits(ring)); }
#endif

// The pixels [b0, b0 + l0) then [b1, b1 + l1), in one loop.
PISCO_FN void accumulate(Sample smp, uint b0, uint l0, uint b1, uint l1, PISCO_INOUT(Sums) acc) {
  const uint jump = b1 - (b0 + l0);  // from the end of the first range to the start of the second
  for (uint q = 0u; q < l0 + l1; ++q) {
    const uint p = b0 + q + (q >= l0 ? jump : 0u);
    const uint t = p - SKY_FIRST;  // the sky tables start at pixel SKY_FIRST (a polar copy's band)
    const vec4 a = uintBitsToFloat(texelFetch(sky, int(2u * t)));
    const vec4 b = uintBitsToFloat(texelFetch(sky, int(2u * t + 1u)));
    const vec3 k = vec3(a.x, a.y, a.z);
    PixelGeometry g = pixel_geometry(smp.f, k);
    // On the float64 path the beam coordinates come from the float64 pixel vectors, as the cuda
    // kernel takes them (docs/vulkan.md, "Precision"): the float32 weights are interpolated there too.
#if PISCO_FF
    vec2 x64 = vec2(0.0f, 0.0f), y64 = vec2(0.0f, 0.0f);
    if (FLOAT64) {
      const ff3 k64 = sky_vector_ff(p);
      x64 = ff_dot(k64, smp.theta_p);
      y64 = ff_dot(k64, smp.phi_p);
      g.x = x64.x;
      g.y = y64.x;
    }
#else
    double x64 = 0.0lf, y64 = 0.0lf;
    if (FLOAT64) {
      const vec4 lo = uintBitsToFloat(texelFetch(sky_lo, int(t)));
      const dvec3 k64 = dvec3(k) + dvec3(lo.x, lo.y, lo.z);
      beam_coordinates(k64, smp.theta_p, smp.phi_p, x64, y64);
      g.x = float(x64);
      g.y = float(y64);
    }
#endif
    vec4 w = RADIAL ? interpolate_radial(smp.g, g.r2) : interpolate_weights(smp.g, g.x, g.y);
    if (PLATE) w = effective_weights(w, smp.m[0], smp.m[1], smp.m[2], smp.m[3]);  // w M(theta)
#if PISCO_ADJOINT
    // The adjoint: the transpose of stokes_response, scattered; its norm pass needs only the float64 sums.
    if (!NORMS) scatter_pixel(p, stokes_adjoint(w, g.cos2chi, g.sin2chi), smp.value);
    if (FLOAT64 && NORMS) {
#else
    kahan_add(acc.sum, acc.comp, stokes_response(w, g.cos2chi, g.sin2chi, vec4(a.w, b.x, b.y, b.z)));
    if (FLOAT64) {
#endif
      // Off the six rings about the caps' edges (ring 0) the monopole's weight is 1.
      const uint ring = cap_boundary_ring(p, pc.nside);
#if PISCO_FF
      const vec2 ring_weight = ring != 0u ? cap_weight(ring) : vec2(1.0f, 0.0f);
      const Stencil64 st = stencil64(smp.g, x64, y64);
      for (int q = 0; q < st.m; ++q) {
        if (PLATE) {
          vec2 wi, wq, wu, wv, wn;
          plate_weight64(st.k[q], wi, wq, wu, wv, wn);
          const vec2 w0 = ff_add(ff_add(ff_mul(wi, smp.m0[0]), ff_mul(wq, smp.m0[1])),
                                 ff_add(ff_mul(wu, smp.m0[2]), ff_mul(wv, smp.m0[3])));
          const vec2 c0 = ff_mul(st.c[q], w0);
          acc.s0 = ff_add(acc.s0, ring != 0u ? ff_mul(ring_weight, c0) : c0);
          acc.n0 = ff_add(acc.n0, ff_mul(st.c[q], wn));
        } else {
          vec2 wi, wn;
          weight64(st.k[q], wi, wn);
          const vec2 c0 = ff_mul(st.c[q], wi);
          acc.s0 = ff_add(acc.s0, ring != 0u ? ff_mul(ring_weight, c0) : c0);
          acc.n0 = ff_add(acc.n0, ff_mul(st.c[q], wn));
        }
      }
#else
      // The float64 weights at the pixel (interpolate.glsl in float64): (w_I, wn), and behind a plate
      // (w_Q, w_U, w_V), for the monopole's weight sum_a w_a M_a0 (plate.glsl).
      Grid64 g64 = smp.g64;
      const dvec4 we = RADIAL ? interpolate_radial(g64, x64 * x64 + y64 * y64) : interpolate_weights(g64, x64, y64);
      double s0 = we.x;
      if (PLATE) {
        g64.part = 1;
        const dvec4 wp = RADIAL ? interpolate_radial(g64, x64 * x64 + y64 * y64) : interpolate_weights(g64, x64, y64);
        s0 = plate_monopole_weight(dvec4(we.x, wp.x, wp.y, wp.z), smp.m0);
      }
      acc.s0 += ring != 0u ? cap_weight(ring) * s0 : s0;
      acc.n0 += we.y;
#endif
    }
  }
}

// Sample sid's sums over the rings part, part + PARTS, ... of its disc, and the pixels it counted.
PISCO_FN void convolve_sample(uint sid, int part, PISCO_OUT(Sums) acc, PISCO_OUT(uint) count) {
  acc.sum = 0.0f;
  acc.comp = 0.0f;
  count = 0u;
  Sample smp;
  smp.g = sample_grid();
#if !PISCO_FF
  smp.g64.offset = smp.g.offset64;
  smp.g64.n = smp.g.n;
  smp.g64.a = smp.g.a64;
  smp.g64.inv_step = smp.g.inv_step64;
  smp.g64.part = 0;
#endif
  const int nside = int(pc.nside);
#if PISCO_ADJOINT
  acc.s0 = PISCO_F64(0.0);
  acc.n0 = PISCO_F64(0.0);
  smp.value = NORMS ? PISCO_F64(0.0) : values[sid];
  if (!NORMS && smp.value == PISCO_F64(0.0)) return;  // nothing to scatter
#endif
#if PISCO_FF
  acc.s0 = vec2(0.0f, 0.0f);
  acc.n0 = vec2(0.0f, 0.0f);
  // The detector's antenna basis and line of sight (frame.glsl): the host gives every sample as a
  // boresight quaternion on this path.
  ffquat b, oq;
  b.x = pointing[4u * sid];
  b.y = pointing[4u * sid + 1u];
  b.z = pointing[4u * sid + 2u];
  b.w = pointing[4u * sid + 3u];
  oq.x = pc.offset_quat[0];
  oq.y = pc.offset_quat[1];
  oq.z = pc.offset_quat[2];
  oq.w = pc.offset_quat[3];
  ff3 p;
  ff_sample_frame((pc.flags & PISCO_FLAG_OFFSET) != 0u, b, oq, smp.theta_p, smp.phi_p, p);
  smp.f.theta_p = ff3_hi(smp.theta_p);
  smp.f.phi_p = ff3_hi(smp.phi_p);
  smp.f.p = ff3_hi(p);
  // The plate's Mueller matrix at this sample's angle: c = cos 2 theta and s = sin 2 theta come from
  // the host in float-float.
  smp.m = mat4(1.0f);
  smp.m0[0] = vec2(1.0f, 0.0f);
  smp.m0[1] = vec2(0.0f, 0.0f);
  smp.m0[2] = vec2(0.0f, 0.0f);
  smp.m0[3] = vec2(0.0f, 0.0f);
  if (PLATE) {
    const vec2 c = plate_angle[2u * sid], s = plate_angle[2u * sid + 1u];
    const uint o = pc.plate_offset64;
    // M(theta) in float32 from M0's leading parts; its column 0 in float-float.
    vec4 r[4], m[4];
    for (int i = 0; i < 4; ++i)
      r[i] = vec4(plate_entry(o, i, 0).x, plate_entry(o, i, 1).x, plate_entry(o, i, 2).x, plate_entry(o, i, 3).x);
    plate_rows(r[0], r[1], r[2], r[3], c.x, s.x, m[0], m[1], m[2], m[3]);
    smp.m = plate_matrix(m[0], m[1], m[2], m[3]);
    const vec2 m10 = plate_entry(o, 1, 0), m20 = plate_entry(o, 2, 0);
    smp.m0[0] = plate_entry(o, 0, 0);
    smp.m0[1] = ff_sub(ff_mul(c, m10), ff_mul(s, m20));
    smp.m0[2] = ff_add(ff_mul(s, m10), ff_mul(c, m20));
    smp.m0[3] = plate_entry(o, 3, 0);
  }
  const vec3 ec = pc.cos_zeta * smp.f.theta_p + pc.sin_zeta * smp.f.phi_p;
  smp.f.e_c = ec;
  // The disc: the rings that can meet it, each settled in float-float.
  const vec2 sin_theta0 = ff_sqrt(ff_add(ff_mul(p.x, p.x), ff_mul(p.y, p.y)));
  float phi0 = atan(p.y.x, p.x.x);
  if (phi0 < 0.0f) phi0 += 6.28318530717958647693f;
  int first_ring, last_ring;
  ff_disc_rings(nside, p.z, sin_theta0, pc.cos_rho_max, first_ring, last_ring);
  for (int iz = first_ring + part; iz <= last_ring; iz += PARTS) {
    uint b0, l0, b1, l1;
    ff_ring_ranges(ring_entry(iz), p, sin_theta0, phi0, pc.cos_rho_max, b0, l0, b1, l1);
    count += l0 + l1;
    accumulate(smp, b0, l0, b1, l1, acc);
  }
#else
  acc.s0 = 0.0lf;
  acc.n0 = 0.0lf;
  // The detector's antenna basis and line of sight in float64 (frame.glsl): from the boresight's
  // angles or quaternion, with the detector's offset applied.
  const dvec4 b = dvec4(pointing[4u * sid], pointing[4u * sid + 1u], pointing[4u * sid + 2u], pointing[4u * sid + 3u]);
  const dvec4 offset_quat = dvec4(pc.offset_quat[0], pc.offset_quat[1], pc.offset_quat[2], pc.offset_quat[3]);
  dvec3 p64;
  double theta, phi;
  pisco_sample_frame((pc.flags & PISCO_FLAG_QUATERNION) != 0u, (pc.flags & PISCO_FLAG_OFFSET) != 0u, b, offset_quat,
                     smp.theta_p, smp.phi_p, p64, theta, phi);
  smp.f.theta_p = vec3(smp.theta_p);
  smp.f.phi_p = vec3(smp.phi_p);
  smp.f.p = vec3(p64);
  // The plate's Mueller matrix at this sample's angle, M(theta) = R(-theta) M0 R(theta), in float64
  // (plate.glsl), and in float32 for the pixels' effective weights.
  smp.m = mat4(1.0f);
  smp.m0 = dvec4(1.0lf, 0.0lf, 0.0lf, 0.0lf);
  if (PLATE) {
    const double th = plate_angle[sid];
    const double c = pisco_cos(2.0lf * th), s = pisco_sin(2.0lf * th);
    const uint o = pc.plate_offset64;
    dvec4 m0, m1, m2, m3;
    plate_rows(plate_row(o, 0), plate_row(o, 1), plate_row(o, 2), plate_row(o, 3), c, s, m0, m1, m2, m3);
    smp.m = plate_matrix(vec4(m0), vec4(m1), vec4(m2), vec4(m3));
    smp.m0 = dvec4(m0.x, m1.x, m2.x, m3.x);
  }
  smp.f.e_c = pc.cos_zeta * smp.f.theta_p + pc.sin_zeta * smp.f.phi_p;
  // The disc: for_each_disc_range of src/kernel/disc.hpp, with the polar caps as whole rings.
  const double z0 = pisco_cos(theta);
  const double xa = 1.0lf / sqrt((1.0lf - z0) * (1.0lf + z0));
  int first_ring, last_ring, irmin, irmax;
  disc_rings(nside, theta, pc.rho_max, first_ring, last_ring, irmin, irmax);
  // One pixel loop for every range of the disc (a single copy of the pixel code): ring iz's first
  // range, then its second (zero length when absent).
  for (int iz = first_ring + part; iz <= last_ring; iz += PARTS) {
    const RingEntry ring = ring_entry(iz);
    uint b0, l0, b1, l1;
    if (iz < irmin || iz > irmax) {
      b0 = ring.first;
      l0 = ring.count;
      b1 = 0u;
      l1 = 0u;
    } else {
      ring_ranges(ring, z0, xa, phi, pc.cos_rho_max, b0, l0, b1, l1);
    }
    count += l0 + l1;
    accumulate(smp, b0, l0, b1, l1, acc);
  }
#endif
}

// float64 (float-float) sums: a + b.
#if PISCO_FF
PISCO_FN vec2 f64_add(vec2 a, vec2 b) { return ff_add(a, b); }
#else
PISCO_FN double f64_add(double a, double b) { return a + b; }
#endif

// The sample's compensated float32 sum, as a float64 number: sum - comp.
PISCO_FN PISCO_F64 float_part(Sums acc) {
#if PISCO_FF
  return ff_two_sum(acc.sum, -acc.comp);
#else
  return double(acc.sum) - double(acc.comp);
#endif
}

// The sample's TOD value from its float32 part d (float_part, summed over the parts of its disc) and
// its float64 sums.
PISCO_FN PISCO_F64 sample_value(PISCO_F64 d, PISCO_F64 s0, PISCO_F64 n0) {
  const bool per_sample = (pc.flags & PISCO_FLAG_PER_SAMPLE) != 0u;
#if PISCO_FF
  const vec2 v = ff_add(d, ff_mul(pc.monopole, s0));
  return per_sample ? (n0.x > 0.0f ? ff_div(v, n0) : vec2(0.0f, 0.0f)) : v;
#else
  return finish_sample(d, pc.monopole, s0, n0, per_sample);
#endif
}

#endif
