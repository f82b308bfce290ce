// Fuzz target: CSV focal-plane tables (docs/config.md, "[focal_plane]") through
// pisco::read_focal_plane_file, once as a configuration with one beam and once with two (when the table
// must name each detector's beam).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_input.hpp"
#include "pisco/simulation_config.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // A file that starts with HDF5's signature is read as a TOAST table whatever its name: that format
  // has a target of its own (fuzz_focal_plane_hdf5).
  if (size >= 8 && std::memcmp(data, "\x89HDF\r\n\x1a\n", 8) == 0) return -1;
  const auto file = pisco_fuzz::write_input(data, size, "focal_plane.csv");
  static const std::vector<std::string> one_beam{"main"}, two_beams{"main", "side"};
  pisco_fuzz::expect_clean([&] {
    std::vector<pisco::DetectorHwp> hwp;
    (void)pisco::read_focal_plane_file(file, one_beam, &hwp);
  });
  pisco_fuzz::expect_clean([&] { (void)pisco::read_focal_plane_file(file, two_beams, nullptr); });
  return 0;
}
