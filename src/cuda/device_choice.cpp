#include "cuda/device_choice.hpp"

#include <algorithm>
#include <cctype>

#include "pisco/error.hpp"

namespace pisco::detail::cuda {
namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

std::string listing(const std::vector<std::string>& names) {
  if (names.empty()) return "no CUDA devices are present";
  std::string s = "CUDA devices present: ";
  for (std::size_t i = 0; i < names.size(); ++i) s += (i ? ", " : "") + std::to_string(i) + ": " + names[i];
  return s;
}

}  // namespace

int choose_device(const std::vector<std::string>& names, const std::string& request) {
  if (names.empty()) throw Error("cuda device '" + request + "' requested, but " + listing(names));
  if (request.empty() || request == "auto") return 0;
  if (std::all_of(request.begin(), request.end(), [](unsigned char c) { return std::isdigit(c); })) {
    if (request.size() < 10) {
      const long index = std::stol(request);
      if (index < long(names.size())) return int(index);
    }
    throw Error("cuda device index " + request + " is out of range; " + listing(names));
  }
  const std::string needle = lower(request);
  for (std::size_t i = 0; i < names.size(); ++i)
    if (lower(names[i]).find(needle) != std::string::npos) return int(i);
  throw Error("cuda device '" + request + "' matches no device name; " + listing(names));
}

}  // namespace pisco::detail::cuda
