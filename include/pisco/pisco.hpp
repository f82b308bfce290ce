// PISCO-VK: pixel-space convolution of polarized skies with beamsors. Umbrella header of the
// operator: skies, beams, focal planes, half-wave plates, pointing and the engine (convolve, adjoint)
// with its errors. The pipeline around it (scans, map-makers, spectra, TOD and pointing files, whole
// simulations) has its own headers, each included where it is used; pisco/simulation.hpp brings the
// parts of a simulation.
#pragma once

#include "pisco/beam_files.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/hwp.hpp"
#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/sky.hpp"
#include "pisco/sources.hpp"
#include "pisco/ground.hpp"
#include "pisco/units.hpp"
#include "pisco/version.hpp"
