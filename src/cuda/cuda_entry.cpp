// The cuda backend's entry (core/backend.hpp): its settings, on every build; its probe and create
// where it is built (cuda_backend.cpp).
#include "core/backend.hpp"

namespace pisco::detail {

BackendEntry cuda_backend_entry() {
  // Above vulkan and cpu: on an NVIDIA machine "auto" runs the native backend.
  BackendEntry e{.name = "cuda", .priority = 20, .settings = {device_setting(), chunk_samples_setting()}};
#ifdef PISCO_HAVE_CUDA
  attach_cuda_backend(e);
#else
  mark_not_built(e, "the CUDA toolkit (nvcc)");
#endif
  return e;
}

}  // namespace pisco::detail
