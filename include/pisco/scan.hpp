// Scan generators: deterministic (theta, phi, psi) streams for one detector (docs/config.md, "[scan]").
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/time_ranges.hpp"

namespace pisco {

// Every RING pixel centre of `nside`, once per angle in psis (all pixels at psis[0], then psis[1]...).
Pointing pixel_centre_scan(int nside, const std::vector<double>& psis);

// Pixel-centre scan with random offsets (paper 6.3): theta += U(f Omega), phi += U(f Omega)/sin theta,
// U(a) uniform in [-a/2, a/2], Omega = sqrt(4 pi / npix) the mean pixel size; one offset per pixel,
// the same at every psi. With `symmetric`, each offset sample is followed by its mirror
// (-dtheta, -dphi), doubling the number of samples.
// theta is reflected back into [0, pi] at the poles; deterministic for a given seed.
Pointing random_offset_scan(int nside, const std::vector<double>& psis, double f, std::uint64_t seed,
                            bool symmetric = false);

// Raster around a point (paper 6.1): the centres of the `nside` pixels within `radius` of
// (theta0, phi0), at each psi.
Pointing raster_scan(double theta0, double phi0, double radius, int nside,
                     const std::vector<double>& psis);

// Constant-elevation scans from a ground site (paper section 7). The boresight sweeps the azimuth
// range az_centre +- az_throw/2 back and forth at az_speed, at a fixed elevation; the boresight
// rotation (about the line of sight) takes the values of `boresight_angles` in turn, one per
// `boresight_period`. Horizontal coordinates become equatorial ones through the local sidereal time
// (Earth rotation angle plus longitude); precession, nutation, aberration and refraction are ignored
// (each below about 0.4 deg over decades, 20 arcsec, and under 1 arcmin at 45 deg elevation), so
// the result is in the equatorial frame of date, which the sky map is taken to be in.
// A boresight position angle psi = boresight angle puts theta' along the direction of increasing
// elevation (towards the zenith).
struct CesScan {
  double latitude = 0.0, longitude = 0.0;  // site, radians (longitude east-positive)
  double elevation = 0.7853981633974483;   // radians
  double az_centre = 0.0, az_throw = 0.0;  // radians, azimuth from north towards east
  double az_speed = 0.017453292519943295;  // radians per second
  double sample_rate = 20.0;               // Hz
  double start_unix = 0.0;                 // seconds since 1970-01-01 UTC of the first sample
  std::vector<double> boresight_angles{0.0};
  double boresight_period = 86400.0;       // seconds each boresight angle is held
  std::size_t samples = 0;                 // total number of samples

