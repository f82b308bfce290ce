// Pair mismatch metrics of the paper's section 7.1.5 (docs/physics.md, "Mismatch metrics"):
// delta = max over the beam plane of |b_a - b_b|, the difference of a PSB pair's two normalized
// beams; delta_p for the pointing mismatch alone (both beams given the pair's mean shape, each at
// its own centre), delta_b for the beam mismatch alone (each its own shape, both at the mean centre).
#pragma once

#include <functional>
#include <span>

namespace pisco {

// An elliptical Gaussian beam on the focal plane's tangent plane: exp(-(u^2 / 2 s_x^2 + v^2 / 2 s_y^2))
// with (u, v) the offset from the centre turned by `angle`, s = FWHM / sqrt(8 ln 2); the beam of
// Beamsor::elliptical_gaussian placed at the detector offset (xi, eta) of docs/config.md.
struct GaussianBeamShape {
  double fwhm_x = 0.0;  // radians, along the axis at `angle`
  double fwhm_y = 0.0;  // radians, across it
  double angle = 0.0;   // radians, of the x axis from theta' towards phi'
  double xi = 0.0;      // radians: the beam centre in focal-plane coordinates
  double eta = 0.0;
};

enum class BeamNormalization {
  // Each beam divided by its own peak: delta is a fraction of the peak (the paper's "percentage of
  // the normalized beams").
  peak,
  // Each beam divided by its integral (the weights it gives the sky), delta a fraction of the peak of
  // the pair's mean beam.
  integral,
};

struct MismatchMaximum {
  double delta = 0.0;  // max |b_a - b_b|, a fraction (0.0042 for the paper's 0.42%)
  double xi = 0.0;     // where the maximum lies, radians
  double eta = 0.0;
};

// max |b_a - b_b| over the plane, searched on a 201 x 201 grid over both beams out to 5 widths and
// refined to 1e-12 of the grid's extent around the best candidates. Throws pisco::Error for a FWHM that
// is not positive and finite, or an angle or centre that is not finite.
MismatchMaximum beam_difference_maximum(const GaussianBeamShape& a, const GaussianBeamShape& b,
                                        BeamNormalization normalization = BeamNormalization::peak);

// The pair's mean beam: FWHMs and centre averaged, the axis angle averaged as an axis (modulo 180 deg).
GaussianBeamShape mean_beam(const GaussianBeamShape& a, const GaussianBeamShape& b);

struct PairMismatch {
  double pointing = 0.0;  // delta_p: both beams the pair's mean shape, each at its own centre
  double beam = 0.0;      // delta_b: each beam its own shape, both at the pair's mean centre
  double total = 0.0;     // delta of the two beams as given
};

PairMismatch pair_mismatch(const GaussianBeamShape& a, const GaussianBeamShape& b,
                           BeamNormalization normalization = BeamNormalization::peak);

// Any two beam profiles f(xi, eta) (any normalization the caller chose; 1/peak for the paper's) over
// the square |xi - centre_xi|, |eta - centre_eta| <= half_width: the same search. The profiles must be
// smooth on the scale of half_width / 100.
MismatchMaximum profile_difference_maximum(const std::function<double(double, double)>& a,
                                           const std::function<double(double, double)>& b,
                                           double centre_xi, double centre_eta, double half_width);

}  // namespace pisco
