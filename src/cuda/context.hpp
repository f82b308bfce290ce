// The CUDA devices of this machine: probing without crashing where there is no driver or no device,
// and opening the one the "device" setting asks for.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "pisco/engine.hpp"

namespace pisco::detail::cuda {

// The backend's line in `pisco-vk devices`: the devices found, or why there are none (the runtime's
// own message, e.g. "no CUDA-capable device is detected").
BackendInfo probe();

struct DeviceContext {
  int index = 0;
  std::string name;
  int sm_major = 0, sm_minor = 0;
  int multiprocessors = 0;
  std::size_t memory = 0;
  std::string description() const;  // "NVIDIA H100 80GB HBM3 (device 0, sm_90, 132 SMs, 79.1 GiB)"
};

// Chooses the device (see choose_device) and makes it current on the calling thread.
DeviceContext open_device(const std::string& request);

// Makes the device current on the calling thread (the engine may be driven from any thread).
void make_current(const DeviceContext& device);

}  // namespace pisco::detail::cuda
