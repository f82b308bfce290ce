// The instruction sets the simd backend compiles (docs/simd.md, "Build"): included by each of its
// Highway translation units before hwy/foreach_target.h, so that every dispatch table has the same
// targets in the same order and one index (simd::Kernel::index) picks the same target in each.
// Scalable vectors cannot be members of a struct (the kernel's F): no SVE or RVV targets. SSSE3 adds
// little beside SSE4 and costs compile time.
#pragma once

#ifndef HWY_DISABLED_TARGETS
#define HWY_DISABLED_TARGETS (HWY_SSSE3 | HWY_SVE | HWY_SVE2 | HWY_SVE_256 | HWY_SVE2_128 | HWY_RVV)
#endif
