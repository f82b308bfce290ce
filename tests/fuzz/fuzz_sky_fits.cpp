// Fuzz target: HEALPix FITS sky maps (docs/formats.md, "Sky maps and output maps") through
// pisco::Sky::read_fits, with UNSEEN pixels refused (the default) and taken as zero.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.hpp"
#include "pisco/sky.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "sky.fits");
  pisco_fuzz::expect_clean([&] { (void)pisco::Sky::read_fits(file, pisco::UnseenPolicy::error); });
  pisco_fuzz::expect_clean([&] { (void)pisco::Sky::read_fits(file, pisco::UnseenPolicy::zero); });
  return 0;
}
