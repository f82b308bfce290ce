#include "pisco/time_ranges.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/text.hpp"

namespace pisco {
namespace {

std::string g(double v) { return detail::number_text(v, 3); }

// The spacing of float64 values at |x|.
double ulp(double x) {
  x = std::abs(x);
  return std::nextafter(x, std::numeric_limits<double>::infinity()) - x;
}

}  // namespace

std::string sample_time_problem(double start, double samples, double sample_rate) {
  if (!(sample_rate > 0) || !std::isfinite(sample_rate)) return "the sample rate must be positive and finite";
  const double end = start + samples / sample_rate;
  if (!std::isfinite(start) || !std::isfinite(end))
    return "the run's times overflow float64 (start " + g(start) + " s, " + g(samples) + " samples at " + g(sample_rate) +
           " Hz)";
  const double t_max = std::max(std::abs(start), std::abs(end));
  const double rounding = ulp(t_max) * sample_rate;  // in sample intervals
  if (rounding > time_resolution)
    return "times up to " + g(t_max) + " s are rounded to " + g(ulp(t_max)) + " s in float64, " + g(rounding) +
           " of the sample interval at " + g(sample_rate) + " Hz (at most " + g(time_resolution) +
           "): start the clock nearer the run, or shorten it";
  return {};
}

std::string turning_problem(double radians_per_second, double t_max, double sample_rate) {
  const double w = std::abs(radians_per_second);
  if (!std::isfinite(w)) return "the rotation rate is not finite";
  const double per_sample = w / sample_rate;
  if (per_sample > std::numbers::pi)
    return "turns " + g(per_sample * 180 / std::numbers::pi) + " deg between samples at " + g(sample_rate) +
           " Hz (at most 180 deg: faster, its samples are noise)";
  const double turns = w * std::abs(t_max) / (2 * std::numbers::pi);
  const double rounding = 2 * std::numbers::pi * ulp(turns);
  if (!std::isfinite(turns) || rounding > angle_resolution)
    return "after " + g(std::abs(t_max)) + " s its angle (" + g(turns) + " turns) is rounded to " + g(rounding) +
           " rad in float64 (at most " + g(angle_resolution) + " rad): turn slower, start the clock nearer the run, or "
           "shorten it";
  return {};
}

std::string stepping_problem(double step_seconds, double t_max, double sample_rate) {
  if (!(step_seconds > 0) || !std::isfinite(step_seconds)) return "the step time must be positive and finite";
  if (step_seconds * sample_rate < 1)
    return "each angle is held " + g(step_seconds) + " s, less than one sample at " + g(sample_rate) +
           " Hz (at least " + g(1 / sample_rate) + " s)";
  const double steps = std::abs(t_max) / step_seconds;
  if (!(steps < 0x1p52))
    return "times up to " + g(std::abs(t_max)) + " s make " + g(steps) + " steps, more than float64 counts exactly (2^52)";
  return {};
}

}  // namespace pisco
