// The convolution kernel (docs/vulkan.md, "The kernel"): one invocation per sample, running
// convolve_sample (kernel.glsl). Large discs are split: PARTS invocations of one workgroup take every
// PARTS-th ring of the sample and add their sums in shared memory (lavapipe also stops any invocation
// after 65,535 loop iterations in all, so a disc of more pixels must be split there).
// Neighbouring invocations hold neighbouring samples of the scan, whose discs overlap: their rings
// have nearly the same length (little divergence) and their pixels are the same cache lines.
// Built twice: with float64 (shaderFloat64), and with PISCO_FF=1 for devices without it, where every
// float64 number the host exchanges with the kernel is a float-float pair (hi, lo) in the same 8 bytes
// (docs/vulkan.md, "Devices without float64").
#version 460
#extension GL_GOOGLE_include_directive : require

#ifndef PISCO_FF
#define PISCO_FF 0
#endif
#if PISCO_FF
#define PISCO_F64 vec2
#else
#define PISCO_F64 double
#endif

#include "interface.h"

layout(local_size_x = PISCO_WG_SIZE) in;

// Specialization constants, so that each pipeline holds only the code it runs (a branch on a push
// constant still costs its code's registers, and on lavapipe most of its time).
layout(constant_id = PISCO_SPEC_RADIAL) const bool RADIAL = false;    // weights as a radial profile
layout(constant_id = PISCO_SPEC_FLOAT64) const bool FLOAT64 = false;  // the float64 path
layout(constant_id = PISCO_SPEC_PARTS) const int PARTS = 1;           // invocations per sample
layout(constant_id = PISCO_SPEC_COLUMNS) const int COLUMNS = 4;       // weights stored per node: 2 or 4
layout(constant_id = PISCO_SPEC_PLATE) const bool PLATE = false;      // a half-wave plate at the aperture
// The sky's first pixel in the sky tables: 0 for the sky, the band's first for its polar copy.
layout(constant_id = PISCO_SPEC_SKY_FIRST) const uint SKY_FIRST = 0u;

shared PISCO_F64 s_d[PISCO_WG_SIZE], s_s0[PISCO_WG_SIZE], s_n0[PISCO_WG_SIZE];
shared uint s_count[PISCO_WG_SIZE];

// Texels fetched as integers, so that no conversion can touch the float32 and float64 bits they carry.
layout(binding = PISCO_BINDING_SKY) uniform usamplerBuffer sky;
layout(binding = PISCO_BINDING_SKY_LO) uniform usamplerBuffer sky_lo;
layout(binding = PISCO_BINDING_RINGS) uniform usamplerBuffer rings;
layout(binding = PISCO_BINDING_WEIGHTS) uniform usamplerBuffer weight_pairs;
layout(binding = PISCO_BINDING_WEIGHTS64) uniform usamplerBuffer weights64;
layout(std430, binding = PISCO_BINDING_POINTING) readonly buffer PointingBuffer { PISCO_F64 pointing[]; };
layout(std430, binding = PISCO_BINDING_TOD) writeonly buffer TodBuffer { PISCO_F64 tod[]; };
layout(std430, binding = PISCO_BINDING_COUNT) writeonly buffer CountBuffer { uint counts[]; };
// float64: the plate's angle per sample; float-float: its (cos 2 theta, sin 2 theta).
layout(std430, binding = PISCO_BINDING_PLATE) readonly buffer PlateBuffer { PISCO_F64 plate_angle[]; };

#include "kernel.glsl"

void main() {
  const uint local = gl_LocalInvocationID.x;
  const uint sid = (gl_WorkGroupID.y * pc.groups_x + gl_WorkGroupID.x) * (PISCO_WG_SIZE / PARTS) + local / PARTS;
  const int part = int(local) % PARTS;
  const bool live = sid < pc.sample_count;
  if (PARTS == 1 && !live) return;

  Sums acc;
  uint count = 0u;
  if (live) {
    convolve_sample(sid, part, acc, count);
  } else {
    acc.sum = 0.0;
    acc.comp = 0.0;
    acc.s0 = PISCO_F64(0.0);
    acc.n0 = PISCO_F64(0.0);
  }
  PISCO_F64 d = float_part(acc);
  if (PARTS > 1) {  // the parts of a sample are neighbours in the workgroup: add them in order
    s_d[local] = d;
    s_s0[local] = acc.s0;
    s_n0[local] = acc.n0;
    s_count[local] = count;
    barrier();
    if (part != 0 || !live) return;
    for (uint q = 1u; q < uint(PARTS); ++q) {
      d = f64_add(d, s_d[local + q]);
      acc.s0 = f64_add(acc.s0, s_s0[local + q]);
      acc.n0 = f64_add(acc.n0, s_n0[local + q]);
      count += s_count[local + q];
    }
  }
  tod[sid] = sample_value(d, acc.s0, acc.n0);
  counts[sid] = count;
}
