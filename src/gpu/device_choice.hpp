// Choosing a device from the "device" setting, one rule for the vulkan and the cuda backends (and
// `pisco-vk devices`): "auto" (or empty) takes the usable device of highest rank, the first among
// equals; a number is an index into the backend's device list; anything else picks the first device
// whose name contains it, case-insensitively. Independent of any runtime, so it is testable anywhere.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace pisco::detail {

// One device as its backend lists it; its position in the list is its index.
struct DeviceCandidate {
  std::string name;         // what a part-of-name request is matched against
  std::string description;  // what error messages list ("" = the name)
  int rank = 0;             // preference of "auto": higher first (e.g. discrete GPU over CPU)
  std::string unusable;     // why the backend cannot run on it; "" when it can
};

// The index in `devices` of the device `request` names. Throws pisco::Error, starting with
// "<backend>: ", naming the request and listing the devices ("<kind> devices: 0: ...; 1: ...") when
// none matches, the index is out of range, the list is empty, or the device named is unusable.
// `kind` names the devices in messages ("Vulkan", "CUDA").
std::size_t choose_device(const std::string& backend, const std::string& kind,
                          const std::vector<DeviceCandidate>& devices, const std::string& request);

}  // namespace pisco::detail
