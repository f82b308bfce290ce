#include "vulkan/pipeline.hpp"

#include <string>

#include "pisco/error.hpp"
#include "vulkan/check.hpp"

namespace pisco::detail::vk {
namespace {

VkDescriptorType descriptor_type(std::uint32_t binding) {
  return is_texel_binding(binding) ? VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
}

}  // namespace

ComputePipeline::ComputePipeline(const Device& device, std::span<const std::uint32_t> spirv, std::uint32_t bindings,
                                 std::uint32_t max_sets)
    : device_(device), bindings_(bindings) {
  if (bindings > PISCO_ADJOINT_BINDINGS) throw Error("vulkan: a kernel with " + std::to_string(bindings) + " bindings");
  const auto& fn = device.fn();
  const VkDevice dev = device.handle();
  try {
    VkShaderModuleCreateInfo mi{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
    mi.codeSize = spirv.size_bytes();
    mi.pCode = spirv.data();
    PISCO_VK(fn.vkCreateShaderModule(dev, &mi, nullptr, &module_));

    std::array<VkDescriptorSetLayoutBinding, PISCO_ADJOINT_BINDINGS> layout{};
    for (std::uint32_t b = 0; b < bindings_; ++b) {
      layout[b].binding = b;
      layout[b].descriptorType = descriptor_type(b);
      layout[b].descriptorCount = 1;
      layout[b].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
    }
    VkDescriptorSetLayoutCreateInfo li{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
    li.bindingCount = bindings_;
    li.pBindings = layout.data();
    PISCO_VK(fn.vkCreateDescriptorSetLayout(dev, &li, nullptr, &set_layout_));

    VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(PushConstants)};
    VkPipelineLayoutCreateInfo pli{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
    pli.setLayoutCount = 1;
    pli.pSetLayouts = &set_layout_;
    pli.pushConstantRangeCount = 1;
    pli.pPushConstantRanges = &range;
    PISCO_VK(fn.vkCreatePipelineLayout(dev, &pli, nullptr, &layout_));

    std::uint32_t texel = 0;
    for (std::uint32_t b = 0; b < bindings_; ++b) texel += is_texel_binding(b) ? 1 : 0;
    const std::array<VkDescriptorPoolSize, 2> sizes{{{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, (bindings_ - texel) * max_sets},
                                                     {VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, texel * max_sets}}};
    VkDescriptorPoolCreateInfo pi{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    pi.maxSets = max_sets;
    pi.poolSizeCount = std::uint32_t(sizes.size());
    pi.pPoolSizes = sizes.data();
    PISCO_VK(fn.vkCreateDescriptorPool(dev, &pi, nullptr, &pool_));
  } catch (...) {
    release();
    throw;
  }
}

ComputePipeline::~ComputePipeline() { release(); }

void ComputePipeline::release() noexcept {
  const auto& fn = device_.fn();
  const VkDevice dev = device_.handle();
  if (pool_) fn.vkDestroyDescriptorPool(dev, pool_, nullptr);
  for (auto& [spec, p] : pipelines_)
    if (p) fn.vkDestroyPipeline(dev, p, nullptr);
  pipelines_.clear();
  if (layout_) fn.vkDestroyPipelineLayout(dev, layout_, nullptr);
  if (set_layout_) fn.vkDestroyDescriptorSetLayout(dev, set_layout_, nullptr);
  if (module_) fn.vkDestroyShaderModule(dev, module_, nullptr);
  pool_ = VK_NULL_HANDLE;
  layout_ = VK_NULL_HANDLE;
  set_layout_ = VK_NULL_HANDLE;
  module_ = VK_NULL_HANDLE;
}

VkDescriptorSet ComputePipeline::make_set(std::span<const Buffer* const> buffers) {
  if (buffers.size() != bindings_) throw Error("vulkan: a descriptor set of " + std::to_string(buffers.size()) + " buffers for " + std::to_string(bindings_) + " bindings");
  const auto& fn = device_.fn();
  VkDescriptorSetAllocateInfo ai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  ai.descriptorPool = pool_;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &set_layout_;
  VkDescriptorSet set = VK_NULL_HANDLE;
  PISCO_VK(fn.vkAllocateDescriptorSets(device_.handle(), &ai, &set));
  std::array<VkDescriptorBufferInfo, PISCO_ADJOINT_BINDINGS> infos{};
  std::array<VkBufferView, PISCO_ADJOINT_BINDINGS> views{};
  std::array<VkWriteDescriptorSet, PISCO_ADJOINT_BINDINGS> writes{};
  for (std::uint32_t b = 0; b < bindings_; ++b) {
    writes[b] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    writes[b].dstSet = set;
    writes[b].dstBinding = b;
    writes[b].descriptorCount = 1;
    writes[b].descriptorType = descriptor_type(b);
    if (is_texel_binding(b)) {
      views[b] = buffers[b]->texel_view();
      writes[b].pTexelBufferView = &views[b];
    } else {
      infos[b] = {buffers[b]->handle(), 0, VK_WHOLE_SIZE};
      writes[b].pBufferInfo = &infos[b];
    }
  }
  fn.vkUpdateDescriptorSets(device_.handle(), bindings_, writes.data(), 0, nullptr);
  return set;
}

VkPipeline ComputePipeline::pipeline(const Specialization& spec) {
  if (auto it = pipelines_.find(spec); it != pipelines_.end()) return it->second;
  std::array<VkSpecializationMapEntry, std::tuple_size_v<Specialization>> entries{};
  for (std::uint32_t i = 0; i < entries.size(); ++i) entries[i] = {i, std::uint32_t(i * sizeof(std::uint32_t)), sizeof(std::uint32_t)};
  VkSpecializationInfo si{std::uint32_t(entries.size()), entries.data(), sizeof(spec), spec.data()};
  VkComputePipelineCreateInfo ci{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  ci.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  ci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  ci.stage.module = module_;
  ci.stage.pName = "main";
  ci.stage.pSpecializationInfo = &si;
  ci.layout = layout_;
  VkPipeline p = VK_NULL_HANDLE;
  PISCO_VK(device_.fn().vkCreateComputePipelines(device_.handle(), VK_NULL_HANDLE, 1, &ci, nullptr, &p));
  pipelines_[spec] = p;
  return p;
}

void ComputePipeline::record(VkCommandBuffer cmd, const Specialization& spec, VkDescriptorSet set, const PushConstants& push,
                             std::uint32_t x, std::uint32_t y) {
  const auto& fn = device_.fn();
  fn.vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline(spec));
  fn.vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout_, 0, 1, &set, 0, nullptr);
  fn.vkCmdPushConstants(cmd, layout_, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(PushConstants), &push);
  fn.vkCmdDispatch(cmd, x, y, 1);
}

}  // namespace pisco::detail::vk
