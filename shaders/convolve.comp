// The convolution kernel (DESIGN 3, 6, 7): one workgroup per sample. Invocation 0 builds the sample's
// antenna frame and disc bounds; then, in batches of PISCO_WG_SIZE rings, each invocation turns one
// ring into pixel ranges, a subgroup scan lays the ranges end to end, and the invocations share the
// pixels evenly, each pixel through the float32 contribution (contribution.glsl). A float64 path adds
// the sky's monopole, I0 sum_k w_I(k), and the per-sample normalization when asked for.
#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require

#include "interface.h"

layout(local_size_x = PISCO_WG_SIZE) in;

struct RingEntry {
  double z;
  uint first;
  uint count;
  uint shifted;
  uint pad;
};

layout(std430, binding = PISCO_BINDING_SKY) readonly buffer SkyBuffer { vec4 sky[]; };
layout(std430, binding = PISCO_BINDING_SKY_LO) readonly buffer SkyLoBuffer { vec4 sky_lo[]; };
layout(std430, binding = PISCO_BINDING_RINGS) readonly buffer RingBuffer { RingEntry rings[]; };
layout(std430, binding = PISCO_BINDING_WEIGHTS) readonly buffer WeightBuffer { vec4 weights[]; };
layout(std430, binding = PISCO_BINDING_WEIGHTS64) readonly buffer Weight64Buffer { dvec2 weights64[]; };
layout(std430, binding = PISCO_BINDING_POINTING) readonly buffer PointingBuffer { double pointing[]; };
layout(std430, binding = PISCO_BINDING_TOD) writeonly buffer TodBuffer { double tod[]; };
layout(std430, binding = PISCO_BINDING_COUNT) writeonly buffer CountBuffer { uint counts[]; };

#include "contribution.glsl"
#include "disc.glsl"

// The sample, as invocation 0 prepared it.
shared vec3 s_theta_p, s_phi_p, s_p, s_e_c;
shared dvec3 s_theta_p64, s_phi_p64;
shared double s_z0, s_xa, s_phi0;
shared int s_irmin, s_irmax;
shared uint s_cap_begin, s_cap_len;  // a polar cap inside the disc (at most one for rho < 90 deg)
// One batch of rings: each invocation's two ranges and where they start in the batch's pixel list.
shared uint s_b0[PISCO_WG_SIZE], s_l0[PISCO_WG_SIZE], s_b1[PISCO_WG_SIZE];
shared uint s_start[PISCO_WG_SIZE + 1];
shared uint s_subgroup_total[PISCO_WG_SIZE];
shared double s_partial[3 * PISCO_WG_SIZE];

void prepare_sample(uint sid) {
  const double theta = pointing[3u * sid];
  const double phi = pointing[3u * sid + 1u];  // wrapped into [0, 2 pi) by the host
  const double psi = pointing[3u * sid + 2u];
  const double ct = pisco_cos(theta), st = pisco_sin(theta);
  const double cp = pisco_cos(phi), sp = pisco_sin(phi);
  const double cs = pisco_cos(psi), ss = pisco_sin(psi);
  const dvec3 th = dvec3(ct * cp, ct * sp, -st);
  const dvec3 ph = dvec3(-sp, cp, 0.0);
  s_theta_p64 = cs * th + ss * ph;
  s_phi_p64 = -ss * th + cs * ph;
  const SampleFrame f = make_frame(float(ct), float(st), float(cp), float(sp), float(cs), float(ss),
                                   pc.cos_zeta, pc.sin_zeta);
  s_theta_p = f.theta_p;
  s_phi_p = f.phi_p;
  s_p = f.p;
  s_e_c = f.e_c;

  // Disc bounds: for_each_disc_range of src/core/disc.hpp.
  const int nside = int(pc.nside);
  const int nrings = 4 * nside - 1;
  const double z0 = ct;
  s_z0 = z0;
  s_xa = 1.0 / sqrt((1.0 - z0) * (1.0 + z0));
  s_phi0 = phi;
  s_cap_begin = 0u;
  s_cap_len = 0u;
  const double rlat1 = theta - pc.rho_max;
  int irmin = ring_above(nside, pisco_cos(rlat1)) + 1;
  if (rlat1 <= 0.0 && irmin > 1) {  // north pole inside: every ring north of irmin entirely
    s_cap_begin = 0u;
    s_cap_len = rings[irmin - 2].first + rings[irmin - 2].count;
  }
  const double rlat2 = theta + pc.rho_max;
  int irmax = ring_above(nside, pisco_cos(rlat2));
  if (irmax > nrings) irmax = nrings;
  if (irmin < 1) irmin = 1;
  if (rlat2 >= PISCO_PI && irmax + 1 < 4 * nside) {  // south pole inside
    s_cap_begin = rings[irmax].first;
    s_cap_len = uint(12 * nside * nside) - rings[irmax].first;
  }
  s_irmin = irmin;
  s_irmax = irmax;
}

