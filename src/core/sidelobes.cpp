// The outer parts of split beams: their sky's NSIDE and the band-limited copy of the sky (docs/beams.md,
// "Sidelobes").
#include "core/sidelobes.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <healpix_map.h>
#include <xcomplex.h>

#include "pisco/error.hpp"

namespace pisco::detail {

int sidelobe_nside(const std::vector<Beamsor>& beams, int sky_nside) {
  int asked = 0, band = 0;
  bool any = false;
  for (const Beamsor& b : beams) {
    if (!b.sidelobes()) continue;
    any = true;
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

Sky band_limited_sky(const Sky& sky, int nside, int l_pass) {
  if (nside == sky.nside()) return sky;
  const int l_stop = std::min(2 * nside, 3 * sky.nside() - 1);
  const int lmax = l_stop;
  auto map_of = [&](std::span<const double> v, int n) {
    Healpix_Map<double> m(n, RING, SET_NSIDE);
    std::copy(v.begin(), v.end(), &m[0]);
    return m;
  };
  try {
    Alm<xcomplex<double>> t(lmax, lmax), e(lmax, lmax), b(lmax, lmax), v(lmax, lmax);
    const auto mt = map_of(sky.I(), sky.nside()), mq = map_of(sky.Q(), sky.nside()), mu = map_of(sky.U(), sky.nside());
    map2alm_pol_iter(mt, mq, mu, t, e, b, 3);
    const bool has_v = std::any_of(sky.V().begin(), sky.V().end(), [](double x) { return x != 0.0; });
    if (has_v) map2alm_iter(map_of(sky.V(), sky.nside()), v, 3);
    std::vector<double> window(static_cast<std::size_t>(lmax) + 1, 0.0);
    for (int l = 0; l <= lmax; ++l) {
      if (l <= l_pass) window[static_cast<std::size_t>(l)] = 1.0;
      else if (l < l_stop) window[static_cast<std::size_t>(l)] = 0.5 * (1 + std::cos(std::numbers::pi * (l - l_pass) / double(l_stop - l_pass)));
    }
    for (int m = 0; m <= lmax; ++m)
      for (int l = m; l <= lmax; ++l) {
        const double w = window[static_cast<std::size_t>(l)];
        t(l, m) *= w;
        e(l, m) *= w;
        b(l, m) *= w;
        v(l, m) *= w;
      }
    Healpix_Map<double> ot(nside, RING, SET_NSIDE), oq(nside, RING, SET_NSIDE), ou(nside, RING, SET_NSIDE);
    alm2map_pol(t, e, b, ot, oq, ou);
    Sky out(nside, sky.units());
    std::copy(&ot[0], &ot[0] + ot.Npix(), out.I().begin());
    std::copy(&oq[0], &oq[0] + oq.Npix(), out.Q().begin());
    std::copy(&ou[0], &ou[0] + ou.Npix(), out.U().begin());
    if (has_v) {
      Healpix_Map<double> ov(nside, RING, SET_NSIDE);
      alm2map(v, ov);
      std::copy(&ov[0], &ov[0] + ov.Npix(), out.V().begin());
    }
    return out;
  } catch (const PlanckError& err) {
    throw Error(std::string("the sidelobes' band-limited sky: HEALPix: ") + err.what());
  }
}

}  // namespace pisco::detail
