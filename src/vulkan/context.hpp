// Vulkan instance and device (docs/vulkan.md, "Loading Vulkan inside a host application"). The instance is shared by every engine of the process and
// loaded through volk; each device keeps its own function table (VolkDeviceTable), so that several
// devices, and the host application's own use of Vulkan, never share global device entry points.
// With PISCO_VK_VALIDATION=1 in the environment the Khronos validation layer is enabled (an error if
// it is not installed; PISCO_VK_VALIDATION=auto enables it only where it is), and any message it gives
// is turned into an error by the caller (Device::check_validation).
#pragma once

#include <volk.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace pisco::detail::vk {

class Instance {
 public:
  // The process's instance, created on first use and kept until the process ends. Throws pisco::Error when no Vulkan loader exists
  // or the validation layer is asked for and missing.
  static std::shared_ptr<Instance> get();
  ~Instance();
  Instance(const Instance&) = delete;
  Instance& operator=(const Instance&) = delete;

  VkInstance handle() const noexcept { return instance_; }
  bool validation() const noexcept { return messenger_ != VK_NULL_HANDLE; }
  // Validation messages since the last call.
  std::vector<std::string> take_messages();

 private:
  Instance();
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                   VkDebugUtilsMessageTypeFlagsEXT type,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data, void* self);
  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  std::mutex mutex_;
  std::vector<std::string> messages_;
};

// What the engine needs to know of a physical device, and whether it can run the kernels.
struct DeviceInfo {
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  std::uint32_t index = 0;  // in vkEnumeratePhysicalDevices order
  std::string name;
  VkPhysicalDeviceType type = VK_PHYSICAL_DEVICE_TYPE_OTHER;
  std::uint32_t api_version = 0;
  std::uint32_t queue_family = 0;
  std::uint32_t subgroup_size = 0;
  VkDeviceSize max_storage_buffer_range = 0;
  std::uint32_t max_texel_buffer_elements = 0;
  std::uint32_t max_groups_x = 0, max_groups_y = 0;
  std::uint64_t device_memory = 0;  // the largest device-local memory heap, bytes
  // shaderFloat64: the kernel's float64 work runs in float64; without it, in float-float
  // (docs/vulkan.md, "Devices without float64").
  bool float64 = false;
  // shaderInt64 and shaderBufferInt64Atomics: the adjoint's fixed-point accumulation (docs/vulkan.md,
  // "The adjoint"). Without them the device runs the forward kernels only.
  bool int64_atomics = false;
  std::string unusable;  // why the kernels cannot run on it ("" when they can)
  std::string type_name() const;
  std::string describe() const;  // "llvmpipe (...) [cpu, Vulkan 1.3, float64]"
};

std::vector<DeviceInfo> enumerate_devices(const Instance& instance);

// The device named by `selector`, by the rule of gpu/device_choice.hpp: "auto" (a usable discrete GPU
// first, then integrated, virtual and cpu devices), an index into enumerate_devices(), or a
// case-insensitive part of the device's name. Throws pisco::Error naming the selector and listing the
// devices when none fits.
DeviceInfo choose_device(const std::vector<DeviceInfo>& devices, const std::string& selector);

class Device {
 public:
  Device(std::shared_ptr<Instance> instance, DeviceInfo info);
  ~Device();
  Device(const Device&) = delete;
  Device& operator=(const Device&) = delete;

  VkDevice handle() const noexcept { return device_; }
  const VolkDeviceTable& fn() const noexcept { return table_; }
  VkQueue queue() const noexcept { return queue_; }
  const DeviceInfo& info() const noexcept { return info_; }
  const VkPhysicalDeviceMemoryProperties& memory() const noexcept { return memory_; }
  Instance& instance() const noexcept { return *instance_; }
  // Throws pisco::Error with the first validation message, if any arrived (PISCO_VK_VALIDATION=1).
  void check_validation(const std::string& where) const;

 private:
  std::shared_ptr<Instance> instance_;
  DeviceInfo info_;
  VkDevice device_ = VK_NULL_HANDLE;
  VolkDeviceTable table_{};
  VkQueue queue_ = VK_NULL_HANDLE;
  VkPhysicalDeviceMemoryProperties memory_{};
};

}  // namespace pisco::detail::vk
