// The ground seen through the far sidelobes of constant-elevation scans (docs/ground.md): a map in the
// horizon frame, which the Earth carries with it, convolved with each detector's beam at the
// boresight's horizon pointing (CesScan::generate_horizon).
#pragma once

#include <string>
#include <vector>

#include "pisco/sky.hpp"

namespace pisco {

// A ground of uniform brightness below a horizon. The horizon's elevation is given at N azimuths
// 0, 360/N, ... deg (from north towards east) and is linear between them, periodic; one value is a
// flat horizon. Across it the brightness falls from `value` (below) to 0 (above) as a half cosine
// over `width` (radians) centred on the horizon; width 0 is a sharp edge.
struct GroundModel {
  double value = 0.0;                  // the ground's brightness, in the map's units
  std::vector<double> horizon{0.0};    // elevations (radians), in (-pi/2, pi/2)
  double width = 0.0;                  // radians, in [0, pi/2]
};

// The model sampled at the pixel centres of a HEALPix RING map of NSIDE `nside` in the horizon frame
// (colatitude 90 deg - elevation, longitude -azimuth: TOAST's Az/El quaternions' frame), I only.
// Throws pisco::Error naming the field that is out of range.
Sky ground_sky(int nside, const GroundModel& model, const std::string& units);

// The ground's brightness temperature in a sky's units: `kelvin` (Rayleigh-Jeans) in K_RJ, uK_RJ,
// K_CMB or uK_CMB (the last two at `frequency_ghz`, through dT_CMB / dT_RJ at the CMB's 2.72548 K).
// Throws pisco::Error for other units, or CMB units without a positive frequency.
double rayleigh_jeans_in(const std::string& units, double kelvin, double frequency_ghz);

}  // namespace pisco
