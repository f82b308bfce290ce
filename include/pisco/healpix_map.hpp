// HEALPix helpers for maps that are not skies: binned maps, hit maps.
#pragma once

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace pisco {

struct MapColumn {
  std::string name;                 // TTYPE, e.g. I_STOKES or HITS
  std::span<const double> values;   // 12 nside^2 values, RING
};

// Writes full-sky RING maps as one HEALPix FITS binary table (the layout of Sky::write_fits, with
// POLCCONV = 'COSMO'), under a temporary name then renamed. Throws pisco::Error naming the file.
void write_healpix_map(const std::filesystem::path& file, int nside, const std::vector<MapColumn>& columns,
                       const std::string& units);

// RING index of the pixel containing (theta, phi). Throws pisco::Error on a bad nside or theta.
std::size_t ang2pix(int nside, double theta, double phi);

}  // namespace pisco
