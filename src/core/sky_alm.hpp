// A sky's spherical harmonic coefficients through HEALPix C++ and back: what the split beams' coarse
// sky (sidelobes.cpp) and the polar copy (poles.cpp) are made from.
#pragma once

#include <string>

#include <alm.h>
#include <xcomplex.h>

#include "pisco/sky.hpp"

namespace pisco::detail {

struct SkyAlm {
  Alm<xcomplex<double>> t, e, b, v;  // I, Q, U as T, E, B; V as spin 0 (only when has_v)
  bool has_v = false;
};

// The sky's a_lm up to lmax by HEALPix's map2alm with `iterations` Jacobi iterations; with
// `ring_weights`, HEALPix's ring weights from healpy-data where it has them for the sky's NSIDE.
// Throws PlanckError, which callers name.
SkyAlm sky_alm(const SkyView& sky, int lmax, int iterations, bool ring_weights);
// The maps of `a` at `nside` (alm2map_pol, and alm2map for V).
Sky sky_from_alm(const SkyAlm& a, int nside, const std::string& units);

}  // namespace pisco::detail
