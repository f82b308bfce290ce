// The body of the two text focal-plane fuzz targets (CSV and TOML): pisco::read_focal_plane_file, once
// as a configuration with one beam and once with two (when the table must name each detector's beam).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_input.hpp"
#include "pisco/simulation_config.hpp"

namespace pisco_fuzz {

// -1 (not added to the corpus) for an input that starts with HDF5's signature: it is read as a TOAST
// table whatever its name, a format with a target of its own (fuzz_focal_plane_hdf5).
inline int read_focal_plane(const std::uint8_t* data, std::size_t size, const char* name) {
  if (size >= 8 && std::memcmp(data, "\x89HDF\r\n\x1a\n", 8) == 0) return -1;
  const auto file = write_input(data, size, name);
  static const std::vector<std::string> one_beam{"main"}, two_beams{"main", "side"};
  expect_clean([&] {
    std::vector<pisco::DetectorHwp> hwp;
    (void)pisco::read_focal_plane_file(file, one_beam, &hwp);
  });
  expect_clean([&] { (void)pisco::read_focal_plane_file(file, two_beams, nullptr); });
  return 0;
}

}  // namespace pisco_fuzz
