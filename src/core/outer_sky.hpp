// The outer parts of split beams (docs/beams.md, "Sidelobes"): the NSIDE of the sky they are summed
// on and that sky, a band-limited copy of the engine's.
#pragma once

#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/sky.hpp"

namespace pisco::detail {

// The outer parts' sky NSIDE: the largest a split beam asks for (Beamsor::sidelobe_nside), or else
// the smallest power of two with 2 NSIDE >= 1.5 l_b for the largest band limit l_b among them
// (Beamsor::sidelobe_band_limit); never above the sky's own NSIDE. 0 when no beam is split.
int sidelobe_nside(const std::vector<Beamsor>& beams, int sky_nside);

// The sky band-limited and resampled at `nside`: its a_lm up to l_stop = min(2 nside, 3 NSIDE - 1)
// (HEALPix C++ map2alm, 3 iterations; I, Q, U as T, E, B and V as a spin-0 map), multiplied by a window
// that is 1 up to l_pass and falls as a half cosine to 0 at l_stop, synthesized at `nside`. The sky
// itself when nside is its own NSIDE.
Sky band_limited_sky(const SkyView& sky, int nside, int l_pass);
// Its transpose (docs/physics.md, "The adjoint"): maps at `nside` back onto the sky's `sky_nside`.
Sky band_limited_sky_adjoint(const SkyView& maps, int sky_nside, int l_pass);

}  // namespace pisco::detail
