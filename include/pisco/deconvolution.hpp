// The beam-deconvolving map-maker (docs/physics.md, "Map-making with the beams"): solves
// (A^T A + lambda) s = A^T d for the sky s at the engine's NSIDE by conjugate gradients, A the
// engine's convolution with each detector's own beamsor, offset and plate (Engine::convolve) and A^T
// its adjoint (Engine::adjoint). Beam and pointing mismatch between the detectors of a pair, which a
// binned map-maker turns into spurious polarization, are then part of the model.
#pragma once

#include <chrono>
#include <cstddef>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "pisco/engine.hpp"
#include "pisco/pointing.hpp"

namespace pisco {

struct DeconvolutionOptions {
  int max_iterations = 100;
  // Stop when ||r|| <= tolerance ||A^T d||, r the residual of the normal equations.
  double tolerance = 1e-6;
  // lambda as a fraction of the Rayleigh quotient <b, A^T A b> / <b, b> of the right-hand side b =
  // A^T d (a typical eigenvalue of A^T A); 0 (the default): none, the minimum-norm solution that
  // conjugate gradients from zero converge to, pixels out of every sample's disc left at zero.
  double regularization = 0.0;
  // Which Stokes parameters lambda applies to: all (the default), or Q, U and V only
  // (polarization), which leaves the temperature to the iterations. An unpolarized sky is then the
  // exact solution of the regularized equations too, so the regularization cannot turn a pair's
  // mismatch into polarization; it shrinks real polarization instead, where the data constrain it
  // least (docs/physics.md, "Map-making with the beams").
  enum class Regularize { all, polarization };
  Regularize regularize = Regularize::all;
  // Polarization is solved only where the scan's angles constrain it: the detectors' (I, Q, U)
  // weights are binned at coverage_nside (0: the engine's NSIDE / 4) as the binned map-maker bins
  // them, and Q, U and V of the pixels in a coverage pixel whose 3x3 matrix has a reciprocal condition
  // number below rcond_min are left out of the solve (zero) and unseen in the maps (docs/physics.md,
  // "Map-making with the beams": what the solver leaves out).
  double rcond_min = 1e-3;
  int coverage_nside = 0;
  // > 0: the solution also returned reconvolved with a circular Gaussian of this FWHM (radians), by
  // harmonic smoothing (HEALPix map2alm with 3 iterations, to 3 NSIDE - 1), for analysis.
  double target_fwhm = 0.0;
  // Several processes, each with its own chunks of the survey: sums a buffer over the processes in
  // place, the same bits on each (an MPI reduction and broadcast). solve() calls it on A^T d, the
  // diagonal and every A^T A p, so that each process runs the same iterations on the whole survey's
  // normal equations. Empty: one process.
  std::function<void(std::span<double>)> reduce;
};

// One chunk of a survey as the solver replays it: a detector, its boresight pointing (angles or
// quaternions), for a detector with a half-wave plate the plate's angles, and for a beam that changes
// with time (Detector::beam_sequence) each sample's time.
struct SurveyChunk {
  std::size_t detector = 0;
  PointingView angles;
  QuatPointingView quats;
  bool quaternions = false;
  std::span<const double> hwp_angle;
  std::span<const double> time;
  std::size_t size() const noexcept { return quaternions ? quats.size() : angles.size(); }
};

struct DeconvolutionProgress {
  int iteration = 0;
  double residual = 0.0;  // ||r|| / ||A^T d||
  double seconds = 0.0;   // since solve() began
};

struct DeconvolvedMaps {
  int nside = 0;
  // The solution (RING); pisco::unseen where no sample's disc reaches the pixel.
  std::vector<double> I, Q, U, V;
  // The solution reconvolved with the target beam (DeconvolutionOptions::target_fwhm), unseen where
  // the solution is; empty without a target.
  std::vector<double> smoothed_I, smoothed_Q, smoothed_U;
  int iterations = 0;
  // Whether the residual fell to the tolerance within max_iterations (or A^T d was zero).
  bool converged = false;
  // What the data do not constrain and the solver left out, a line each for a person ("Q and U in
  // 120 of the 3072 pixels the beams reach: ..."); empty when everything the beams reach was solved.
  std::vector<std::string> left_out;
  // Pixels reached by the beams whose Q and U were solved, and whether that is none of them while the
  // beams respond to polarization (one polarization angle: the maps hold I alone).
  std::size_t polarization_pixels = 0;
  bool polarization_unconstrained = false;
  std::vector<double> residuals;  // ||r|| / ||A^T d|| after each iteration
  double seconds = 0.0, seconds_per_iteration = 0.0;
};

class DeconvolvingMapmaker {
 public:
  // Replays every chunk of the survey, in the same order each time: `visit` is called once per chunk.
  using Survey = std::function<void(const std::function<void(const SurveyChunk&)>& visit)>;

  // The engine's beams, focal plane and options define A; its sky is replaced as the solver iterates
  // (Engine::set_sky), so the engine must not be used elsewhere meanwhile, and after solve() its sky
  // is the solver's last search direction: set_sky before convolving with it again. Its backend
  // must have the adjoint (BackendCapabilities::adjoint). Memory: eight maps of 4 x npix doubles
  // beside the engine's.
  explicit DeconvolvingMapmaker(Engine& engine, const DeconvolutionOptions& options = {});

  // Adds a chunk's TOD to the right-hand side A^T d.
  void add(const SurveyChunk& chunk, std::span<const double> tod);

  // Conjugate gradients from zero on the normal equations, one pass of the survey (convolve and
  // adjoint of every chunk) per iteration; `progress`, when given, is called after each.
  DeconvolvedMaps solve(const Survey& survey, const std::function<void(const DeconvolutionProgress&)>& progress = {});

 private:
  Engine& engine_;
  DeconvolutionOptions options_;
  bool any_ = false;
};

}  // namespace pisco
