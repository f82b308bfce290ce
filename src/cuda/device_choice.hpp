// Device choice from the "device" setting for the cuda backend, apart from the runtime so that it is
// testable anywhere: the rule of gpu/device_choice.hpp with every device usable and of equal rank,
// so "auto" (or empty) is device 0. Throws pisco::Error naming the request and the devices present.
#pragma once

#include <string>
#include <vector>

namespace pisco::detail::cuda {

int choose_device(const std::vector<std::string>& names, const std::string& request);

}  // namespace pisco::detail::cuda
