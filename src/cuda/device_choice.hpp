// Device choice from EngineOptions::device, apart from the runtime so that it is testable anywhere:
// "auto" (or empty) is device 0, a number is an index, anything else the first device whose name
// contains it (case-insensitive). Throws pisco::Error naming the request and the devices present.
#pragma once

#include <string>
#include <vector>

namespace pisco::detail::cuda {

int choose_device(const std::vector<std::string>& names, const std::string& request);

}  // namespace pisco::detail::cuda
