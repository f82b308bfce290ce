// Beams as teams hold them (docs/beams.md): harmonic beam coefficients b_lm in healpy's layout, as
// ducc0's totalconvolve, TOAST and litebird_sim take them, and TICRA GRASP far-field files (.grd
// grids and .cut cuts). Each is turned into a Beamsor by Beamsor::from_harmonic / from_grasp.
#pragma once

#include <array>
#include <complex>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "pisco/units.hpp"

namespace pisco {

// Sidelobes at a cost that does not grow with the disc's area (docs/beams.md, "Sidelobes"): the beam
// B splits into a main part B tau, summed on the sky's own pixels within rho_main, and an outer part
// B (1 - tau), summed out to rho_max on a band-limited copy of the sky at a coarser NSIDE; tau is 1
// within rho_main - taper and falls to 0 at rho_main as a half cosine. Both parts keep the whole
// beam's Omega~, so their TODs add up to the whole beam's.
struct SidelobeSplit {
  double rho_main = 0.0;  // radians; 0: no split
  double taper = 0.0;     // radians; 0: rho_main / 4
  int nside = 0;          // the outer part's sky NSIDE; 0: from the outer part's band limit (band_limit)
};

// Where a file beam sits in the antenna basis and on which grid it is sampled.
struct FileBeamOptions {
  double rho_max = 5 * deg;  // radians, in (0, pi/2)
  double grid_step = 0.0;    // radians; 0 = the file's own resolution (docs/beams.md, "Grid")
  // The beam frame's x axis (the co-polar axis of a GRASP file, the polarization axis of a b_lm
  // beam) lies at this angle from theta' towards phi'; the whole beam turns with it. `pisco-vk run`
  // sets it to each detector's zeta, so a pair's two detectors see the same optics turned by 90 deg.
  double angle = 0.0;
  SidelobeSplit split;
  // When set, told of the progress of a build that takes more than a few seconds (a b_lm file's
  // synthesis at large lmax and mmax), a line at its start and one every few seconds.
  std::function<void(const std::string&)> progress;
};

// Checks `options` as every file beam's builder does before it reads further (check_beam_options'
// checks of rho_max, grid_step and the split, and the angle finite). Throws pisco::Error (input)
// keyed by the field: rho_max, grid_step, angle, split.rho_main, split.taper or split.nside; with a
// `source` (the beam's file), one that reads "source: field: what" instead.
void check_file_beam_options(const FileBeamOptions& options, const std::string& source = "");

// Harmonic beam coefficients, the beam axis at the north pole, sigma = longitude: T, E and B in
// healpy's layout (index m (2 lmax + 1 - m) / 2 + l for 0 <= m <= mmax <= l <= lmax), with the
// polarization convention of ducc0's totalconvolve (docs/beams.md, "Harmonic beams"): a detector of
// this beam measures the sky's T against the beam's T map, and Q and U against the beam's Q and U
// maps (healpy's alm2map of T, E, B). e and b are empty for an unpolarized beam.
struct HarmonicBeam {
  int lmax = -1;
  int mmax = -1;
  std::vector<std::complex<double>> t, e, b;
  std::string source;  // the file, or a description, for messages

  static std::size_t size(int lmax, int mmax);
  static std::size_t index(int lmax, int l, int m) {
    return static_cast<std::size_t>(m) * (2 * lmax + 1 - m) / 2 + static_cast<std::size_t>(l);
  }
  bool polarized() const { return !e.empty(); }
  // Checks sizes, 0 <= mmax <= lmax, finite values and a positive beam integral (b_00 > 0); throws
  // pisco::Error naming `source` and what was expected.
  void check() const;
  // The beam's T and, in its frame's Ludwig-3 basis, Q and U at (rho, sigma) about its axis: the
  // values Beamsor::from_harmonic samples (O(lmax mmax) a call).
  std::array<double, 3> stokes_at(double rho, double sigma) const;

  // A healpy alm FITS file (healpy.write_alm: one binary table a component with columns INDEX =
  // l^2 + l + m + 1, REAL, IMAG): one HDU (T) or three (T, E, B). Errors name the file and the HDU.
  static HarmonicBeam read_fits(const std::filesystem::path& file);
};

// A GRASP far field: the linear co- and cross-polar components (Ludwig's third definition, TICRA's
// ICOMP = 3) of one beam, on a regular grid of one of TICRA's grid types or as polar cuts.
struct GraspBeam {
  enum class Grid {
    uv,                     // IGRID 1: x = u = sin(theta) cos(phi), y = v = sin(theta) sin(phi)
    elevation_over_azimuth, // IGRID 4: x = az, y = el (degrees): u = -sin(az) cos(el), v = sin(el)
    elevation_and_azimuth,  // IGRID 5: x = az, y = el (degrees): az = -theta cos(phi), el = theta sin(phi)
    azimuth_over_elevation, // IGRID 6: x = az, y = el (degrees): u = -sin(az), v = cos(az) sin(el)
    theta_phi,              // IGRID 7: x = phi, y = theta (degrees)
    cuts,                   // a .cut file: x = phi of each cut, y = theta along it (radians)
  };
  Grid grid = Grid::uv;
  int nx = 0, ny = 0;      // x runs fastest: value (i, j) at [j * nx + i]
  double xs = 0, ys = 0, xe = 0, ye = 0;  // grid corners, radians for angle grids
  std::vector<double> x_values;           // cuts: the phi of each cut (radians), ascending
  std::vector<std::complex<double>> co, cx;
  std::string source;  // "file (beam k of n)" for messages
  double frequency = 0.0;  // from the header where it says, else 0

  // Every beam of a .grd (one per field set, NSET) or .cut file (one per frequency block) in order.
  // Errors name the file, the line and what was expected.
  static std::vector<GraspBeam> read(const std::filesystem::path& file);
};

}  // namespace pisco
