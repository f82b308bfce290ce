// Fuzz target: TOAST focal planes (HDF5, docs/formats.md, "TOAST focal planes") through
// pisco::read_toast_focal_plane.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.hpp"
#include "pisco/focal_plane.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "focal_plane.h5");
  pisco_fuzz::expect_clean([&] { (void)pisco::read_toast_focal_plane(file, 0); });
  return 0;
}
