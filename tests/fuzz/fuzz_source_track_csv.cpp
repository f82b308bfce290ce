// Fuzz target: source track files (docs/formats.md, "Source tracks"; the [[sources]] file of a
// simulation) through pisco::SourceTrack::read_csv.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.hpp"
#include "pisco/sources.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "track.csv");
  pisco_fuzz::expect_clean([&] { (void)pisco::SourceTrack::read_csv(file, "fuzz"); });
  return 0;
}
