// The outer parts of split beams: their sky's NSIDE and the band-limited copy of the sky (docs/beams.md,
// "Sidelobes").
#include "core/outer_sky.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>


#include "core/sky_alm.hpp"
#include "pisco/error.hpp"

namespace pisco::detail {

int sidelobe_nside(const std::vector<Beamsor>& beams, int sky_nside) {
  int asked = 0, band = 0;
  bool any = false;
  for (const Beamsor& b : beams) {
    if (!b.sidelobes()) continue;
    any = true;
    // The outer parts are summed on a band-limited copy of the sky, which cannot be finer than the sky.
    if (b.sidelobe_nside() > sky_nside)
      throw Error("beam " + b.description() + ": sidelobe_nside = " + std::to_string(b.sidelobe_nside()) +
                  " is above the sky's NSIDE " + std::to_string(sky_nside) +
                  "; the sidelobes are summed on a smoothed copy of the sky at most as fine as the sky: set at most " +
                  std::to_string(sky_nside) + ", or 0 to choose it from the sidelobes' band limit");
    asked = std::max(asked, b.sidelobe_nside());
    band = std::max(band, b.sidelobe_band_limit());
  }
  if (!any) return 0;
  int nside = asked;
  if (nside == 0) {
    nside = 1;
    while (2.0 * nside < 1.5 * band && nside < sky_nside) nside *= 2;
  }
  return std::min(nside, sky_nside);
}

namespace {
// The window: 1 up to l_pass, a half cosine down to 0 at l_stop.
void apply_window(SkyAlm& a, int l_pass, int l_stop) {
  const int lmax = a.t.Lmax();
  std::vector<double> window(static_cast<std::size_t>(lmax) + 1, 0.0);
  for (int l = 0; l <= lmax; ++l) {
    if (l <= l_pass) window[static_cast<std::size_t>(l)] = 1.0;
    else if (l < l_stop) window[static_cast<std::size_t>(l)] = 0.5 * (1 + std::cos(std::numbers::pi * (l - l_pass) / double(l_stop - l_pass)));
  }
  for (int m = 0; m <= lmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const double w = window[static_cast<std::size_t>(l)];
      a.t(l, m) *= w;
      a.e(l, m) *= w;
      a.b(l, m) *= w;
      a.v(l, m) *= w;
    }
}
}  // namespace

Sky band_limited_sky_adjoint(const SkyView& maps, int sky_nside, int l_pass) {
  if (maps.nside() == sky_nside) return Sky(maps);
  const int l_stop = std::min(2 * maps.nside(), 3 * sky_nside - 1);
  try {
    SkyAlm a = sky_from_alm_adjoint(maps, l_stop);
    apply_window(a, l_pass, l_stop);
    return sky_alm_adjoint(a, sky_nside, 3, maps.units());
  } catch (const PlanckError& err) {
    throw Error(std::string("the adjoint of the sidelobes' band-limited sky: HEALPix: ") + err.what());
  }
}

Sky band_limited_sky(const SkyView& sky, int nside, int l_pass) {
  if (nside == sky.nside()) return Sky(sky);
  const int l_stop = std::min(2 * nside, 3 * sky.nside() - 1);
  const int lmax = l_stop;
  try {
    SkyAlm a = sky_alm(sky, lmax, 3);
    apply_window(a, l_pass, l_stop);
    return sky_from_alm(a, nside, sky.units());
  } catch (const PlanckError& err) {
    throw Error(std::string("the sidelobes' band-limited sky: HEALPix: ") + err.what());
  }
}

}  // namespace pisco::detail
