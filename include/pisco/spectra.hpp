// Sky synthesis from a C_l table and power spectra through HEALPix C++ (docs/physics.md,
// "Map-making and spectra").
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "pisco/sky.hpp"

namespace pisco {

// Power spectra C_l (not D_l) from l = 0 to lmax.
struct Spectra {
  std::vector<double> TT, EE, BB, TE, EB, TB;
  int lmax() const noexcept { return static_cast<int>(TT.size()) - 1; }
};

// The CAMB table of Debian's healpy-data package (columns l, TT, EE, BB, TE as l(l+1)C_l/2pi, uK^2).
std::filesystem::path default_cl_file();

// Reads such a table into C_l (uK^2) up to lmax (missing l are zero). With bb_zero, BB = 0 (r = 0).
// Throws pisco::Error naming the file and line on malformed input.
Spectra read_cl_table(const std::filesystem::path& file, int lmax, bool bb_zero);

// Gaussian CMB realization (synfast equivalent through HEALPix C++), seeded; V = 0. Units uK_CMB.
Sky synthesize_sky(const Spectra& cls, int nside, std::uint64_t seed);

// anafast equivalent: auto and cross spectra of I, Q, U maps (RING, same NSIDE), map2alm with
// `iterations` Jacobi iterations. Pixels equal to UNSEEN count as zero.
Spectra anafast(std::span<const double> I, std::span<const double> Q, std::span<const double> U,
                int nside, int lmax, int iterations = 3);

// Beam and pixel windows.
std::vector<double> gaussian_beam_window(double fwhm, int lmax, bool polarization);
// HEALPix pixel window of `nside` from healpy-data (temperature or polarization column).
std::vector<double> pixel_window(int nside, int lmax, bool polarization);

// Divides each spectrum by (beam window * pixel window)^2, TT by the temperature windows, EE and BB
// by the polarization ones, cross spectra by the product. Empty windows are skipped.
Spectra deconvolve_windows(const Spectra& spectra, std::span<const double> beam_t,
                           std::span<const double> beam_p, std::span<const double> pix_t,
                           std::span<const double> pix_p);

// D_l = l (l + 1) C_l / 2 pi.
std::vector<double> to_dl(std::span<const double> cl);

}  // namespace pisco
