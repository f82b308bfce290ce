#include "vulkan/buffer.hpp"

#include <utility>

#include "vulkan/check.hpp"

namespace pisco::detail::vk {
namespace {

// The first memory type allowed by `bits` with all `want` flags, or -1.
int find_type(const VkPhysicalDeviceMemoryProperties& mem, std::uint32_t bits, VkMemoryPropertyFlags want) {
  for (std::uint32_t i = 0; i < mem.memoryTypeCount; ++i)
    if ((bits & (1u << i)) && (mem.memoryTypes[i].propertyFlags & want) == want) return int(i);
  return -1;
}

}  // namespace

Buffer::Buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage, MemoryUse use)
    : device_(&device), size_(size) {
  const auto& fn = device.fn();
  if (const Faults f = injected_faults(); use != MemoryUse::device && (usage & VK_BUFFER_USAGE_STORAGE_BUFFER_BIT) &&
      f.oom_above && size > f.oom_above)
    fail(VK_ERROR_OUT_OF_DEVICE_MEMORY, "vkAllocateMemory (PISCO_VK_TEST_FAULT)");
  VkBufferCreateInfo bi{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  bi.size = size;
  bi.usage = usage;
  bi.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  PISCO_VK(fn.vkCreateBuffer(device.handle(), &bi, nullptr, &buffer_));
  try {
    VkMemoryRequirements req;
    fn.vkGetBufferMemoryRequirements(device.handle(), buffer_, &req);
    const auto& mem = device.memory();
    int type = -1;
    switch (use) {
      case MemoryUse::device:
        type = find_type(mem, req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
        break;
      case MemoryUse::upload:
        type = find_type(mem, req.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
        break;
      case MemoryUse::readback:
        type = find_type(mem, req.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
        if (type < 0)
          type = find_type(mem, req.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
        break;
    }
    if (type < 0) throw Error("vulkan: no suitable memory type for a buffer of " + std::to_string(size) + " bytes", ErrorKind::device);
    VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = std::uint32_t(type);
    PISCO_VK(fn.vkAllocateMemory(device.handle(), &ai, nullptr, &memory_));
    PISCO_VK(fn.vkBindBufferMemory(device.handle(), buffer_, memory_, 0));
    const VkMemoryPropertyFlags flags = mem.memoryTypes[type].propertyFlags;
    coherent_ = (flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT) != 0;
    if (use != MemoryUse::device) PISCO_VK(fn.vkMapMemory(device.handle(), memory_, 0, VK_WHOLE_SIZE, 0, &mapped_));
  } catch (...) {
    release();
    throw;
  }
}

void Buffer::make_texel_view(VkFormat format) {
  VkBufferViewCreateInfo vi{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
  vi.buffer = buffer_;
  vi.format = format;
  vi.range = VK_WHOLE_SIZE;
  PISCO_VK(device_->fn().vkCreateBufferView(device_->handle(), &vi, nullptr, &view_));
}

void Buffer::invalidate() const {
  if (coherent_ || !mapped_) return;
  VkMappedMemoryRange r{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
  r.memory = memory_;
  r.offset = 0;
  r.size = VK_WHOLE_SIZE;
  PISCO_VK(device_->fn().vkInvalidateMappedMemoryRanges(device_->handle(), 1, &r));
}

void Buffer::release() noexcept {
  if (!device_) return;
  const auto& fn = device_->fn();
  if (view_) fn.vkDestroyBufferView(device_->handle(), view_, nullptr);
  if (mapped_) fn.vkUnmapMemory(device_->handle(), memory_);
  if (buffer_) fn.vkDestroyBuffer(device_->handle(), buffer_, nullptr);
  if (memory_) fn.vkFreeMemory(device_->handle(), memory_, nullptr);
  view_ = VK_NULL_HANDLE;
  buffer_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  mapped_ = nullptr;
}

Buffer::~Buffer() { release(); }

Buffer::Buffer(Buffer&& o) noexcept
    : device_(o.device_), buffer_(std::exchange(o.buffer_, VK_NULL_HANDLE)), view_(std::exchange(o.view_, VK_NULL_HANDLE)),
      memory_(std::exchange(o.memory_, VK_NULL_HANDLE)), size_(o.size_), mapped_(std::exchange(o.mapped_, nullptr)),
      coherent_(o.coherent_) {}

Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    release();
    device_ = o.device_;
    buffer_ = std::exchange(o.buffer_, VK_NULL_HANDLE);
    view_ = std::exchange(o.view_, VK_NULL_HANDLE);
    memory_ = std::exchange(o.memory_, VK_NULL_HANDLE);
    size_ = o.size_;
    mapped_ = std::exchange(o.mapped_, nullptr);
    coherent_ = o.coherent_;
  }
  return *this;
}

}  // namespace pisco::detail::vk
