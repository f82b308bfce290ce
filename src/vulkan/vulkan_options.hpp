// The vulkan backend's settings (docs/vulkan.md): a device, the samples of a chunk, and the kernel's
// float64 arithmetic, read from EngineOptions::settings (vulkan_entry.cpp declares them).
#pragma once

#include <cstddef>
#include <string>

#include "pisco/engine.hpp"

namespace pisco::detail::vk {

// The kernel's float64 work (frame, disc selection, monopole and normalization): float64 on devices
// with shaderFloat64, float_float (pairs of float32) on any device, or automatic: float64 where the
// device has it, float-float elsewhere.
enum class Arithmetic { automatic, float64, float_float };

// "auto", "float64" or "float-float"; throws pisco::Error (ErrorKind::input, key "arithmetic") naming
// them for any other.
Arithmetic arithmetic_from(const std::string& name);
std::string arithmetic_name(Arithmetic a);

struct VulkanOptions {
  std::string device = "auto";    // an index, part of a name, or "auto" (a discrete GPU first)
  std::size_t chunk_samples = 0;  // 0: fitted to the device's limits
  Arithmetic arithmetic = Arithmetic::automatic;
};
VulkanOptions vulkan_options(const EngineOptions& options);

}  // namespace pisco::detail::vk