void main() {
  const uint sid = gl_WorkGroupID.x + gl_WorkGroupID.y * pc.groups_x;
  if (sid >= pc.sample_count) return;  // the whole workgroup leaves together
  const uint lid = gl_LocalInvocationID.x;
  if (lid == 0u) prepare_sample(sid);
  barrier();

  SampleFrame f;
  f.theta_p = s_theta_p;
  f.phi_p = s_phi_p;
  f.p = s_p;
  f.e_c = s_e_c;
  const dvec3 theta_p64 = s_theta_p64, phi_p64 = s_phi_p64;
  const double z0 = s_z0, xa = s_xa, phi0 = s_phi0;
  const int irmin = s_irmin, irmax = s_irmax;
  const bool radial = (pc.flags & PISCO_FLAG_RADIAL) != 0u;
  const bool float64 = (pc.flags & PISCO_FLAG_FLOAT64) != 0u;

  // Compensated (Kahan) float32 sum, float64 sums of the monopole weight and the normalization.
  precise float sum = 0.0, comp = 0.0;
  double s0 = 0.0, n0 = 0.0;
  uint total = 0u;
  const int rings_in_disc = max(irmax - irmin + 1, 0);
  const int batches = max((rings_in_disc + PISCO_WG_SIZE - 1) / PISCO_WG_SIZE, 1);
  for (int batch = 0; batch < batches; ++batch) {
    const int iz = irmin + batch * PISCO_WG_SIZE + int(lid);
    uint b0, l0, b1, l1;
    if (iz <= irmax) {
      ring_ranges(iz, z0, xa, phi0, pc.cos_rho_max, b0, l0, b1, l1);
    } else {
      b0 = 0u; l0 = 0u; b1 = 0u; l1 = 0u;
    }
    // Lay the ranges end to end: the cap first (batch 0 only), then invocation by invocation.
    const uint len = l0 + l1;
    const uint inclusive = subgroupInclusiveAdd(len);
    if (gl_SubgroupInvocationID == gl_SubgroupSize - 1u) s_subgroup_total[gl_SubgroupID] = inclusive;
    s_b0[lid] = b0;
    s_l0[lid] = l0;
    s_b1[lid] = b1;
    barrier();
    const uint cap = batch == 0 ? s_cap_len : 0u;
    uint before = cap;
    for (uint g = 0u; g < gl_SubgroupID; ++g) before += s_subgroup_total[g];
    s_start[lid] = before + inclusive - len;
    if (lid == PISCO_WG_SIZE - 1u) s_start[PISCO_WG_SIZE] = before + inclusive;
    barrier();
    const uint count = s_start[PISCO_WG_SIZE];
    total += count;

    uint owner = 0u;
    for (uint i = lid; i < count; i += PISCO_WG_SIZE) {
      uint p;
      if (i < cap) {
        p = s_cap_begin + i;
      } else {
        while (owner + 1u < PISCO_WG_SIZE && s_start[owner + 1u] <= i) ++owner;
        const uint r = i - s_start[owner];
        p = r < s_l0[owner] ? s_b0[owner] + r : s_b1[owner] + (r - s_l0[owner]);
      }
      const vec4 a = sky[2u * p];
      const vec4 b = sky[2u * p + 1u];
      vec3 xyz;
      float cos2chi, sin2chi;
      pixel_geometry(f, a.xyz, xyz, cos2chi, sin2chi);
      const vec4 w = radial ? interpolate_radial(pc.grid_offset, pc.grid_n, pc.grid_inv_step32, xyz.x, xyz.y)
                            : interpolate_weights(pc.grid_offset, pc.grid_n, pc.grid_a32, pc.grid_inv_step32,
                                                  xyz.x, xyz.y);
      const float term = stokes_response(w, cos2chi, sin2chi, vec4(a.w, b.xyz));
      const float y = term - comp;
      const float t = sum + y;
      comp = (t - sum) - y;
      sum = t;
      if (float64) {
        const dvec3 k = dvec3(a.xyz) + dvec3(sky_lo[p].xyz);
        const double x64 = dot(k, theta_p64), y64 = dot(k, phi_p64);
        const dvec2 w64 = radial ? interpolate_radial64(pc.grid_offset, pc.grid_n, pc.grid_inv_step, x64, y64)
                                 : interpolate_weights64(pc.grid_offset, pc.grid_n, pc.grid_a, pc.grid_inv_step,
                                                         x64, y64);
        s0 += w64.x;
        n0 += w64.y;
      }
    }
    barrier();  // the next batch overwrites the shared ranges
  }

  // Workgroup reduction in float64, invocation by invocation in a fixed order (deterministic, and
  // without relying on float64 subgroup arithmetic).
  s_partial[3u * lid] = double(sum) - double(comp);
  s_partial[3u * lid + 1u] = s0;
  s_partial[3u * lid + 2u] = n0;
  barrier();
  if (lid == 0u) {
    double d = 0.0, m = 0.0, n = 0.0;
    for (uint g = 0u; g < PISCO_WG_SIZE; ++g) {
      d += s_partial[3u * g];
      m += s_partial[3u * g + 1u];
      n += s_partial[3u * g + 2u];
    }
    d += pc.monopole * m;
    if ((pc.flags & PISCO_FLAG_PER_SAMPLE) != 0u) d = n > 0.0 ? d / n : 0.0;
    tod[sid] = d;
    counts[sid] = total;
  }
}
