// Scans of a spinning, precessing satellite (litebird_sim's SpinningScanningStrategy, TOAST 3's
// SimSatellite): include/pisco/scan.hpp documents the geometry and the orientation.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <utility>

#include "pisco/error.hpp"
#include "pisco/time_ranges.hpp"
#include "pisco/scan.hpp"
#include "pisco/units.hpp"

namespace pisco {
namespace {

constexpr double pi = std::numbers::pi;

// Fixed rotations between celestial frames.
// - Ecliptic to equatorial: a rotation by the obliquity about the x axis (the equinox), the IAU 1976
//   value at J2000, eps0 = 84381.448 arcsec = 23.4392911 deg (Lieske et al. 1977, A&A 58, 1; the
//   Explanatory Supplement to the Astronomical Almanac). The result is the J2000 mean equator and
//   equinox, within 0.02 arcsec of ICRS.
// - Equatorial to galactic: the IAU 1958 system (Blaauw et al. 1960, MNRAS 121, 123) carried to J2000
//   and ICRS in The Hipparcos and Tycho Catalogues (ESA SP-1200, 1997), vol. 1, section 1.5.3: the
//   north galactic pole at RA 192.85948 deg, Dec +27.12825 deg, and the north celestial pole at
//   galactic longitude 122.93192 deg.
constexpr double obliquity_j2000 = 23.4392911 * deg;
constexpr double ngp_ra = 192.85948 * deg, ngp_dec = 27.12825 * deg, ncp_l = 122.93192 * deg;

void require(bool ok, const std::string& field, const std::string& what) {
  if (!ok) throw Error("satellite scan: " + field + " " + what);
}

// 2 pi times the fractional part of t / period: the angle of a uniform rotation, kept within [0, 2 pi)
// before it meets the phase, so that large t loses no more than its own rounding.
double turn_angle(double t, double period) {
  const double turns = t / period;
  return 2 * pi * (turns - std::floor(turns));
}

}  // namespace

Quat SatelliteScan::ecliptic_to(Frame frame) noexcept {
  const Quat ecl_to_equ = quat_from_axis_angle({1, 0, 0}, obliquity_j2000);
  switch (frame) {
    case Frame::ecliptic:
      return Quat{};
    case Frame::equatorial:
      return ecl_to_equ;
    case Frame::galactic: {
      // The galactic basis seen from the equatorial frame is R_z(ra) R_y(pi/2 - dec) R_z(pi - l_ncp):
      // its z axis at the galactic pole, and its x axis turned from the local meridian (which points
      // away from the celestial pole, at galactic longitude l_ncp + pi) so that the celestial pole
      // falls at longitude l_ncp. Equatorial to galactic is its inverse.
      const Quat galactic_basis = quat_from_pointing(pi / 2 - ngp_dec, ngp_ra, pi - ncp_l);
      return conjugate(galactic_basis) * ecl_to_equ;
    }
  }
  return Quat{};
}

void SatelliteScan::check() const {
  require(std::isfinite(spin_sun_angle) && spin_sun_angle >= 0 && spin_sun_angle <= pi, "spin_sun_angle",
          "must be within [0, 180] deg");
  require(std::isfinite(spin_boresight_angle) && spin_boresight_angle > 0 && spin_boresight_angle < pi,
          "spin_boresight_angle", "must be within (0, 180) deg");
  require(std::isfinite(precession_period) && precession_period > 0, "precession_period", "must be positive");
  require(std::isfinite(spin_period) && spin_period > 0, "spin_period", "must be positive");
  require(std::isfinite(sample_rate) && sample_rate > 0, "sample_rate", "must be positive");
  require(std::isfinite(start_time), "start_time", "must be finite");
  require(std::isfinite(precession_phase), "precession_phase", "must be finite");
  require(std::isfinite(spin_phase), "spin_phase", "must be finite");
  require(std::isfinite(year) && year > 0, "year", "must be positive");
  require(frame == Frame::ecliptic || frame == Frame::equatorial || frame == Frame::galactic, "frame",
          "must be ecliptic, equatorial or galactic");
  if (const auto p = time_problem()) throw p->error();
}

// docs/formats.md, "Times, rates and angles".
std::optional<TimeProblem> SatelliteScan::time_problem() const {
  if (std::string why = sample_time_problem(start_time, double(samples), sample_rate); !why.empty())
    return TimeProblem{"start_time", why};
  const double t_max = std::max(std::abs(start_time), std::abs(time(samples)));
  for (const auto& [field, period] : {std::pair<const char*, double>{"spin_period", spin_period},
                                      {"precession_period", precession_period}, {"year", year}})
    if (std::string why = turning_problem(2 * pi / period, t_max, sample_rate); !why.empty())
      return TimeProblem{field, why};
  return std::nullopt;
}

double SatelliteScan::time(std::size_t i) const { return start_time + double(i) / sample_rate; }

namespace {

// The rotations of one sample, in the ecliptic frame: the anti-sun direction's (yearly) one and the
// precession, whose product carries the precession axis x^ onto the anti-sun direction.
struct Motion {
  Quat sky;  // R_z(longitude) R_x(precession angle)
  Quat spin; // R_z(spin angle)
};

Motion motion(const SatelliteScan& s, double t) {
  const double longitude = turn_angle(t, s.year);
  const double precession = turn_angle(t, s.precession_period) + s.precession_phase;
  const double spin = turn_angle(t, s.spin_period) + s.spin_phase;
  return {quat_from_axis_angle({0, 0, 1}, longitude) * quat_from_axis_angle({1, 0, 0}, precession),
          quat_from_axis_angle({0, 0, 1}, spin)};
}

}  // namespace

void SatelliteScan::generate(std::size_t first, std::size_t count, std::vector<Quat>& out) const {
  check();
  out.clear();
  out.reserve(count);
  // The fixed factors: the output frame on the left, the spin axis's tilt from the precession axis
  // (R_y(pi/2 - alpha) takes z^ to cos(alpha) x^ + sin(alpha) z^) and the boresight's from the spin
  // axis (R_y(beta)).
  const Quat to_frame = ecliptic_to(frame);
  const Quat tilt = quat_from_axis_angle({0, 1, 0}, pi / 2 - spin_sun_angle);
  const Quat opening = quat_from_axis_angle({0, 1, 0}, spin_boresight_angle);
  for (std::size_t i = first; i < first + count; ++i) {
    const Motion m = motion(*this, time(i));
    out.push_back(to_frame * (m.sky * (tilt * (m.spin * opening))));
  }
}

std::array<double, 3> SatelliteScan::spin_axis(std::size_t i) const {
  const Motion m = motion(*this, time(i));
  const std::array<double, 3> tilted{std::cos(spin_sun_angle), 0.0, std::sin(spin_sun_angle)};
  return rotate(ecliptic_to(frame), rotate(m.sky, tilted));
}

std::array<double, 3> SatelliteScan::anti_sun(std::size_t i) const {
  const double longitude = turn_angle(time(i), year);
  return rotate(ecliptic_to(frame), {std::cos(longitude), std::sin(longitude), 0.0});
}

}  // namespace pisco
