// The adjoint kernel (docs/vulkan.md, "The adjoint"): one invocation per sample, walking the sample's
// disc as convolve.comp does (kernel.glsl, built with PISCO_ADJOINT) and adding the sample's value
// times each pixel's adjoint weights into the maps (scatter.glsl). With NORMS it computes instead
// each sample's per-sample normalization, exactly as the forward kernel does, for the host to divide
// the TOD by before the scatter. Built twice, like convolve.comp: float64 and float-float (PISCO_FF=1).
#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

#ifndef PISCO_FF
#define PISCO_FF 0
#endif
#if PISCO_FF
#define PISCO_F64 vec2
#else
#define PISCO_F64 double
#endif
#define PISCO_ADJOINT 1

#include "interface.h"

layout(local_size_x = PISCO_WG_SIZE) in;

layout(constant_id = PISCO_SPEC_RADIAL) const bool RADIAL = false;
layout(constant_id = PISCO_SPEC_FLOAT64) const bool FLOAT64 = false;
layout(constant_id = PISCO_SPEC_PARTS) const int PARTS = 1;
layout(constant_id = PISCO_SPEC_COLUMNS) const int COLUMNS = 4;
layout(constant_id = PISCO_SPEC_PLATE) const bool PLATE = false;
layout(constant_id = PISCO_SPEC_NORMS) const bool NORMS = false;      // the norm pass, not the scatter
layout(constant_id = PISCO_SPEC_SQUARES) const bool SQUARES = false;  // v g^2: the diagonal of A^T A
// The adjoint reads the sky's own tables (the pixels' positions), never a polar copy's band.
const uint SKY_FIRST = 0u;

shared PISCO_F64 s_n0[PISCO_WG_SIZE];
shared uint s_count[PISCO_WG_SIZE];

layout(binding = PISCO_BINDING_SKY) uniform usamplerBuffer sky;
layout(binding = PISCO_BINDING_SKY_LO) uniform usamplerBuffer sky_lo;
layout(binding = PISCO_BINDING_RINGS) uniform usamplerBuffer rings;
layout(binding = PISCO_BINDING_WEIGHTS) uniform usamplerBuffer weight_pairs;
layout(binding = PISCO_BINDING_WEIGHTS64) uniform usamplerBuffer weights64;
layout(std430, binding = PISCO_BINDING_POINTING) readonly buffer PointingBuffer { PISCO_F64 pointing[]; };
// NORMS: each sample's normalization (sum of its pixels' Omega_pix B_TT / Omega~).
layout(std430, binding = PISCO_BINDING_TOD) writeonly buffer NormBuffer { PISCO_F64 norms[]; };
layout(std430, binding = PISCO_BINDING_COUNT) writeonly buffer CountBuffer { uint counts[]; };
layout(std430, binding = PISCO_BINDING_PLATE) readonly buffer PlateBuffer { PISCO_F64 plate_angle[]; };
layout(std430, binding = PISCO_BINDING_MAPS) buffer MapBuffer { int64_t maps[]; };
layout(std430, binding = PISCO_BINDING_VALUES) readonly buffer ValueBuffer { PISCO_F64 values[]; };

#include "kernel.glsl"

void main() {
  const uint local = gl_LocalInvocationID.x;
  const uint sid = (gl_WorkGroupID.y * pc.groups_x + gl_WorkGroupID.x) * (PISCO_WG_SIZE / PARTS) + local / PARTS;
  const int part = int(local) % PARTS;
  const bool live = sid < pc.sample_count;
  if (PARTS == 1 && !live) return;

  Sums acc;
  acc.n0 = PISCO_F64(0.0);
  uint count = 0u;
  if (live) convolve_sample(sid, part, acc, count);
  if (PARTS > 1) {  // the parts of a sample are neighbours in the workgroup: add them in order
    s_n0[local] = acc.n0;
    s_count[local] = count;
    barrier();
    if (part != 0 || !live) return;
    for (uint q = 1u; q < uint(PARTS); ++q) {
      acc.n0 = f64_add(acc.n0, s_n0[local + q]);
      count += s_count[local + q];
    }
  }
  if (NORMS) norms[sid] = acc.n0;
  counts[sid] = count;
}
