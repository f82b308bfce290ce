// Every Vulkan return code is checked: a failure throws pisco::Error naming the call and the result.
#pragma once

#include <volk.h>

#include <cstddef>
#include <string>

#include "pisco/error.hpp"

namespace pisco::detail::vk {

const char* result_name(VkResult r);

// Thrown for VK_ERROR_OUT_OF_DEVICE_MEMORY / OUT_OF_HOST_MEMORY, so that callers can retry smaller.
struct OutOfMemory : Error {
  using Error::Error;
};

[[noreturn]] void fail(VkResult r, const char* call);

// Fault injection for the tests of the error paths, from the environment variable
// PISCO_VK_TEST_FAULT: "oom-above:BYTES" makes every streaming buffer larger than BYTES fail to
// allocate as if the device were out of memory; "lose-device-after:N" makes the device fail as lost
// once N chunks have completed; "texels-max:N" makes the device bind at most N texels in a texel
// buffer. Unset (always, outside tests): no effect.
struct Faults {
  std::size_t oom_above = 0;         // 0: none
  long lose_device_after = -1;       // -1: never
  std::size_t texels_max = 0;        // 0: the device's own limit
};
Faults injected_faults();

inline void check(VkResult r, const char* call) {
  if (r != VK_SUCCESS) fail(r, call);
}

}  // namespace pisco::detail::vk

#define PISCO_VK(call) ::pisco::detail::vk::check((call), #call)
