// The convolution kernel (docs/vulkan.md, "The kernel"): one invocation per sample, walking its disc ring by ring
// as the float64 reference does (src/core/cpu_backend.cpp). Large discs are split: PARTS invocations of one workgroup take every PARTS-th ring of the sample
// and add their sums in shared memory (lavapipe also stops any invocation after 65,535 loop
// iterations in all, so a disc of more pixels must be split there).
// Neighbouring invocations hold neighbouring samples of the scan, whose discs overlap: their rings
// have nearly the same length (little divergence) and their pixels are the same cache lines.
// Each pixel goes through the float32 contribution (contribution.glsl); a float64 path adds the sky's
// monopole, I0 sum_k w_I(k), and the per-sample normalization when asked for.
#version 460
#extension GL_GOOGLE_include_directive : require

#include "interface.h"

layout(local_size_x = PISCO_WG_SIZE) in;

// Specialization constants, so that each pipeline holds only the code it runs (a branch on a push
// constant still costs its code's registers, and on lavapipe most of its time).
layout(constant_id = PISCO_SPEC_RADIAL) const bool RADIAL = false;    // weights as a radial profile
layout(constant_id = PISCO_SPEC_FLOAT64) const bool FLOAT64 = false;  // the float64 path
layout(constant_id = PISCO_SPEC_PARTS) const int PARTS = 1;           // invocations per sample
layout(constant_id = PISCO_SPEC_COLUMNS) const int COLUMNS = 4;       // weights stored per node: 2 or 4
layout(constant_id = PISCO_SPEC_PLATE) const bool PLATE = false;      // a half-wave plate at the aperture

shared float s_sum[PISCO_WG_SIZE], s_comp[PISCO_WG_SIZE];
shared double s_s0[PISCO_WG_SIZE], s_n0[PISCO_WG_SIZE];
shared uint s_count[PISCO_WG_SIZE];

struct RingEntry {
  double z;
  uint first;
  uint count;
  bool shifted;
};

// Texels fetched as integers, so that no conversion can touch the float32 and float64 bits they carry.
layout(binding = PISCO_BINDING_SKY) uniform usamplerBuffer sky;
layout(binding = PISCO_BINDING_SKY_LO) uniform usamplerBuffer sky_lo;
layout(binding = PISCO_BINDING_RINGS) uniform usamplerBuffer rings;
layout(binding = PISCO_BINDING_WEIGHTS) uniform usamplerBuffer weight_pairs;
layout(binding = PISCO_BINDING_WEIGHTS64) uniform usamplerBuffer weights64;
layout(std430, binding = PISCO_BINDING_POINTING) readonly buffer PointingBuffer { double pointing[]; };
layout(std430, binding = PISCO_BINDING_TOD) writeonly buffer TodBuffer { double tod[]; };
layout(std430, binding = PISCO_BINDING_COUNT) writeonly buffer CountBuffer { uint counts[]; };
layout(std430, binding = PISCO_BINDING_PLATE) readonly buffer PlateBuffer { double plate_angle[]; };

#include "contribution.glsl"
#include "disc.glsl"
#include "frame.glsl"

// The running sums of one sample: Kahan-compensated float32, float64 monopole weight and norm.
struct Sums {
  float sum, comp;
  double s0, n0;
};

// The pixels [b0, b0 + l0) then [b1, b1 + l1), in one loop.
// With PLATE, `m` is M(theta) with m[j] its column j (w * m = w M), and `m0` M(theta)'s column 0 in
// float64, for the monopole's weight sum_a w_a M_a0.
void accumulate(SampleFrame f, Grid g, dvec3 theta_p64, dvec3 phi_p64, uint b0, uint l0, uint b1, uint l1, mat4 m,
                dvec4 m0, inout Sums acc) {
  const uint jump = b1 - (b0 + l0);  // from the end of the first range to the start of the second
  for (uint q = 0u; q < l0 + l1; ++q) {
    const uint p = b0 + q + (q >= l0 ? jump : 0u);
    const vec4 a = uintBitsToFloat(texelFetch(sky, int(2u * p)));
    const vec4 b = uintBitsToFloat(texelFetch(sky, int(2u * p + 1u)));
    vec3 xyz;
    float r2, cos2chi, sin2chi;
    pixel_geometry(f, a.xyz, xyz, r2, cos2chi, sin2chi);
    // On the float64 path the beam coordinates come from the float64 pixel vectors, as the cuda
    // kernel takes them (docs/vulkan.md, "Precision"): the float32 weights are interpolated there too.
    double x64 = 0.0lf, y64 = 0.0lf;
    if (FLOAT64) {
      const dvec3 k = dvec3(a.xyz) + dvec3(uintBitsToFloat(texelFetch(sky_lo, int(p)).xyz));
      x64 = dot(k, theta_p64);
      y64 = dot(k, phi_p64);
      xyz.xy = vec2(float(x64), float(y64));
    }
    vec4 w = RADIAL ? interpolate_radial(g, r2) : interpolate_weights(g, xyz.x, xyz.y);
    if (PLATE) w = w * m;  // the effective weights w M(theta)
    precise const float y = stokes_response(w, cos2chi, sin2chi, vec4(a.w, b.xyz)) - acc.comp;
    precise const float t = acc.sum + y;
    acc.comp = (t - acc.sum) - y;
    acc.sum = t;
    if (FLOAT64) {
      const Stencil64 st = stencil64(g, x64, y64);
      if (PLATE) {
        dvec4 w64 = dvec4(0.0lf);
        double n64 = 0.0lf;
        for (int q = 0; q < st.m; ++q) {
          w64 += st.c[q] * plate_weight64(st.k[q]);
          n64 += st.c[q] * plate_norm_at(st.k[q]);
        }
        acc.s0 += dot(w64, m0);
        acc.n0 += n64;
      } else {
        dvec2 w64 = dvec2(0.0lf);
        for (int q = 0; q < st.m; ++q) w64 += st.c[q] * weight64(st.k[q]);
        acc.s0 += w64.x;
        acc.n0 += w64.y;
      }
    }
  }
}

