// A Vulkan buffer with its own memory (one allocation each: the engine holds a handful of buffers).
#pragma once

#include <volk.h>

#include <cstddef>

#include "vulkan/context.hpp"

namespace pisco::detail::vk {

enum class MemoryUse {
  device,    // device-local, filled through a staging copy
  upload,    // host-visible and coherent, written by the host every chunk
  readback,  // host-visible, preferably cached, read by the host every chunk
};

class Buffer {
 public:
  Buffer() = default;
  // Throws OutOfMemory when the device or host memory is exhausted, pisco::Error otherwise.
  Buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage, MemoryUse use);
  ~Buffer();
  Buffer(Buffer&& o) noexcept;
  Buffer& operator=(Buffer&& o) noexcept;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;

  VkBuffer handle() const noexcept { return buffer_; }
  // A view of the whole buffer as texels of `format`, for uniform texel buffer bindings; owned by
  // the buffer and destroyed with it.
  void make_texel_view(VkFormat format);
  VkBufferView texel_view() const noexcept { return view_; }
  VkDeviceSize size() const noexcept { return size_; }
  void* mapped() const noexcept { return mapped_; }  // null for device memory
  bool coherent() const noexcept { return coherent_; }
  // Makes device writes visible to the host for non-coherent readback memory.
  void invalidate() const;

 private:
  void release() noexcept;
  const Device* device_ = nullptr;
  VkBuffer buffer_ = VK_NULL_HANDLE;
  VkBufferView view_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  VkDeviceSize size_ = 0;
  void* mapped_ = nullptr;
  bool coherent_ = true;
};

}  // namespace pisco::detail::vk
