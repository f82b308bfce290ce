// The body of the two GRASP fuzz targets (.grd and .cut): pisco::GraspBeam::read, then each beam read
// turned into a beamsor (Beamsor::from_grasp), which checks the grid's geometry and interpolates it, on
// a small grid so that an input's cost stays that of its reading.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "fuzz_input.hpp"
#include "pisco/beam_files.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/units.hpp"

namespace pisco_fuzz {

inline void read_grasp(const std::uint8_t* data, std::size_t size, const char* name) {
  const auto file = write_input(data, size, name);
  std::vector<pisco::GraspBeam> beams;
  expect_clean([&] { beams = pisco::GraspBeam::read(file); });
  pisco::FileBeamOptions options;
  options.rho_max = 1.0 * pisco::deg;    // within the reach of the seeds' grids
  options.grid_step = 0.25 * pisco::deg;  // 9 x 9 nodes
  options.angle = 30.0 * pisco::deg;
  // Two beams at most: a file of many small field sets costs no more than one of two.
  for (std::size_t k = 0; k < beams.size() && k < 2; ++k)
    expect_clean([&] { (void)pisco::Beamsor::from_grasp(beams[k], options); });
}

}  // namespace pisco_fuzz
