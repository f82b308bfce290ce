// Beamsors: fields of 4x4 Mueller matrices over beam directions (paper section 3), sampled on a
// regular grid in the orthographic coordinates (x, y) = (sin rho cos sigma, sin rho sin sigma) of the
// antenna basis, |x|, |y| <= sin rho_max (docs/physics.md, "Beamsors").
#pragma once

#include <array>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "pisco/beam_files.hpp"
#include "pisco/units.hpp"

namespace pisco {

// Mueller matrix indexed [row][column] with T, Q, U, V = 0, 1, 2, 3. The paper's element B_XY is
// row Y, column X: B_TQ (X = T leaking into Y = Q) is m[1][0].
using Mueller = std::array<std::array<double, 4>, 4>;
Mueller identity_mueller();

// Physical bounds on Mueller matrices (docs/physics.md, "Physical bounds on Mueller matrices"),
// held to a relative tolerance: measured or fitted matrices carry errors of about 1%; beyond that a
// matrix is a mistake (a typo, a wrong unit or scale, a transposed table).
inline constexpr double mueller_tolerance = 0.01;
enum class MuellerBounds {
  finite,    // every entry finite
  // finite, M00 > 0 and every |Mij| <= (1 + tol) M00: a Mueller matrix up to a positive scale (a
  // beam's constant matrix, BeamOptions::mueller)
  relative,
  // relative, and no more light out than in: M00 + |(M01, M02, M03)| <= 1 + tol (the transmission of
  // the most transmitted fully polarized input) and |(M10, M20, M30)| <= (1 + tol) M00 (unpolarized
  // light leaves at most fully polarized): a passive element such as a half-wave plate
  passive,
};
// Throws pisco::Error beginning with `what`, naming the entry or the bound broken and its value.
void check_mueller(const Mueller& m, const std::string& what, MuellerBounds bounds);

// Angular pattern of an in-phase cross-polar far field E_cx = kappa(sigma) E_co.
enum class CrossPolarPattern {
  uniform,     // kappa constant: the detector's polarization axis is rotated by atan(kappa)
  // kappa(rho, sigma) = kappa sin(2 sigma) q e^(1 - q), q = rho^2 / 2 s^2 (s the Gaussian width,
  // geometric mean for elliptical beams): zero on the axis and on the principal planes, largest
  // (kappa) at rho = sqrt(2) s on the diagonals, like the cross-polar lobes of reflector antennas.
  quadrupole,
};

// A far sidelobe added to a Gaussian beam's pattern (docs/beams.md, "Far sidelobes"): a ring of peak
// `level` (relative to the main beam's peak, linear) at `radius` from the axis, Gaussian in rho of
// standard deviation `width`, weighted around the axis by (1 + asymmetry cos(sigma - angle)) / (1 +
// asymmetry): uniform at asymmetry 0, a single lobe towards `angle` (from theta' towards phi') at 1.
// Spillover past the mirrors, which sees the ground and the Sun. Off while level is 0.
struct FarSidelobe {
  double level = 0.0;
  double radius = 0.0;     // radians
  double width = 0.0;      // radians
  double angle = 0.0;      // radians
  double asymmetry = 0.0;  // in [0, 1]
};

struct BeamOptions {
  double rho_max = 5 * deg;              // radians; must be in (0, pi/2)
  double grid_step = 0.0;                // radians; 0 = 1/16 of the smallest FWHM (round: 1/20)
  double cross_polar = 0.0;              // kappa: cross-polar / co-polar field amplitude ratio
  CrossPolarPattern cross_polar_pattern = CrossPolarPattern::uniform;
  // Constant Mueller matrix applied after the beam: finite, M00 > 0, every |Mij| <= (1 + 1%) M00
  // (MuellerBounds::relative).
  Mueller mueller = identity_mueller();
  SidelobeSplit split;                   // a main and an outer part (beam_files.hpp); off by default
  FarSidelobe far_sidelobe;              // Gaussian beams only; off by default
};

// Checks `options` (docs/beams.md), as every builder does: rho_max in (0, 90) deg, grid_step finite
// and not negative (0: the default step), the sidelobe split (its main part within rho_max, its taper
// within the main part, its NSIDE a power of two), cross_polar finite, the constant Mueller matrix
// (MuellerBounds::relative) and the far sidelobe. Throws pisco::Error (ErrorKind::input) keyed by the
// field it concerns (Error::key): rho_max, grid_step, split.rho_main, split.taper, split.nside,
// cross_polar, mueller, far_sidelobe.level, far_sidelobe.radius, far_sidelobe.width,
// far_sidelobe.angle or far_sidelobe.asymmetry; a simulation file names the error by its own key.
void check_beam_options(const BeamOptions& options);
// A Gaussian's FWHM (radians): positive, finite, and its half-maximum radius within rho_max. Throws
// pisco::Error keyed by `field`.
void check_beam_width(double fwhm, double rho_max, const std::string& field);

class Beamsor {
 public:
  // Function of the antenna-basis direction (rho, sigma) returning the (unnormalized) Mueller matrix.
  using Field = std::function<Mueller(double rho, double sigma)>;

