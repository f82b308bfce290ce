// Float-float ("double-single") arithmetic for devices without float64 (docs/vulkan.md, "Devices
// without float64"): a number is the unevaluated sum hi + lo of two float32 values, kept in a vec2
// (x = hi, y = lo, |lo| <= ulp(hi) / 2), about 48 significant bits. The error-free transformations
// are Knuth's two-sum and Dekker's split product, which need no fused multiply-add; every step is
// `precise` (PISCO_PRECISE), so that no compiler contracts or reassociates what they rely on.
// Written in the common subset of GLSL and C++ (tests/test_kernel_host.cpp compiles it as C++).
#ifndef PISCO_FF_GLSL
#define PISCO_FF_GLSL

#include "common.glsl"

// a + b = s + e exactly (Knuth).
PISCO_FN vec2 ff_two_sum(float a, float b) {
  PISCO_PRECISE const float s = a + b;
  PISCO_PRECISE const float bb = s - a;
  PISCO_PRECISE const float e = (a - (s - bb)) + (b - bb);
  return vec2(s, e);
}

// a + b = s + e exactly, when |a| >= |b| or a = 0.
PISCO_FN vec2 ff_quick_two_sum(float a, float b) {
  PISCO_PRECISE const float s = a + b;
  PISCO_PRECISE const float e = b - (s - a);
  return vec2(s, e);
}

// a = hi + lo with hi and lo of 12 significant bits each (Dekker; |a| < 2^115).
PISCO_FN vec2 ff_split(float a) {
  PISCO_PRECISE const float c = 4097.0f * a;
  PISCO_PRECISE const float hi = c - (c - a);
  PISCO_PRECISE const float lo = a - hi;
  return vec2(hi, lo);
}

// a b = p + e exactly (Dekker).
PISCO_FN vec2 ff_two_prod(float a, float b) {
  PISCO_PRECISE const float p = a * b;
  const vec2 as = ff_split(a), bs = ff_split(b);
  PISCO_PRECISE const float e = ((as.x * bs.x - p) + as.x * bs.y + as.y * bs.x) + as.y * bs.y;
  return vec2(p, e);
}

PISCO_FN vec2 ff_add(vec2 a, vec2 b) {
  const vec2 s = ff_two_sum(a.x, b.x);
  const vec2 t = ff_two_sum(a.y, b.y);
  PISCO_PRECISE const float e = s.y + t.x;
  const vec2 u = ff_quick_two_sum(s.x, e);
  PISCO_PRECISE const float f = u.y + t.y;
  return ff_quick_two_sum(u.x, f);
}

PISCO_FN vec2 ff_neg(vec2 a) { return vec2(-a.x, -a.y); }

PISCO_FN vec2 ff_sub(vec2 a, vec2 b) { return ff_add(a, ff_neg(b)); }

PISCO_FN vec2 ff_mul(vec2 a, vec2 b) {
  const vec2 p = ff_two_prod(a.x, b.x);
  PISCO_PRECISE const float e = p.y + (a.x * b.y + a.y * b.x);
  return ff_quick_two_sum(p.x, e);
}

// a times a float32 number.
PISCO_FN vec2 ff_mul_f(vec2 a, float b) {
  const vec2 p = ff_two_prod(a.x, b);
  PISCO_PRECISE const float e = p.y + a.y * b;
  return ff_quick_two_sum(p.x, e);
}

PISCO_FN vec2 ff_div(vec2 a, vec2 b) {
  PISCO_PRECISE const float q1 = a.x / b.x;
  const vec2 r = ff_sub(a, ff_mul_f(b, q1));
  PISCO_PRECISE const float q2 = r.x / b.x;
  const vec2 r2 = ff_sub(r, ff_mul_f(b, q2));
  PISCO_PRECISE const float q3 = r2.x / b.x;
  return ff_add(ff_quick_two_sum(q1, q2), vec2(q3, 0.0f));
}

// sqrt(a), 0 for a <= 0: one Newton step from the float32 root.
PISCO_FN vec2 ff_sqrt(vec2 a) {
  if (!(a.x > 0.0f)) return vec2(0.0f, 0.0f);
  PISCO_PRECISE const float q = sqrt(a.x);
  const vec2 r = ff_sub(a, ff_two_prod(q, q));
  PISCO_PRECISE const float c = r.x / (2.0f * q);
  return ff_quick_two_sum(q, c);
}

PISCO_FN vec2 ff_abs(vec2 a) { return a.x < 0.0f || (a.x == 0.0f && a.y < 0.0f) ? ff_neg(a) : a; }

// a < b, a <= b.
PISCO_FN bool ff_lt(vec2 a, vec2 b) { return a.x < b.x || (a.x == b.x && a.y < b.y); }
PISCO_FN bool ff_le(vec2 a, vec2 b) { return a.x < b.x || (a.x == b.x && a.y <= b.y); }

// floor(a) as a float32 integer (|a| < 2^24).
PISCO_FN float ff_floor(vec2 a) {
  const float f = floor(a.x);
  return f == a.x ? f + floor(a.y) : f;
}

// Three-vectors of float-float numbers.
struct ff3 {
  vec2 x, y, z;
};

PISCO_FN vec2 ff_dot(ff3 a, ff3 b) {
  return ff_add(ff_add(ff_mul(a.x, b.x), ff_mul(a.y, b.y)), ff_mul(a.z, b.z));
}

// The float32 vector nearest to a.
PISCO_FN vec3 ff3_hi(ff3 a) { return vec3(a.x.x, a.y.x, a.z.x); }

// A float64 pixel vector carried as float32 k plus its residual lo (the sky tables).
PISCO_FN ff3 ff3_from_parts(vec3 k, vec3 lo) {
  ff3 r;
  r.x = ff_quick_two_sum(k.x, lo.x);
  r.y = ff_quick_two_sum(k.y, lo.y);
  r.z = ff_quick_two_sum(k.z, lo.z);
  return r;
}

#endif
