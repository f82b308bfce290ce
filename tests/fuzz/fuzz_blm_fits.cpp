// Fuzz target: harmonic beam files (healpy alm FITS, docs/beams.md, "Harmonic beams") through
// pisco::HarmonicBeam::read_fits, which also checks the coefficients it read (HarmonicBeam::check).
#include <cstddef>
#include <cstdint>

#include "fuzz_input.hpp"
#include "pisco/beam_files.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "blm.fits");
  pisco_fuzz::expect_clean([&] { (void)pisco::HarmonicBeam::read_fits(file); });
  return 0;
}