  // Circular Gaussian b = exp(-rho^2 / 2 s^2), s = fwhm / sqrt(8 ln 2): B = b (x) X(kappa) M.
  // Round beams without a sigma-dependent cross-polar pattern are stored as radial profiles.
  static Beamsor gaussian(double fwhm, const BeamOptions& options = {});
  // Elliptical Gaussian with widths fwhm_x along the major-axis direction `angle` (from theta'
  // towards phi') and fwhm_y perpendicular to it.
  static Beamsor elliptical_gaussian(double fwhm_x, double fwhm_y, double angle,
                                     const BeamOptions& options = {});
  // Any field: sampled on a grid of step `grid_step` out to rho_max; Omega~ by quadrature of the
  // field's B_TT over the cap (the smallest feature of the field must be resolved by grid_step).
  // With `radial`, the field must not depend on sigma: it is stored as a radial profile in
  // r = sin(rho), sampled radial_oversampling times finer than grid_step, so that its interpolation
  // is exactly invariant under rotations about the beam axis (an ideal round beam then leaks no
  // temperature into polarization: docs/validation.md, "C").
  // With `split` (rho_main > 0), the beamsor returned is the main part, B tau within rho_main on
  // the field's grid, and holds the outer part, B (1 - tau) out to rho_max (sidelobes()).
  // Every builder checks the sampled field (docs/physics.md, "Physical bounds on Mueller matrices"):
  // every node's entries finite, the peak B_TT positive, and no entry anywhere above
  // (1 + mueller_tolerance) times the peak B_TT; pisco::Error names the beam, the entry and the node.
  static Beamsor from_field(const Field& field, double rho_max, double grid_step,
                            std::string description, double feature_scale = 0.0, bool radial = false,
                            const SidelobeSplit& split = {});
  static constexpr int radial_oversampling = 64;
  // The most grid nodes per axis any builder accepts (a 2D grid of 8192^2 nodes is 512 MiB per element).
  static constexpr int max_grid_nodes = 8192;
  // The most nodes of a radial profile: radial_oversampling per grid step over half the 2D grid's
  // width (a grid step the 2D limit accepts never needs more).
  static constexpr int max_radial_nodes = max_grid_nodes / 2 * radial_oversampling + 2;
  // The nodes of a radial profile every grid_step / radial_oversampling out to sin(rho_max) (and two
  // beyond); throws pisco::Error beginning with `who` when there would be more than max_radial_nodes.
  static int radial_nodes(double rho_max, double grid_step, const std::string& who);

