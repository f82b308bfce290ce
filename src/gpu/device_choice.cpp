#include "gpu/device_choice.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>

#include "pisco/error.hpp"

namespace pisco::detail {
namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string describe(const DeviceCandidate& d) { return d.description.empty() ? d.name : d.description; }

std::string listing(const std::string& kind, const std::vector<DeviceCandidate>& devices) {
  std::string s = kind + " devices:";
  for (std::size_t i = 0; i < devices.size(); ++i)
    s += (i ? "; " : " ") + std::to_string(i) + ": " + describe(devices[i]) +
         (devices[i].unusable.empty() ? "" : " (" + devices[i].unusable + ")");
  return s;
}

}  // namespace

std::size_t choose_device(const std::string& backend, const std::string& kind,
                          const std::vector<DeviceCandidate>& devices, const std::string& request) {
  if (devices.empty())
    throw Error(backend + ": device '" + request + "' requested, but no " + kind + " devices are present", ErrorKind::unavailable);
  const std::string list = listing(kind, devices);
  std::size_t pick = devices.size();
  if (request.empty() || request == "auto") {
    for (std::size_t i = 0; i < devices.size(); ++i)
      if (devices[i].unusable.empty() && (pick == devices.size() || devices[i].rank > devices[pick].rank))
        pick = i;
    if (pick == devices.size()) throw Error(backend + ": no usable device; " + list, ErrorKind::unavailable);
    return pick;
  }
  if (std::all_of(request.begin(), request.end(), [](unsigned char c) { return std::isdigit(c); })) {
    unsigned long long index = 0;
    const auto [end, ec] = std::from_chars(request.data(), request.data() + request.size(), index);
    if (ec != std::errc() || end != request.data() + request.size() || index >= devices.size())
      throw Error(backend + ": device index " + request + " is out of range; " + list);
    pick = static_cast<std::size_t>(index);
  } else {
    const std::string needle = lower(request);
    for (std::size_t i = 0; i < devices.size() && pick == devices.size(); ++i)
      if (lower(devices[i].name).find(needle) != std::string::npos) pick = i;
    if (pick == devices.size()) throw Error(backend + ": no device named '" + request + "'; " + list);
  }
  if (!devices[pick].unusable.empty())
    throw Error(backend + ": device '" + request + "' (" + describe(devices[pick]) + ") " + devices[pick].unusable, ErrorKind::unavailable);
  return pick;
}

}  // namespace pisco::detail