  // Checks the parameters; throws pisco::Error naming the field (in its message, or as its key() for
  // what time_problem finds).
  void check() const;
  // What float64 cannot carry over the run (docs/formats.md, "Times, rates and angles"), by field:
  // start_unix (the sample times, and the Earth's rotation from them), az_speed, boresight_period.
  // Part of check().
  std::optional<TimeProblem> time_problem() const;
  // Boresight pointing of samples [first, first + count), appended to `out` (cleared first).
  void generate(std::size_t first, std::size_t count, Pointing& out) const;
  // The same boresight in the horizon frame (docs/ground.md): z at the zenith, x to the north, y to the
  // west, so that colatitude is 90 deg - elevation and longitude is -azimuth (TOAST's boresight_azel);
  // psi pi + the boresight rotation, theta' towards the zenith at rotation 0 as in generate(). The
  // two differ by the rotation from the horizon to the sky at each sample, which the ground does not
  // take part in: a ground map in this frame turns with the Earth.
  void generate_horizon(std::size_t first, std::size_t count, Pointing& out) const;
  // The boresight rotation at sample i (radians): boresight_angles in turn, each held boresight_period.
  double boresight_angle(std::size_t i) const;
  // Azimuth and elevation of the boresight at sample i (radians), for tests and diagnostics.
  double azimuth(std::size_t i) const;
  // Local sidereal time at sample i (radians).
  double local_sidereal_time(std::size_t i) const;
};

// A spinning, precessing satellite at L2 (the scanning strategy of litebird_sim's
// SpinningScanningStrategy and TOAST 3's SimSatellite). Three rotations, each right-handed and at a
// constant rate, computed in double directly from the time of each sample
// t = start_time + i / sample_rate (no accumulation: any split into chunks gives the same bits):
// - the boresight turns about the spin axis, at spin_boresight_angle (beta) from it, one turn per
//   spin_period; spin phase 2 pi t / spin_period + spin_phase;
// - the spin axis turns about the anti-sun direction (the precession axis), at spin_sun_angle
//   (alpha) from it, one turn per precession_period; phase 2 pi t / precession_period +
//   precession_phase;
// - the anti-sun direction moves along the ecliptic, 2 pi per `year`, at ecliptic longitude
//   2 pi t / year: t = 0 is an instant when the anti-sun direction is at longitude 0 (the Sun at
//   180 deg, the September equinox), as in litebird_sim (float times) and TOAST. start_time =
//   L / (2 pi) year puts it at longitude L. The yearly motion is uniform (no ephemeris: the Earth's
//   orbital eccentricity puts the true anti-sun direction up to 1.9 deg from it) and the orbit about
//   L2 is ignored.
// At precession phase 0 the spin axis lies in the plane of the anti-sun direction and the north
// ecliptic pole, north of the ecliptic; at spin phase 0 the boresight is at its closest to the
// anti-sun direction (|alpha - beta| from it).
// The boresight quaternion is, in the ecliptic frame (the composition of litebird_sim's
// spin_to_ecliptic with its bore2spin quaternion R_y(beta), boresight_rotangle = spin_rotangle = 0):
//   q = R_z(2 pi t / year) R_x(precession angle) R_y(pi/2 - alpha) R_z(spin angle) R_y(beta),
// then turned into the output frame (equatorial or galactic) by a fixed rotation on the left.
// Orientation: the boresight's theta' (q x^ q*, where a detector at zeta = 0 points) lies in the
// plane of the spin axis and the line of sight, pointing away from the spin axis, across the scan;
// phi' (q y^ q*) points along the boresight's motion about the spin axis (spin axis x line of
// sight), the scan direction. This is litebird_sim's frame; TOAST's satellite_scanning gives the
// boresight's x axis along the scan direction and its y axis towards the spin axis, which is this
// frame turned by +90 deg about the line of sight (x_TOAST = phi', y_TOAST = -theta': a direction at
// angle z from TOAST's x axis towards its y axis is at zeta = z + 90 deg here).
struct SatelliteScan {
  double spin_sun_angle = 0.7853981633974483;        // alpha, radians, within [0, pi]
  double spin_boresight_angle = 0.8726646259971648;  // beta, radians, within (0, pi)
  double precession_period = 192.348 * 60;           // seconds (LiteBIRD)
  double spin_period = 20.0 * 60;                    // seconds (LiteBIRD: 0.05 rpm)
  double sample_rate = 19.0;                         // Hz
  double start_time = 0.0;                           // seconds from the reference epoch above
  double precession_phase = 0.0, spin_phase = 0.0;   // radians at t = 0
  double year = 365.25 * 86400;                      // seconds: one turn of the anti-sun direction
  // Coordinates of the output (and of the sky map): ecliptic, or equatorial (the J2000 mean equator,
  // through the J2000 obliquity 23.4392911 deg) or galactic (IAU 1958: north galactic pole at RA 192.85948 deg,
  // Dec 27.12825 deg, galactic longitude of the north celestial pole 122.93192 deg, J2000).
  enum class Frame { ecliptic, equatorial, galactic } frame = Frame::ecliptic;
  std::size_t samples = 0;                           // total number of samples

  // Checks the parameters; throws pisco::Error naming the field (in its message, or as its key() for
  // what time_problem finds).
  void check() const;
  // What float64 cannot carry over the run (docs/formats.md, "Times, rates and angles"), by field:
  // start_time (the sample times), spin_period, precession_period, year. Part of check().
  std::optional<TimeProblem> time_problem() const;
  // Boresight quaternions of samples [first, first + count), appended to `out` (cleared first).
  void generate(std::size_t first, std::size_t count, std::vector<Quat>& out) const;
  // Time of sample i, seconds from the reference epoch: start_time + i / sample_rate.
  double time(std::size_t i) const;
  // The spin axis and the anti-sun direction at sample i, unit vectors in the output frame.
  std::array<double, 3> spin_axis(std::size_t i) const;
  std::array<double, 3> anti_sun(std::size_t i) const;
  // The fixed rotation from ecliptic coordinates to `frame` (v_frame = q v_ecliptic q*).
  static Quat ecliptic_to(Frame frame) noexcept;
};

}  // namespace pisco
