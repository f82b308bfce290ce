// What float64 can carry over a run (docs/formats.md, "Times, rates and angles"): sample times and
// the angles of uniform rotations (a spin, a precession, a half-wave plate, the Earth) computed from
// them. Each function returns an empty string when the values are fine, else what is wrong, for a
// message "<key>: <what>" that names the key the caller read the value from.
#pragma once

#include <cstddef>
#include <optional>
#include <string>

#include "pisco/error.hpp"

namespace pisco {

// A sample's time may be rounded by at most this fraction of the sample interval.
inline constexpr double time_resolution = 1e-3;
// An angle may be rounded by at most this many radians anywhere in the run (2 arcsec: a
// polarization angle error of 2e-5, five times below the engine's 1e-4 accuracy).
inline constexpr double angle_resolution = 1e-5;

// A value a run cannot carry: the field it concerns (the struct member's name, which a caller that
// read it from a file maps to its key) and what is wrong.
struct TimeProblem {
  std::string field;
  std::string what;
  // As the input error a check() throws: what is wrong, keyed by the field (Error::key, Error::named).
  Error error() const { return Error(what, ErrorKind::input, field); }
};

// Samples at start + i / sample_rate, i < samples: every time finite and resolved to time_resolution
// of the sample interval.
std::string sample_time_problem(double start, double samples, double sample_rate);

// An angle turning at `radians_per_second` (either sense), computed from times up to |t_max|: less than
// half a turn between samples (else its samples are noise), and rounded by at most angle_resolution
// at t_max.
std::string turning_problem(double radians_per_second, double t_max, double sample_rate);

// A plate that steps every `step_seconds`, its step counted from times up to |t_max|: each angle held
// for at least one sample, and the step count an exact integer (below 2^52).
std::string stepping_problem(double step_seconds, double t_max, double sample_rate);

}  // namespace pisco
