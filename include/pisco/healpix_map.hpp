// HEALPix helpers shared by skies, maps, scans and files: the NSIDE the library accepts, the UNSEEN
// marker, writing maps that are not skies (binned maps, hit maps), and pixel lookup.
#pragma once

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace pisco {

// The largest NSIDE accepted anywhere in the library (skies, maps, scans, spectra, FITS files). Pixel
// geometry goes through HEALPix C++'s Healpix_Base, whose pixel indices are 32-bit ints:
// 12 NSIDE^2 = 805,306,368 pixels at NSIDE 8192, while NSIDE 16384 would need 3.2e9.
inline constexpr int max_nside = 8192;

// Whether nside is a power of two in [1, max_nside].
constexpr bool valid_nside(long long nside) noexcept {
  return nside >= 1 && nside <= max_nside && (nside & (nside - 1)) == 0;
}
// Throws pisco::Error("<where>: NSIDE = <nside> is not a power of two in [1, 8192]") unless
// valid_nside(nside). `where` names the function, file or key the value came from.
void check_nside(long long nside, const std::string& where);

// HEALPix's marker of a pixel without data (healpy's UNSEEN): unsolved pixels of binned maps.
inline constexpr double unseen = -1.6375e30;
// True for UNSEEN to within 1e-5 relative, as healpy compares it (files may round it to float32).
inline bool is_unseen(double value) noexcept {
  const double d = value - unseen;
  return (d < 0 ? -d : d) <= 1e-5 * -unseen;
}

struct MapColumn {
  std::string name;                 // TTYPE, e.g. I_STOKES or HITS
  std::span<const double> values;   // 12 nside^2 values, RING
};

// Writes full-sky RING maps as one HEALPix FITS binary table (the layout of Sky::write_fits, with
// POLCCONV = 'COSMO'), under a temporary name then renamed. Throws pisco::Error naming the file, and
// before writing anything on a value that is not finite, naming the column and the pixel (UNSEEN is
// finite, and written).
void write_healpix_map(const std::filesystem::path& file, int nside, const std::vector<MapColumn>& columns,
                       const std::string& units);

// RING index of the pixel containing (theta, phi). Throws pisco::Error on a bad nside or theta.
std::size_t ang2pix(int nside, double theta, double phi);

}  // namespace pisco