  // The paper's HEALPix beamsor files: a FITS binary table of up to 16 HEALPix maps with columns
  // named B_TT, B_QT, ... (B_XY = row Y, column X; absent columns are zero), beam axis at the north
  // pole, sigma = longitude. Resampled onto the grid with HEALPix bilinear interpolation;
  // Omega~ is the pixel sum of B_TT within rho_max. grid_step 0 = 1.25 of the file's pixels.
  static Beamsor read_healpix_fits(const std::filesystem::path& file, double rho_max,
                                   double grid_step = 0.0);
  // Beams as teams hold them (docs/beams.md). Both describe the Stokes response (I_b, Q_b, U_b, V_b)
  // of a detector whose polarization axis is the beam frame's x axis, Q_b and U_b in the frame's
  // Ludwig-3 basis; the beamsor is stokes_mueller of them at every node, the frame turned by
  // options.angle. Omega~ is the cap integral of I_b within rho_max.
  // Harmonic coefficients, synthesized exactly (Wigner-d recursion in l) at every node's radius.
  static Beamsor from_harmonic(const HarmonicBeam& beam, const FileBeamOptions& options = {});
  // A GRASP far field: I_b = |co|^2 + |cx|^2, Q_b = |co|^2 - |cx|^2, U_b = 2 Re(co cx*),
  // V_b = 2 Im(co cx*) on the file's grid, interpolated onto the nodes (6-point Lagrange along each
  // grid axis; trigonometric in phi for cuts).
  static Beamsor from_grasp(const GraspBeam& beam, const FileBeamOptions& options = {});
  // The Mueller matrix of a detector's Stokes response: row T = (I, 0, 0, 0), row Q = (0, Q, U, V),
  // rows U and V those of the smallest rotation taking Q's axis onto (Q, U, V), times its length.
  // For an in-phase cross-polar field this is (1 + k^2) R(atan k), the Gaussian builders' X(kappa).
  static Mueller stokes_mueller(double i, double q, double u, double v);
  // Writes this beamsor as such a file at the given NSIDE (pixels beyond rho_max are zero). Only the
  // non-zero elements are written. Atomic (temporary name, then rename).
  void write_healpix_fits(const std::filesystem::path& file, int nside) const;

  double rho_max() const noexcept { return rho_max_; }  // a split beam's: its main part's rho_main
  // A split beam's outer part (docs/beams.md, "Sidelobes"), nullptr for others: a beamsor out to the
  // whole beam's rho_max, with the whole beam's Omega~, on a grid of step max(grid step, taper / 16).
  const Beamsor* sidelobes() const noexcept { return outer_.get(); }
  // The outer part's sky NSIDE as the split asked for it (0: let the engine choose from band_limit()).
  int sidelobe_nside() const noexcept { return outer_nside_; }
  // The outer part's band limit: the smallest l beyond which its mean radial profile's Legendre
  // coefficients stay below 1e-4 of b_0 (l up to 4096); 0 for a beam that is not split.
  int sidelobe_band_limit() const noexcept { return outer_lmax_; }
  bool is_radial() const noexcept { return radial_; }   // stored as a radial profile
  int grid_size() const noexcept { return n_; }          // nodes per axis (radial: along r)
  double grid_half_width() const noexcept { return a_; } // = sin(rho_max)
  double grid_step() const noexcept { return step_; }    // node spacing in x and y (radial: in r)
  double omega_tilde() const noexcept { return omega_; } // integral of B_TT over the cap, sr
  const std::string& description() const noexcept { return description_; }

  // Grid values of element (row, col), n*n nodes with x fastest (radial: n nodes at r = i * step);
  // empty if the element is zero.
  std::span<const double> element(int row, int col) const;
  bool has_element(int row, int col) const;

  // Bilinear (radial: linear in r) interpolation of the (unnormalized) Mueller matrix at
  // orthographic (x, y); zero outside the grid or beyond rho_max.
  Mueller at(double x, double y) const;

 private:
  Beamsor() = default;
  void sample(const Field& field);
  static Beamsor split_field(const Field& field, double rho_max, double grid_step, std::string description,
                             double feature_scale, bool radial, const SidelobeSplit& split);

  double rho_max_ = 0.0;
  bool radial_ = false;
  int n_ = 0;
  double a_ = 0.0;
  double step_ = 0.0;
  double omega_ = 0.0;
  std::string description_;
  std::array<std::vector<double>, 16> elements_;  // [row * 4 + col]
  std::shared_ptr<const Beamsor> outer_;
  int outer_nside_ = 0;
  int outer_lmax_ = 0;
  friend class BeamsorAccess;
};

// Integral of f(rho, sigma) sin(rho) over the cap rho <= rho_max: composite Gauss-Legendre in rho
// (panels no wider than feature_scale / 4) times a periodic trapezoid rule in sigma.
double cap_integral(const std::function<double(double, double)>& f, double rho_max,
                    double feature_scale, int sigma_points = 64);

}  // namespace pisco
