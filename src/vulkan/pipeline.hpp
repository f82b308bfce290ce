// The compute pipelines of one embedded SPIR-V kernel: its descriptor set layout (its bindings,
// storage and uniform texel buffers, src/kernel/interface.h), push constants, a pool of descriptor sets, and one pipeline per
// set of specialization-constant values, created when first used.
#pragma once

#include <volk.h>

#include <array>
#include <map>
#include <cstddef>
#include <cstdint>
#include <span>

#include "interface.h"
#include "vulkan/buffer.hpp"
#include "vulkan/context.hpp"

namespace pisco::detail::vk {

class ComputePipeline {
 public:
  // `bindings`: PISCO_BINDINGS for convolve.comp, PISCO_ADJOINT_BINDINGS for adjoint.comp.
  ComputePipeline(const Device& device, std::span<const std::uint32_t> spirv, std::uint32_t bindings,
                  std::uint32_t max_sets);
  ~ComputePipeline();
  ComputePipeline(const ComputePipeline&) = delete;
  ComputePipeline& operator=(const ComputePipeline&) = delete;

  // A descriptor set with buffers[b] at binding b (its texel view for a texel binding).
  VkDescriptorSet make_set(std::span<const Buffer* const> buffers);
  // Values of the kernels' specialization constants, by constant_id (booleans as 0 or 1); a kernel
  // ignores those it does not declare.
  using Specialization = std::array<std::uint32_t, 8>;
  // Creates the pipeline specialized with `spec` now rather than at its first use.
  void prepare(const Specialization& spec) { pipeline(spec); }
  // Records: bind the pipeline specialized with `spec`, bind `set`, push `push`, dispatch (x, y)
  // workgroups.
  void record(VkCommandBuffer cmd, const Specialization& spec, VkDescriptorSet set, const PushConstants& push,
              std::uint32_t x, std::uint32_t y);

 private:
  void release() noexcept;
  const Device& device_;
  std::uint32_t bindings_;
  VkShaderModule module_ = VK_NULL_HANDLE;
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout layout_ = VK_NULL_HANDLE;
  VkPipeline pipeline(const Specialization& spec);
  std::map<Specialization, VkPipeline> pipelines_;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
};

}  // namespace pisco::detail::vk
