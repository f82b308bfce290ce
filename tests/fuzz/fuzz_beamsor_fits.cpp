// Fuzz target: HEALPix beamsor files (docs/formats.md, "Beamsor files") through
// pisco::Beamsor::read_healpix_fits, which reads the cap within rho_max and resamples it onto the
// beamsor's grid (of the file's pixel size).
#include <cstddef>
#include <cstdint>

#include "fuzz_input.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/units.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "beamsor.fits");
  pisco_fuzz::expect_clean([&] { (void)pisco::Beamsor::read_healpix_fits(file, 30.0 * pisco::deg); });
  return 0;
}