void main() {
  const uint local = gl_LocalInvocationID.x;
  const uint sid = (gl_WorkGroupID.y * pc.groups_x + gl_WorkGroupID.x) * (PISCO_WG_SIZE / PARTS) + local / PARTS;
  const int part = int(local) % PARTS;
  const bool live = sid < pc.sample_count;
  if (PARTS == 1 && !live) return;

  Sums acc = Sums(0.0, 0.0, 0.0lf, 0.0lf);
  uint count = 0u;
  if (live) {
    // The detector's antenna basis and line of sight in float64 (frame.glsl): from the boresight's
    // angles or quaternion, with the detector's offset applied.
    const dvec4 b = dvec4(pointing[4u * sid], pointing[4u * sid + 1u], pointing[4u * sid + 2u], pointing[4u * sid + 3u]);
    const dvec4 offset_quat = dvec4(pc.offset_quat[0], pc.offset_quat[1], pc.offset_quat[2], pc.offset_quat[3]);
    dvec3 theta_p64, phi_p64, p64;
    double theta, phi;
    pisco_sample_frame((pc.flags & PISCO_FLAG_QUATERNION) != 0u, (pc.flags & PISCO_FLAG_OFFSET) != 0u, b, offset_quat,
                       theta_p64, phi_p64, p64, theta, phi);
    const double ct = pisco_cos(theta);
    // Push constants read once, outside the pixel loops (lavapipe would read them again per lane
    // and per pixel).
    Grid g;
    g.offset = int(pc.grid_offset);
    g.offset64 = pc.grid_offset64;
    g.n = int(pc.grid_n);
    g.a = pc.grid_a32;
    g.inv_step = pc.grid_inv_step32;
    g.a64 = pc.grid_a;
    g.inv_step64 = pc.grid_inv_step;
    const double cos_rho_max = pc.cos_rho_max;
    // The plate's Mueller matrix at this sample's angle, in float64: M(theta) = R(-theta) M0 R(theta).
    mat4 m = mat4(1.0);
    dvec4 m0 = dvec4(1.0lf, 0.0lf, 0.0lf, 0.0lf);
    if (PLATE) {
      const double th = plate_angle[sid];
      const double c = pisco_cos(2.0lf * th), s = pisco_sin(2.0lf * th);
      dmat4 mt;  // mt[j][i] = M_ij (column-major)
      plate_mueller(pc.plate_offset64, c, s, mt);
      m = mat4(mt);
      m0 = mt[0];
    }
    SampleFrame f;  // the float32 frame: the float64 one, rounded
    f.theta_p = vec3(theta_p64);
    f.phi_p = vec3(phi_p64);
    f.p = vec3(p64);
    f.e_c = pc.cos_zeta * f.theta_p + pc.sin_zeta * f.phi_p;

    // The disc: for_each_disc_range of src/core/disc.hpp, with the polar caps as whole rings.
    const int nside = int(pc.nside);
    const int nrings = 4 * nside - 1;
    const double z0 = ct;
    const double xa = 1.0lf / sqrt((1.0lf - z0) * (1.0lf + z0));
    const double rlat1 = theta - pc.rho_max;
    int irmin = ring_above(nside, pisco_cos(rlat1)) + 1;
    const bool north_cap = rlat1 <= 0.0lf && irmin > 1;  // every ring north of irmin entirely
    const double rlat2 = theta + pc.rho_max;
    int irmax = ring_above(nside, pisco_cos(rlat2));
    if (irmax > nrings) irmax = nrings;
    if (irmin < 1) irmin = 1;
    const bool south_cap = rlat2 >= PISCO_PI && irmax + 1 < 4 * nside;  // every ring south of irmax
    const int first_ring = north_cap ? 1 : irmin;
    const int last_ring = south_cap ? nrings : irmax;
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
        ring_ranges(ring, z0, xa, phi, cos_rho_max, b0, l0, b1, l1);
      }
      count += l0 + l1;
      accumulate(f, g, theta_p64, phi_p64, b0, l0, b1, l1, m, m0, acc);
    }
  }

  double d = double(acc.sum) - double(acc.comp);
  if (PARTS > 1) {  // the parts of a sample are neighbours in the workgroup: add them in order
    s_sum[local] = acc.sum;
    s_comp[local] = acc.comp;
    s_s0[local] = acc.s0;
    s_n0[local] = acc.n0;
    s_count[local] = count;
    barrier();
    if (part != 0 || !live) return;
    for (uint q = 1u; q < uint(PARTS); ++q) {
      d += double(s_sum[local + q]) - double(s_comp[local + q]);
      acc.s0 += s_s0[local + q];
      acc.n0 += s_n0[local + q];
      count += s_count[local + q];
    }
  }
  d += pc.monopole * acc.s0;
  if ((pc.flags & PISCO_FLAG_PER_SAMPLE) != 0u) d = acc.n0 > 0.0lf ? d / acc.n0 : 0.0lf;
  tod[sid] = d;
  counts[sid] = count;
}
