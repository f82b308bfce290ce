// Fuzz target: TICRA GRASP .cut files (docs/beams.md, "GRASP files"); the body is fuzz_grasp.hpp's.
#include <cstddef>
#include <cstdint>

#include "fuzz_grasp.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  pisco_fuzz::read_grasp(data, size, "beam.cut");
  return 0;
}
