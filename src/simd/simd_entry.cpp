// The simd backend's entry (core/backend.hpp): its settings, on every build; its probe and create
// where it is built (simd_backend.cpp).
#include "core/backend.hpp"

namespace pisco::detail {

BackendEntry simd_backend_entry() {
  // Above the float64 reference and vulkan on a CPU device (lavapipe), below a GPU: BENCHMARKS.md.
  BackendEntry e{.name = "simd",
                 .priority = 5,
                 .settings = {threads_setting(),
                              // its device: the instruction set (docs/simd.md)
                              {"device", "an instruction set (\"AVX3\", \"AVX2\", \"SSE4\", \"NEON\", ...) or \"auto\""}}};
#ifdef PISCO_HAVE_SIMD
  attach_simd_backend(e);
#else
  mark_not_built(e, "Google's Highway (Debian: libhwy-dev)");
#endif
  return e;
}

}  // namespace pisco::detail
