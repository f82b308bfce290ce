// A sky's spherical harmonic coefficients through HEALPix C++ and back: what the split beams' coarse
// sky (outer_sky.cpp) and the deconvolving map-maker's smoothing to a target beam go through.
#pragma once

#include <filesystem>
#include <string>

#include <alm.h>
#include <xcomplex.h>

#include "pisco/sky.hpp"

namespace pisco::detail {

struct SkyAlm {
  Alm<xcomplex<double>> t, e, b, v;  // I, Q, U as T, E, B; V as spin 0 (only when has_v)
  bool has_v = false;
};

// healpy-data's folder (totcls.dat, the pixel windows, the ring weights): the environment's
// PISCO_HEALPY_DATA_DIR where set, else the build's (CMake's PISCO_HEALPY_DATA_DIR).
std::filesystem::path healpy_data_dir();

// The sky's a_lm up to lmax by HEALPix's map2alm with `iterations` Jacobi iterations and unit ring
// weights. Throws PlanckError, which callers name.
SkyAlm sky_alm(const SkyView& sky, int lmax, int iterations);
// The maps of `a` at `nside` (alm2map_pol, and alm2map for V).
Sky sky_from_alm(const SkyAlm& a, int nside, const std::string& units);

// The transposes of the two, for the adjoint (docs/physics.md, "The adjoint"), in the inner products
// sum_p m_p m'_p of maps and sum_l [a_l0 b_l0 + 2 sum_{m>0} Re(a_lm conj(b_lm))] of a_lm, in which
// HEALPix's map2alm is alm2map_adjoint of the map times the ring weights and pixel area:
// sky_alm = P = sum_{j=0}^{n} (1 - W Y)^j W with Y = alm2map, W = Y^T D, D = the weights times
// 4 pi / Npix, so P^T b = D Y sum_{j=0}^{n} (1 - Y^T D Y)^j b. Both leave V out where it is zero
// (has_v false: V's a_lm or maps all zero), as the forward does: the same linear map.
// sky_from_alm_adjoint: Y^T of the maps, a_lm up to lmax.
SkyAlm sky_from_alm_adjoint(const SkyView& maps, int lmax);
// sky_alm_adjoint: P^T of `b` into maps at `nside`.
Sky sky_alm_adjoint(const SkyAlm& b, int nside, int iterations, const std::string& units);

}  // namespace pisco::detail
