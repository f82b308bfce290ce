// Fuzz target: CSV focal-plane tables (docs/config.md, "[focal_plane]"); the body is fuzz_focal_plane.hpp's.
#include <cstddef>
#include <cstdint>

#include "fuzz_focal_plane.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return pisco_fuzz::read_focal_plane(data, size, "focal_plane.csv");
}
