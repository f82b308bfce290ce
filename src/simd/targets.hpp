// The instruction sets the simd backend compiles (docs/simd.md, "Build"): included by each of its
// Highway translation units before hwy/foreach_target.h, so that every dispatch table has the same
// targets in the same order and one index (simd::Kernel::index) picks the same target in each.
// Scalable vectors cannot be members of a struct (the kernel's F): no SVE or RVV targets. SSSE3 adds
// little beside SSE4 and costs compile time.
#pragma once

// PISCO_SIMD_FEW_TARGETS (scripts/run-sanitizers.sh) leaves x86 with AVX2 and the baseline: the
// sanitizers' instrumentation makes each target minutes to compile, and the other x86 targets are
// checked by the plain build's tests.
#ifndef HWY_DISABLED_TARGETS
#ifdef PISCO_SIMD_FEW_TARGETS
#define HWY_DISABLED_TARGETS \
  (HWY_SSSE3 | HWY_SSE4 | HWY_AVX3 | HWY_AVX3_DL | HWY_SVE | HWY_SVE2 | HWY_SVE_256 | HWY_SVE2_128 | HWY_RVV)
#else
#define HWY_DISABLED_TARGETS (HWY_SSSE3 | HWY_SVE | HWY_SVE2 | HWY_SVE_256 | HWY_SVE2_128 | HWY_RVV)
#endif
#endif
