// Fuzz target: HDF5 pointing files (docs/formats.md, "Pointing files"), both forms, told apart as a
// simulation tells them apart: boresight quaternions (pisco::BoresightFile, with its hwp_angle) when the
// file has a dataset `boresight`, else per-detector angles (pisco::pointing_detectors and
// pisco::read_pointing_hdf5).
//
// A boresight file is read by chunks, as a simulation reads it; only the first and the last chunks are
// read here, so that a file declaring billions of samples costs no more than a small one.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz_input.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/tod_file.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  pisco_fuzz::quiet_notes();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = pisco_fuzz::write_input(data, size, "pointing.h5");
  bool boresight = false;
  pisco_fuzz::expect_clean([&] { boresight = pisco::BoresightFile::holds_boresight(file); });
  if (boresight) {
    pisco_fuzz::expect_clean([&] {
      const pisco::BoresightFile pointing(file);
      constexpr std::size_t chunk = 256;
      const std::size_t n = pointing.size();
      std::vector<pisco::Quat> quats;
      std::vector<double> angles;
      for (const std::size_t first : {std::size_t{0}, n > chunk ? n - chunk : std::size_t{0}}) {
        const std::size_t count = std::min(chunk, n - first);
        pisco_fuzz::expect_clean([&] { pointing.read(first, count, quats); });
        if (pointing.has_hwp_angle()) pisco_fuzz::expect_clean([&] { pointing.read_hwp_angle(first, count, angles); });
      }
    });
    return 0;
  }
  std::vector<std::string> detectors;
  pisco_fuzz::expect_clean([&] { detectors = pisco::pointing_detectors(file); });
  // A few detectors at most: a file of many small groups costs no more than one of four.
  for (std::size_t d = 0; d < detectors.size() && d < 4; ++d)
    pisco_fuzz::expect_clean([&] { (void)pisco::read_pointing_hdf5(file, detectors[d]); });
  return 0;
}
