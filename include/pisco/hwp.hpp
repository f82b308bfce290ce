// Half-wave plates and other per-sample Mueller elements in front of a detector (docs/physics.md,
// "Half-wave plates"): the plate's Mueller matrix at angle 0, where it sits, and the streams of its
// angle. A plate turned to angle theta from the detector's polarization axis has
//   M(theta) = R(-theta) M0 R(theta),
//   R(a) rows (1,0,0,0), (0,cos2a,sin2a,0), (0,-sin2a,cos2a,0), (0,0,0,1),
// and theta = hwp_angle - gamma: the plate's angle is given in the focal-plane frame (TOAST's
// per-sample `hwp_angle`), and the detector's polarization axis lies at gamma in that frame (TOAST's
// focal-plane `gamma`). An ideal plate, M0 = diag(1, 1, -1, -1), turns linear polarization at angle
// g into 2 theta - g: with a round beam, d(psi0, theta) equals the plate-less d(psi0 + 2 theta).
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/time_ranges.hpp"

namespace pisco {

enum class HwpPlacement {
  aperture,  // skyward of the optics (LiteBIRD, SO SATs): the sky passes the plate before the beamsor
  detector,  // between the optics and the detector: the plate acts on the beam-convolved Stokes vector
};

// diag(1, 1, -1, -1).
Mueller ideal_hwp_mueller();
// R(-angle) m0 R(angle).
Mueller rotated_mueller(const Mueller& m0, double angle);

struct HalfWavePlate {
  Mueller mueller = ideal_hwp_mueller();  // M0: the plate's Mueller matrix with its fast axis along the detector's axis
  HwpPlacement placement = HwpPlacement::aperture;
  double gamma = 0.0;  // the detector's polarization angle in the focal-plane frame, radians

  static HalfWavePlate ideal(double gamma = 0.0, HwpPlacement placement = HwpPlacement::aperture);
  // Throws pisco::Error naming `where` for a non-finite entry or gamma, or a matrix no passive plate
  // has (docs/physics.md, "Physical bounds on Mueller matrices": M00 > 0, transmission at most 1).
  void check(const std::string& where) const;
};

// The plate's angle per sample (radians, focal-plane frame), from one of the streams the field uses.
struct HwpAngleStream {
  enum class Kind { continuous, stepped };
  Kind kind = Kind::continuous;
  double frequency_hz = 0.0;   // continuous: turns per second (may be negative: the other sense)
  double phase = 0.0;          // continuous: the angle at time 0
  std::vector<double> steps;   // stepped: the angles taken in turn
  double step_seconds = 0.0;   // stepped: how long each is held
  double sample_rate = 0.0;    // Hz: sample i is at time start_time + i / sample_rate
  double start_time = 0.0;     // seconds

  // Throws pisco::Error naming the field (non-finite values, sample_rate <= 0, stepped without angles
  // or with step_seconds <= 0).
  void check() const;
  // check(), and what float64 carries over `samples` samples (docs/formats.md, "Times, rates and
  // angles"): sample times, the rotation's angle, the step count. Throws pisco::Error naming the field
  // (time_problem's as its key()).
  void check(std::size_t samples) const;
  // What float64 cannot carry over `samples` samples, by field: start_time (the sample times),
  // frequency, step_seconds. Part of check(samples).
  std::optional<TimeProblem> time_problem(std::size_t samples) const;
  // Angles of samples [first, first + count) into out (resized), each computed from its own time;
  // check(first + count) first.
  void generate(std::size_t first, std::size_t count, std::vector<double>& out) const;
};

}  // namespace pisco
