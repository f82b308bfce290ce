// The sky's polar copy (docs/physics.md, "The quadrature"): the sky turned by R (poles.hpp's
// polar_rotation) on the pixels where the turned poles land, made from the sky's own pixels around
// each pole. Within the zone of the least-squares fit (polar_fit.hpp: a band-limited field fitted to
// the pixels of the rings around the pole, every azimuthal mode at once) a copy pixel is the fitted
// field's value; beyond it, for reaches of more than 64 rings, it is interpolated from the rings, and
// the two are blended over the zone's last rings.
//
// The interpolation: around a pole each HEALPix ring is equally spaced in phi: its values are upsampled
// by FFT (the ring's own trigonometric interpolant, exact for every Fourier mode the ring holds) and
// read between the upsampled points by Lagrange interpolation in phi; across rings, Lagrange
// interpolation in the signed colatitude along the great circle through the pole (a ring's values at
// phi + pi are that line's samples beyond the pole). Q and U are fitted and interpolated in the frame
// parallel-transported from the pole (smooth through it, where the local theta/phi frame turns once
// per ring) and turned at the end into the copy's own frame. The copy is linear in the sky;
// polar_sky_adjoint is its exact transpose.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "pisco/sky.hpp"

namespace pisco::detail {

// The part of the copy that samples can read, as the backends keep it beside the sky: whole rings
// around the copy's equator, pixels [first, first + size()) (RING), first a multiple of 64 so that
// every backend's rows keep their alignment. About sin(reach) of the sky (docs/physics.md, "The
// quadrature", has its memory).
struct SkyBand {
  int nside = 0;
  std::size_t first = 0;
  std::array<std::vector<double>, 4> maps;  // I, Q, U, V
  std::size_t size() const noexcept { return maps[0].size(); }
  double value(int stokes, std::size_t pixel) const { return maps[std::size_t(stokes)][pixel - first]; }
};

// The band of a copy of `reach` at `nside`: its first pixel and its number of pixels.
std::array<std::size_t, 2> polar_band(int nside, double reach);

// What the copy is made from: the sky's mean I and its pixels on the rings around each pole that the
// copy reads (a few percent of the sky at most), so that a copy made on another thread holds no whole
// sky of its own.
struct PolarSource {
  int nside = 0;
  double reach = 0.0, mean = 0.0;
  SkyBand north, south;
};
PolarSource polar_source(const SkyView& sky, double reach);

// S'(R p) = S(p) on the copy's pixels within `reach` (radians) of (+-1, 0, 0), where the north and
// south poles land, held in the band polar_band(nside, reach); the band's other pixels, which no sample
// reads, hold the sky's mean I, and Q, U and V 0. Its own cap-boundary rings weighted when
// `weigh_boundaries`. `reach` below 88 deg. Runs on `threads` threads (0: all the host's).
SkyBand polar_sky(const SkyView& sky, bool weigh_boundaries, double reach, unsigned threads = 0);
SkyBand polar_sky(const PolarSource& source, bool weigh_boundaries, unsigned threads = 0);
// Its transpose (docs/physics.md, "The adjoint"): <polar_sky(s), m> = <s, polar_sky_adjoint(m)> to
// rounding, in the inner product sum_p of the four maps over the band. `maps` is a band of the same
// extent; the result is the whole sky.
Sky polar_sky_adjoint(const SkyBand& maps, bool weigh_boundaries, double reach, unsigned threads = 0);
// The band's pixels of whole-sky maps (the adjoint's maps as the backends give them).
SkyBand band_of(const SkyView& maps, std::size_t first, std::size_t count);
// Whether a copy of that reach can be made at `nside`: its stencils need kHalfWidth + 1 rings beyond
// reach and 40 rings at least (polar_copy.cpp), fewer than the sky's 4 NSIDE - 1.
bool polar_copy_fits(int nside, double reach);

}  // namespace pisco::detail
