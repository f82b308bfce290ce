// PISCO-VK: pixel-space convolution of polarized skies with beamsors. Umbrella header.
#pragma once

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/output_file.hpp"
#include "pisco/pointing.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/scan.hpp"
#include "pisco/sky.hpp"
#include "pisco/spectra.hpp"
#include "pisco/tod_file.hpp"
#include "pisco/units.hpp"
#include "pisco/version.hpp"
