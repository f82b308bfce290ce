// The backend interface behind pisco::Engine. A backend receives the prepared inputs once and then
// turns pointing chunks into TOD. Backends register themselves in backend_registry().
#pragma once

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/prepared.hpp"
#include "pisco/engine.hpp"

namespace pisco::detail {

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  virtual std::string device() const = 0;
  // pointing has been validated and has tod.size() samples; every sample of tod must be written.
  // Returns the number of sky pixels evaluated.
  virtual std::uint64_t convolve(std::size_t detector, const PointingView& pointing,
                                 std::span<double> tod) = 0;
};

struct BackendEntry {
  std::string name;
  int priority;  // "auto" picks the available backend with the highest priority
  std::function<BackendInfo()> probe;
  std::function<std::unique_ptr<Backend>(std::shared_ptr<const EngineInputs>, const EngineOptions&)> create;
  // When set, replaces `priority` for "auto" once the backend is known to be available (the vulkan
  // backend ranks below the float64 reference when its only device is a CPU: docs/vulkan.md says why).
  std::function<int()> auto_priority = nullptr;
};

const std::vector<BackendEntry>& backend_registry();

BackendEntry cpu_backend_entry();
BackendEntry vulkan_backend_entry();  // src/vulkan/, when built with Vulkan
BackendEntry cuda_backend_entry();    // src/cuda/, when built with CUDA

}  // namespace pisco::detail
