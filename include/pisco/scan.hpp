// Scan generators: deterministic (theta, phi, psi) streams for one detector (DESIGN 5).
#pragma once

#include <cstdint>
#include <vector>

#include "pisco/pointing.hpp"

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

  // Checks the parameters; throws pisco::Error naming the field.
  void check() const;
  // Boresight pointing of samples [first, first + count), appended to `out` (cleared first).
  void generate(std::size_t first, std::size_t count, Pointing& out) const;
  // Azimuth and elevation of the boresight at sample i (radians), for tests and diagnostics.
  double azimuth(std::size_t i) const;
  // Local sidereal time at sample i (radians).
  double local_sidereal_time(std::size_t i) const;
};

}  // namespace pisco
