// The vulkan backend's entry (core/backend.hpp): its settings, on every build; its probe and create
// where it is built (vulkan_backend.cpp).
#include "core/backend.hpp"
#include "core/names.hpp"
#include "vulkan/vulkan_options.hpp"

namespace pisco::detail {

namespace vk {
namespace {
constexpr Named<Arithmetic> arithmetics[] = {
    {"auto", Arithmetic::automatic}, {"float64", Arithmetic::float64}, {"float-float", Arithmetic::float_float}};
}  // namespace

Arithmetic arithmetic_from(const std::string& name) { return from_name(arithmetics, name, "arithmetic"); }
std::string arithmetic_name(Arithmetic a) { return name_of(arithmetics, a); }

VulkanOptions vulkan_options(const EngineOptions& options) {
  return {options.text("device"), options.number("chunk_samples"),
          arithmetic_from(options.text("arithmetic"))};
}
}  // namespace vk

BackendEntry vulkan_backend_entry() {
  static const std::string arithmetic_takes = listed(vk::arithmetics);
  BackendEntry e{.name = "vulkan",
                 .priority = 10,
                 .settings = {device_setting(), chunk_samples_setting(),
                              {"arithmetic", arithmetic_takes.c_str(), false,
                               [](const EngineValue& v) { vk::arithmetic_from(std::get<std::string>(v)); }}}};
#ifdef PISCO_HAVE_VULKAN
  attach_vulkan_backend(e);
#else
  mark_not_built(e, "Vulkan's loader and headers and glslang (Debian: libvulkan-dev glslang-tools)");
#endif
  return e;
}

}  // namespace pisco::detail
