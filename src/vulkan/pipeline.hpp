// The compute pipeline of one embedded SPIR-V kernel: its descriptor set layout (PISCO_BINDINGS storage
// buffers, shaders/interface.h), push constants and a pool of descriptor sets.
#pragma once

#include <volk.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "interface.h"
#include "vulkan/context.hpp"

namespace pisco::detail::vk {

class ComputePipeline {
 public:
  ComputePipeline(const Device& device, std::span<const std::uint32_t> spirv, std::uint32_t max_sets);
  ~ComputePipeline();
  ComputePipeline(const ComputePipeline&) = delete;
  ComputePipeline& operator=(const ComputePipeline&) = delete;

  // A descriptor set with buffers[b] at binding b.
  VkDescriptorSet make_set(const std::array<VkBuffer, PISCO_BINDINGS>& buffers);
  // Records: bind the pipeline and `set`, push `push`, dispatch (x, y) workgroups.
  void record(VkCommandBuffer cmd, VkDescriptorSet set, const PushConstants& push, std::uint32_t x,
              std::uint32_t y) const;

 private:
  void release() noexcept;
  const Device& device_;
  VkShaderModule module_ = VK_NULL_HANDLE;
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout layout_ = VK_NULL_HANDLE;
  VkPipeline pipeline_ = VK_NULL_HANDLE;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
};

}  // namespace pisco::detail::vk
