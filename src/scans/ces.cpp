// Constant-elevation scans from a ground site (docs/config.md, "[scan]"; paper section 7).
#include <cmath>
#include <numbers>
#include <string>

#include "core/prepared.hpp"
#include "pisco/error.hpp"
#include "pisco/time_ranges.hpp"
#include "pisco/scan.hpp"

namespace pisco {
namespace {

constexpr double pi = std::numbers::pi;

void require(bool ok, const std::string& what) {
  if (!ok) throw Error("constant-elevation scan: " + what);
}

}  // namespace

void CesScan::check() const {
  require(std::isfinite(latitude) && std::abs(latitude) <= pi / 2, "latitude must be within [-90, 90] deg");
  require(std::isfinite(longitude), "longitude must be finite");
  require(elevation > 0 && elevation < pi / 2, "elevation must be within (0, 90) deg");
  require(std::isfinite(az_centre) && az_throw >= 0 && std::isfinite(az_throw), "az_centre and az_throw >= 0 must be finite");
  require(az_speed > 0 && std::isfinite(az_speed), "az_speed must be positive");
  require(sample_rate > 0 && std::isfinite(sample_rate), "sample_rate must be positive");
  require(std::isfinite(start_unix), "start time must be finite");
  require(!boresight_angles.empty(), "boresight_angles must not be empty");
  for (double b : boresight_angles) require(std::isfinite(b), "boresight_angles must be finite");
  require(boresight_period > 0 && std::isfinite(boresight_period), "boresight_period must be positive");
  if (const auto p = time_problem()) throw p->error();
}

// docs/formats.md, "Times, rates and angles": the sample times (Unix), the azimuth (from the run's
// start), the Earth's rotation (from Unix times) and the count of boresight periods.
std::optional<TimeProblem> CesScan::time_problem() const {
  const double duration = double(samples) / sample_rate;
  if (std::string why = sample_time_problem(start_unix, double(samples), sample_rate); !why.empty())
    return TimeProblem{"start_unix", why};
  if (std::string why = turning_problem(az_speed, duration, sample_rate); !why.empty())
    return TimeProblem{"az_speed", why};
  if (std::string why = turning_problem(7.2921159e-5, std::abs(start_unix) + duration, sample_rate); !why.empty())
    return TimeProblem{"start_unix", "the Earth's rotation: " + why};
  if (boresight_angles.size() > 1)
    if (std::string why = stepping_problem(boresight_period, duration, sample_rate); !why.empty())
      return TimeProblem{"boresight_period", why};
  return std::nullopt;
}

double CesScan::azimuth(std::size_t i) const {
  if (az_throw == 0) return az_centre;
  // A triangle wave between az_centre - throw/2 and az_centre + throw/2 at constant speed.
  const double s = std::fmod(double(i) / sample_rate * az_speed, 2 * az_throw);
  return az_centre - az_throw / 2 + (s < az_throw ? s : 2 * az_throw - s);
}

double CesScan::local_sidereal_time(std::size_t i) const {
  // Earth rotation angle (IERS 2003) from days since J2000.0 (2000-01-01 12:00 TT ~ UT1), plus the
  // longitude; the whole and fractional days are kept apart to keep full double precision.
  const double days = (start_unix + double(i) / sample_rate) / 86400.0 - 10957.5;
  const double whole = std::floor(days), frac = days - whole;
  const double turns = 0.7790572732640 + 0.00273781191135448 * days + frac;
  return std::fmod(2 * pi * (turns - std::floor(turns)) + longitude, 2 * pi);
}

void CesScan::generate(std::size_t first, std::size_t count, Pointing& out) const {
  check();
  out.clear();
  out.reserve(count);
  const double sl = std::sin(latitude), cl = std::cos(latitude);
  const double se = std::sin(elevation), ce = std::cos(elevation);
  for (std::size_t i = first; i < first + count; ++i) {
    const double az = azimuth(i), lst = local_sidereal_time(i);
    const double sa = std::sin(az), ca = std::cos(az);
    // Horizontal (az from north towards east, el) to declination and hour angle.
    const double sin_dec = sl * se + cl * ce * ca;
    const double cdch = cl * se - sl * ce * ca;  // cos(dec) cos(H)
    const double cdsh = -ce * sa;                // cos(dec) sin(H)
    const double theta = std::atan2(std::hypot(cdch, cdsh), sin_dec);
    const double phi = detail::wrap_phi(lst - std::atan2(cdsh, cdch));
    // The direction of increasing elevation: the zenith's component tangent to the sphere at p.
    const double st = std::sin(theta), ct = std::cos(theta), sp = std::sin(phi), cp = std::cos(phi);
    const double zx = cl * std::cos(lst), zy = cl * std::sin(lst), zz = sl;
    const double up_theta = zx * ct * cp + zy * ct * sp - zz * st;  // Z . theta^
    const double up_phi = -zx * sp + zy * cp;                       // Z . phi^
    out.push_back(theta, phi, std::atan2(up_phi, up_theta) + boresight_angle(i));
  }
}

double CesScan::boresight_angle(std::size_t i) const {
  if (boresight_angles.size() == 1) return boresight_angles[0];
  // check() keeps the count of boresight periods below 2^52, so the conversion is exact.
  const double day = std::floor(double(i) / sample_rate / boresight_period);
  return boresight_angles[static_cast<std::size_t>(day) % boresight_angles.size()];
}

void CesScan::generate_horizon(std::size_t first, std::size_t count, Pointing& out) const {
  check();
  out.clear();
  out.reserve(count);
  // At the boresight theta^ points down (away from the zenith, the pole): theta' up is psi = pi.
  for (std::size_t i = first; i < first + count; ++i)
    out.push_back(pi / 2 - elevation, detail::wrap_phi(-azimuth(i)), pi + boresight_angle(i));
}

}  // namespace pisco
