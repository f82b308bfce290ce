// Fuzz target: simulation files (TOML, docs/config.md) through pisco::read_simulation_file.
//
// The reader checks that the files a simulation names exist and reads one of them, the focal plane of
// [focal_plane] file. To keep this target to the one format, inputs that could name a file outside the
// private directory (a string that is an absolute path or climbs out with "..") are set aside unread:
// relative names resolve into the private directory, where no file but the input itself exists.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string_view>

#include <toml++/toml.h>

#include "fuzz_input.hpp"
#include "pisco/simulation_config.hpp"

namespace {

// Whether a string of the document could lead the reader out of the private directory.
bool leaves_directory(std::string_view s) {
  const std::filesystem::path p(s);
  if (p.has_root_path()) return true;
  for (const auto& part : p)
    if (part == "..") return true;
  return false;
}

bool names_outside_file(const toml::node& node) {
  if (const auto* table = node.as_table()) {
    for (const auto& [key, value] : *table)
      if (names_outside_file(value)) return true;
  } else if (const auto* array = node.as_array()) {
    for (const auto& value : *array)
      if (names_outside_file(value)) return true;
  } else if (const auto* text = node.as_string()) {
    return leaves_directory(text->get());
  }
  return false;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const toml::table document = toml::parse(std::string_view(reinterpret_cast<const char*>(data), size));
    // -1: left out of the corpus (libFuzzer 15 and later; 14 runs on regardless).
    if (names_outside_file(document)) return -1;
  } catch (const toml::parse_error&) {
    // Not TOML: the reader refuses it before it looks at any file name.
  }
  const auto file = pisco_fuzz::write_input(data, size, "simulation.toml");
  pisco_fuzz::expect_clean([&] { (void)pisco::read_simulation_file(file); });
  return 0;
}
