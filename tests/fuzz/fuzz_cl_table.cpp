// Fuzz target: C_l tables (the [sky] cl_file of a simulation: columns l TT EE BB TE as
// l(l+1) C_l / 2 pi) through pisco::read_cl_table.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.hpp"
#include "pisco/spectra.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "cls.txt");
  pisco_fuzz::expect_clean([&] { (void)pisco::read_cl_table(file, 64, false); });
  return 0;
}
