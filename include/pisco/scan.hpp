// Scan generators: deterministic (theta, phi, psi) streams for one detector (DESIGN 5).
#pragma once

#include <cstdint>
#include <vector>

#include "pisco/pointing.hpp"

namespace pisco {

// Every RING pixel centre of `nside`, once per angle in psis (all pixels at psis[0], then psis[1]...).
Pointing pixel_centre_scan(int nside, const std::vector<double>& psis);

// Pixel-centre scan with random offsets (paper 6.3): theta += U(f Omega), phi += U(f Omega)/sin theta,
// U(a) uniform in [-a/2, a/2], Omega = sqrt(4 pi / npix) the mean pixel size. With `symmetric`,
// each offset sample is followed by its mirror (-dtheta, -dphi), doubling the number of samples.
// theta is reflected back into [0, pi] at the poles; deterministic for a given seed.
Pointing random_offset_scan(int nside, const std::vector<double>& psis, double f, std::uint64_t seed,
                            bool symmetric = false);

// Raster around a point (paper 6.1): the centres of the `nside` pixels within `radius` of
// (theta0, phi0), at each psi.
Pointing raster_scan(double theta0, double phi0, double radius, int nside,
                     const std::vector<double>& psis);

}  // namespace pisco
