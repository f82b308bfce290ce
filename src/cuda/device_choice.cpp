#include "cuda/device_choice.hpp"

#include "gpu/device_choice.hpp"

namespace pisco::detail::cuda {

int choose_device(const std::vector<std::string>& names, const std::string& request) {
  std::vector<DeviceCandidate> devices;
  devices.reserve(names.size());
  for (const std::string& name : names) devices.push_back({name, "", 0, ""});
  return static_cast<int>(detail::choose_device("cuda", "CUDA", devices, request));
}

}  // namespace pisco::detail::cuda
