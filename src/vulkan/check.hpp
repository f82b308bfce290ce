// Every Vulkan return code is checked: a failure throws pisco::Error naming the call and the result.
#pragma once

#include <volk.h>

#include <string>

#include "pisco/error.hpp"

namespace pisco::detail::vk {

const char* result_name(VkResult r);

// Thrown for VK_ERROR_OUT_OF_DEVICE_MEMORY / OUT_OF_HOST_MEMORY, so that callers can retry smaller.
struct OutOfMemory : Error {
  using Error::Error;
};

[[noreturn]] void fail(VkResult r, const char* call);

inline void check(VkResult r, const char* call) {
  if (r != VK_SUCCESS) fail(r, call);
}

}  // namespace pisco::detail::vk

#define PISCO_VK(call) ::pisco::detail::vk::check((call), #call)
