#include "vulkan/context.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <utility>

#include "gpu/device_choice.hpp"
#include "vulkan/check.hpp"
#include "interface.h"

namespace pisco::detail::vk {

const char* result_name(VkResult r) {
  switch (r) {
#define PISCO_CASE(x) \
  case x:             \
    return #x;
    PISCO_CASE(VK_SUCCESS)
    PISCO_CASE(VK_NOT_READY)
    PISCO_CASE(VK_TIMEOUT)
    PISCO_CASE(VK_INCOMPLETE)
    PISCO_CASE(VK_ERROR_OUT_OF_HOST_MEMORY)
    PISCO_CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    PISCO_CASE(VK_ERROR_INITIALIZATION_FAILED)
    PISCO_CASE(VK_ERROR_DEVICE_LOST)
    PISCO_CASE(VK_ERROR_MEMORY_MAP_FAILED)
    PISCO_CASE(VK_ERROR_LAYER_NOT_PRESENT)
    PISCO_CASE(VK_ERROR_EXTENSION_NOT_PRESENT)
    PISCO_CASE(VK_ERROR_FEATURE_NOT_PRESENT)
    PISCO_CASE(VK_ERROR_INCOMPATIBLE_DRIVER)
    PISCO_CASE(VK_ERROR_TOO_MANY_OBJECTS)
    PISCO_CASE(VK_ERROR_FORMAT_NOT_SUPPORTED)
    PISCO_CASE(VK_ERROR_FRAGMENTED_POOL)
    PISCO_CASE(VK_ERROR_OUT_OF_POOL_MEMORY)
    PISCO_CASE(VK_ERROR_UNKNOWN)
#undef PISCO_CASE
    default:
      return "VkResult (unnamed)";
  }
}

void fail(VkResult r, const char* call) {
  // The function's name from the call's text: "fn.vkWaitForFences(device, ...)" -> "vkWaitForFences".
  std::string name(call);
  name = name.substr(0, name.find('('));
  if (const auto dot = name.find_last_of(".>"); dot != std::string::npos) name = name.substr(dot + 1);
  while (!name.empty() && name.back() == ' ') name.pop_back();
  const std::string what = "vulkan: " + name + " failed: " + result_name(r);
  if (r == VK_ERROR_OUT_OF_DEVICE_MEMORY || r == VK_ERROR_OUT_OF_HOST_MEMORY) throw OutOfMemory(what, ErrorKind::device);
  if (r == VK_ERROR_DEVICE_LOST)
    throw Error(what + " (the device was lost: driver reset, hang or removal)", ErrorKind::device);
  if (r == VK_ERROR_INCOMPATIBLE_DRIVER || r == VK_ERROR_INITIALIZATION_FAILED || r == VK_ERROR_EXTENSION_NOT_PRESENT ||
      r == VK_ERROR_LAYER_NOT_PRESENT)
    throw Error(what, ErrorKind::unavailable);
  throw Error(what, ErrorKind::device);
}

Faults injected_faults() {
  Faults f;
  const char* v = std::getenv("PISCO_VK_TEST_FAULT");
  if (!v) return f;
  const std::string s(v);
  try {
    if (s.rfind("oom-above:", 0) == 0) f.oom_above = std::stoull(s.substr(10));
    else if (s.rfind("lose-device-after:", 0) == 0) f.lose_device_after = std::stol(s.substr(18));
    else if (s.rfind("texels-max:", 0) == 0) f.texels_max = std::stoull(s.substr(11));
    else throw Error("");
  } catch (const std::exception&) {
    throw Error("PISCO_VK_TEST_FAULT='" + s + "': expected oom-above:BYTES, lose-device-after:N or texels-max:N");
  }
  return f;
}

namespace {

constexpr const char* validation_layer = "VK_LAYER_KHRONOS_validation";

// PISCO_VK_VALIDATION: unset or "0": off; "auto": on where the layer is installed; else: required.
enum class Validation { off, if_installed, required };
Validation validation_requested() {
  const char* v = std::getenv("PISCO_VK_VALIDATION");
  if (!v || !*v || std::strcmp(v, "0") == 0) return Validation::off;
  if (std::strcmp(v, "auto") == 0) return Validation::if_installed;
  return Validation::required;
}

void load_loader() {
  static const VkResult loaded = volkInitialize();
  if (loaded != VK_SUCCESS)
    throw Error("vulkan: the Vulkan loader (libvulkan.so.1) was not found; install it (Debian: libvulkan1, "
                "and mesa-vulkan-drivers for the lavapipe CPU device)", ErrorKind::unavailable);
}

std::mutex instance_mutex;

}  // namespace

// The instance lives as long as the process: loading and unloading the driver with each engine cost
// about 0.3 s an engine on an NVIDIA GPU, and after a few dozen cycles NVIDIA's driver (580, on an
// H200) refused every later vkCreateInstance with VK_ERROR_INCOMPATIBLE_DRIVER. Never destroyed, so
// no engine's end can race another's start; still reachable, so leak checkers do not count it.
std::shared_ptr<Instance> Instance::get() {
  std::lock_guard lock(instance_mutex);
  static std::shared_ptr<Instance>* kept = nullptr;
  if (!kept) kept = new std::shared_ptr<Instance>(new Instance());  // a throw keeps nothing: the next call retries
  return *kept;
}

Instance::Instance() {
  load_loader();
  if (volkGetInstanceVersion() < VK_API_VERSION_1_2)
    throw Error("vulkan: the Vulkan loader supports only Vulkan " +
                std::to_string(VK_API_VERSION_MAJOR(volkGetInstanceVersion())) + "." +
                std::to_string(VK_API_VERSION_MINOR(volkGetInstanceVersion())) + "; Vulkan 1.2 is required", ErrorKind::unavailable);
  const Validation mode = validation_requested();
  bool validate = false;
  std::vector<const char*> layers, extensions;
  if (mode != Validation::off) {
    std::uint32_t n = 0;
    PISCO_VK(vkEnumerateInstanceLayerProperties(&n, nullptr));
    std::vector<VkLayerProperties> props(n);
    PISCO_VK(vkEnumerateInstanceLayerProperties(&n, props.data()));
    const bool found = std::any_of(props.begin(), props.end(),
                                   [](const VkLayerProperties& p) { return std::strcmp(p.layerName, validation_layer) == 0; });
    if (!found && mode == Validation::required)
      throw Error("vulkan: PISCO_VK_VALIDATION is set but the layer VK_LAYER_KHRONOS_validation is not installed "
                  "(Debian: vulkan-validationlayers; PISCO_VK_VALIDATION=auto runs without it)", ErrorKind::unavailable);
    if (found) {
      validate = true;
      layers.push_back(validation_layer);
      extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
    }
  }
  // Devices behind the portability subset (MoltenVK) are listed too.
  std::uint32_t n = 0;
  PISCO_VK(vkEnumerateInstanceExtensionProperties(nullptr, &n, nullptr));
  std::vector<VkExtensionProperties> ext(n);
  PISCO_VK(vkEnumerateInstanceExtensionProperties(nullptr, &n, ext.data()));
  VkInstanceCreateFlags flags = 0;
  for (const auto& e : ext)
    if (std::strcmp(e.extensionName, VK_KHR_PORTABILITY_ENUMERATION_EXTENSION_NAME) == 0) {
      extensions.push_back(VK_KHR_PORTABILITY_ENUMERATION_EXTENSION_NAME);
      flags |= VK_INSTANCE_CREATE_ENUMERATE_PORTABILITY_BIT_KHR;
    }

  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "pisco";
  app.pEngineName = "pisco";
  app.apiVersion = VK_API_VERSION_1_2;
  VkInstanceCreateInfo ci{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  ci.flags = flags;
  ci.pApplicationInfo = &app;
  ci.enabledLayerCount = std::uint32_t(layers.size());
  ci.ppEnabledLayerNames = layers.data();
  ci.enabledExtensionCount = std::uint32_t(extensions.size());
  ci.ppEnabledExtensionNames = extensions.data();
  PISCO_VK(vkCreateInstance(&ci, nullptr, &instance_));
  volkLoadInstanceOnly(instance_);

  if (validate) {
    VkDebugUtilsMessengerCreateInfoEXT mi{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
    mi.messageSeverity =
        VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    mi.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                     VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    mi.pfnUserCallback = &Instance::on_message;
    mi.pUserData = this;
    PISCO_VK(vkCreateDebugUtilsMessengerEXT(instance_, &mi, nullptr, &messenger_));
  }
}

Instance::~Instance() {
  if (messenger_) vkDestroyDebugUtilsMessengerEXT(instance_, messenger_, nullptr);
  if (instance_) vkDestroyInstance(instance_, nullptr);
}

VkBool32 Instance::on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity, VkDebugUtilsMessageTypeFlagsEXT,
                              const VkDebugUtilsMessengerCallbackDataEXT* data, void* self) {
  auto* inst = static_cast<Instance*>(self);
  std::lock_guard lock(inst->mutex_);
  inst->messages_.push_back(std::string(severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT ? "error: " : "warning: ") +
                            (data && data->pMessage ? data->pMessage : "(no text)"));
  return VK_FALSE;
}

std::vector<std::string> Instance::take_messages() {
  std::lock_guard lock(mutex_);
  return std::exchange(messages_, {});
}

std::string DeviceInfo::type_name() const {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return "discrete GPU";
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return "integrated GPU";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return "virtual GPU";
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return "cpu";
    default: return "other";
  }
}

std::string DeviceInfo::describe() const {
  return name + " [" + type_name() + ", Vulkan " + std::to_string(VK_API_VERSION_MAJOR(api_version)) + "." +
         std::to_string(VK_API_VERSION_MINOR(api_version)) + ", " + (float64 ? "float64" : "float-float") + "]";
}

std::vector<DeviceInfo> enumerate_devices(const Instance& instance) {
  std::uint32_t n = 0;
  PISCO_VK(vkEnumeratePhysicalDevices(instance.handle(), &n, nullptr));
  std::vector<VkPhysicalDevice> phys(n);
  PISCO_VK(vkEnumeratePhysicalDevices(instance.handle(), &n, phys.data()));
  std::vector<DeviceInfo> out;
  for (std::uint32_t i = 0; i < n; ++i) {
    DeviceInfo d;
    d.physical = phys[i];
    d.index = i;
    VkPhysicalDeviceSubgroupProperties sub{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES};
    VkPhysicalDeviceProperties2 props{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    props.pNext = &sub;
    vkGetPhysicalDeviceProperties2(phys[i], &props);
    VkPhysicalDeviceFeatures features{};
    vkGetPhysicalDeviceFeatures(phys[i], &features);
    d.name = props.properties.deviceName;
    d.float64 = features.shaderFloat64 == VK_TRUE;
    if (props.properties.apiVersion >= VK_API_VERSION_1_2) {
      VkPhysicalDeviceVulkan12Features f12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
      VkPhysicalDeviceFeatures2 f2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
      f2.pNext = &f12;
      vkGetPhysicalDeviceFeatures2(phys[i], &f2);
      d.int64_atomics = f2.features.shaderInt64 == VK_TRUE && f12.shaderBufferInt64Atomics == VK_TRUE;
    }
    d.type = props.properties.deviceType;
    d.api_version = props.properties.apiVersion;
    d.subgroup_size = sub.subgroupSize;
    d.max_storage_buffer_range = props.properties.limits.maxStorageBufferRange;
    d.max_texel_buffer_elements = props.properties.limits.maxTexelBufferElements;
    d.max_groups_x = props.properties.limits.maxComputeWorkGroupCount[0];
    d.max_groups_y = props.properties.limits.maxComputeWorkGroupCount[1];
    VkPhysicalDeviceMemoryProperties memory{};
    vkGetPhysicalDeviceMemoryProperties(phys[i], &memory);
    for (std::uint32_t h = 0; h < memory.memoryHeapCount; ++h)
      if (memory.memoryHeaps[h].flags & VK_MEMORY_HEAP_DEVICE_LOCAL_BIT)
        d.device_memory = std::max<std::uint64_t>(d.device_memory, memory.memoryHeaps[h].size);
    std::uint32_t nq = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(phys[i], &nq, nullptr);
    std::vector<VkQueueFamilyProperties> queues(nq);
    vkGetPhysicalDeviceQueueFamilyProperties(phys[i], &nq, queues.data());
    bool compute = false;
    for (std::uint32_t q = 0; q < nq && !compute; ++q)
      if (queues[q].queueFlags & VK_QUEUE_COMPUTE_BIT) {
        d.queue_family = q;
        compute = true;
      }
    if (d.api_version < VK_API_VERSION_1_2)
      d.unusable = "supports only Vulkan " + std::to_string(VK_API_VERSION_MAJOR(d.api_version)) + "." +
                   std::to_string(VK_API_VERSION_MINOR(d.api_version)) + " (1.2 required)";
    else if (!compute)
      d.unusable = "has no compute queue";
    out.push_back(std::move(d));
  }
  return out;
}

namespace {
// The preference of `auto`: a discrete GPU, then integrated, virtual and CPU devices.
int rank(const DeviceInfo& d) {
  switch (d.type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return 4;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return 3;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return 1;
    default: return 0;
  }
}
}  // namespace

DeviceInfo choose_device(const std::vector<DeviceInfo>& devices, const std::string& selector) {
  std::vector<DeviceCandidate> candidates;
  candidates.reserve(devices.size());
  for (const auto& d : devices) candidates.push_back({d.name, d.describe(), rank(d), d.unusable});
  return devices[detail::choose_device("vulkan", "Vulkan", candidates, selector)];
}

Device::Device(std::shared_ptr<Instance> instance, DeviceInfo info) : instance_(std::move(instance)), info_(std::move(info)) {
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo qi{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  qi.queueFamilyIndex = info_.queue_family;
  qi.queueCount = 1;
  qi.pQueuePriorities = &priority;
  VkPhysicalDeviceFeatures features{};
  features.shaderFloat64 = info_.float64 ? VK_TRUE : VK_FALSE;
  features.shaderInt64 = info_.int64_atomics ? VK_TRUE : VK_FALSE;
  VkPhysicalDeviceVulkan12Features f12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
  f12.shaderBufferInt64Atomics = info_.int64_atomics ? VK_TRUE : VK_FALSE;
  VkDeviceCreateInfo ci{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  ci.pNext = &f12;
  ci.queueCreateInfoCount = 1;
  ci.pQueueCreateInfos = &qi;
  ci.pEnabledFeatures = &features;
  PISCO_VK(vkCreateDevice(info_.physical, &ci, nullptr, &device_));
  volkLoadDeviceTable(&table_, device_);
  table_.vkGetDeviceQueue(device_, info_.queue_family, 0, &queue_);
  vkGetPhysicalDeviceMemoryProperties(info_.physical, &memory_);
}

Device::~Device() {
  if (device_) {
    table_.vkDeviceWaitIdle(device_);
    table_.vkDestroyDevice(device_, nullptr);
  }
}

void Device::check_validation(const std::string& where) const {
  const std::vector<std::string> messages = instance_->take_messages();
  if (messages.empty()) return;
  std::string what = "vulkan validation layer, " + where + ": " + messages.front();
  if (messages.size() > 1) what += " (and " + std::to_string(messages.size() - 1) + " more)";
  throw Error(what);
}

}  // namespace pisco::detail::vk
