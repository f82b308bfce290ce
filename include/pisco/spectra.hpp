// Sky synthesis from a C_l table and power spectra through HEALPix C++ (docs/physics.md,
// "Map-making and spectra").
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
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
// The beam window of a circularly symmetric profile b(theta) (paper 7.1.4: the mean radial profile
// of the focal plane's beams): b_l = int b P_l(cos theta) sin theta dtheta / int b sin theta dtheta
// over [0, theta_max], by the composite Simpson rule on `steps` intervals (even; the profile must be
// resolved by theta_max / steps). Throws pisco::Error for theta_max outside (0, pi], a profile with no
// positive integral, or a non-finite value.
std::vector<double> radial_beam_window(const std::function<double(double)>& profile, double theta_max, int lmax,
                                       int steps = 20000);
// The azimuthal mean of the elliptical Gaussian exp(-(u^2/2 s_x^2 + v^2/2 s_y^2)) at radius theta:
// exp(-theta^2 (a + b)/2) I0(theta^2 (a - b)/2), a = 1/2 s_x^2, b = 1/2 s_y^2 (s = FWHM / sqrt(8 ln 2)).
double elliptical_gaussian_radial_profile(double fwhm_x, double fwhm_y, double theta);
// HEALPix pixel window of `nside` from healpy-data (temperature or polarization column).
std::vector<double> pixel_window(int nside, int lmax, bool polarization);

// Divides each spectrum by (beam window * pixel window)^2, TT by the temperature windows, EE and BB
// by the polarization ones, cross spectra by the product. Empty windows are skipped.
Spectra deconvolve_windows(const Spectra& spectra, std::span<const double> beam_t,
                           std::span<const double> beam_p, std::span<const double> pix_t,
                           std::span<const double> pix_p);

// D_l = l (l + 1) C_l / 2 pi.
std::vector<double> to_dl(std::span<const double> cl);

// For the writers of spectra: throws pisco::Error "<where>: <spectrum> at l = <l> is <value>; ..." on
// the first value of l in [lmin, lmax] that is not finite (lmax -1: the spectra's own lmax).
void check_finite(const Spectra& spectra, const std::string& where, int lmin = 0, int lmax = -1);

}  // namespace pisco
