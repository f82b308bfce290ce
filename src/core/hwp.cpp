#include "pisco/hwp.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "kernel/plate.hpp"
#include "pisco/error.hpp"
#include "pisco/time_ranges.hpp"

namespace pisco {

Mueller ideal_hwp_mueller() {
  Mueller m{};
  m[0][0] = 1.0;
  m[1][1] = 1.0;
  m[2][2] = -1.0;
  m[3][3] = -1.0;
  return m;
}

HalfWavePlate HalfWavePlate::ideal(double gamma, HwpPlacement placement) {
  return {ideal_hwp_mueller(), placement, gamma};
}

// A passive element's bounds (docs/physics.md, "Physical bounds on Mueller matrices").
void HalfWavePlate::check(const std::string& where) const {
  check_mueller(mueller, where + ": half-wave plate", MuellerBounds::passive);
  if (!std::isfinite(gamma)) throw Error(where + ": half-wave plate gamma is not finite");
}

Mueller rotated_mueller(const Mueller& m0, double angle) {
  double in[16], out[16];
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) in[4 * i + j] = m0[i][j];
  detail::plate_at(in, std::cos(2 * angle), std::sin(2 * angle), out);
  Mueller m{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) m[i][j] = out[4 * i + j];
  return m;
}

void HwpAngleStream::check() const {
  if (!(sample_rate > 0) || !std::isfinite(sample_rate))
    throw Error("half-wave plate: sample_rate must be positive and finite");
  if (!std::isfinite(start_time)) throw Error("half-wave plate: start_time is not finite");
  if (kind == Kind::continuous) {
    if (!std::isfinite(frequency_hz)) throw Error("half-wave plate: frequency is not finite");
    if (!std::isfinite(phase)) throw Error("half-wave plate: phase is not finite");
    return;
  }
  if (steps.empty()) throw Error("half-wave plate: a stepped plate needs at least one angle (steps)");
  for (std::size_t i = 0; i < steps.size(); ++i)
    if (!std::isfinite(steps[i])) throw Error("half-wave plate: step angle " + std::to_string(i) + " is not finite");
  if (!(step_seconds > 0) || !std::isfinite(step_seconds))
    throw Error("half-wave plate: step_seconds must be positive and finite");
}

void HwpAngleStream::check(std::size_t samples) const {
  check();
  if (const auto p = time_problem(samples)) throw p->error();
}

// docs/formats.md, "Times, rates and angles".
std::optional<TimeProblem> HwpAngleStream::time_problem(std::size_t samples) const {
  if (std::string why = sample_time_problem(start_time, double(samples), sample_rate); !why.empty())
    return TimeProblem{"start_time", why};
  const double t_max = std::max(std::abs(start_time), std::abs(start_time + double(samples) / sample_rate));
  if (kind == Kind::continuous) {
    if (std::string why = turning_problem(2 * std::numbers::pi * frequency_hz, t_max, sample_rate); !why.empty())
      return TimeProblem{"frequency", why};
  } else if (std::string why = stepping_problem(step_seconds, t_max, sample_rate); !why.empty()) {
    return TimeProblem{"step_seconds", why};
  }
  return std::nullopt;
}

void HwpAngleStream::generate(std::size_t first, std::size_t count, std::vector<double>& out) const {
  check(first + count);
  out.resize(count);
  const double twopi = 2 * std::numbers::pi;
  for (std::size_t i = 0; i < count; ++i) {
    const double t = start_time + double(first + i) / sample_rate;
    if (kind == Kind::continuous) {
      // The number of turns is reduced first so that the angle keeps full precision over long runs.
      const double turns = frequency_hz * t;
      out[i] = std::remainder(twopi * (turns - std::floor(turns)) + phase, twopi);
    } else {
      // check() keeps |k| below 2^52: k and its remainder are exact integers within [0, n).
      const double k = std::floor(t / step_seconds);
      const double n = double(steps.size());
      const double step = k - n * std::floor(k / n);
      out[i] = steps[step >= 0 && step < n ? std::size_t(step) : 0];
    }
  }
}

}  // namespace pisco
