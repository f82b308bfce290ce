// The sky's polar copy, resampled locally (docs/physics.md, "The quadrature"): the sky turned by R
// (poles.hpp's polar_rotation) on the pixels where the turned poles land, interpolated from the
// sky's own pixels around each pole.
//
// Around a pole each HEALPix ring is equally spaced in phi: its values are upsampled by FFT (the
// ring's own trigonometric interpolant, exact for every Fourier mode the ring holds) and read between
// the upsampled points by Lagrange interpolation in phi; across rings, Lagrange interpolation in the
// signed colatitude along the great circle through the pole (a ring's values at phi + pi are that
// line's samples beyond the pole). Q and U are interpolated in the frame parallel-transported from the
// pole (smooth through it, where the local theta/phi frame turns once per ring) and turned at the end
// into the copy's own frame. The copy is linear in the sky; polar_sky_adjoint is its exact transpose.
#pragma once

#include <cstddef>

#include "pisco/sky.hpp"

namespace pisco::detail {

// S'(R p) = S(p) on the copy's pixels within `reach` (radians) of (+-1, 0, 0), where the north and
// south poles land; I elsewhere is the sky's mean I (so that the copy's monopole is the sky's, for the
// float32 backends' precision), Q, U and V 0. Its own cap-boundary rings weighted when
// `weigh_boundaries`. `reach` below 88 deg. Runs on `threads` threads (0: all the host's).
Sky polar_sky(const SkyView& sky, bool weigh_boundaries, double reach, unsigned threads = 0);
// Its transpose (docs/physics.md, "The adjoint"): <polar_sky(s), m> = <s, polar_sky_adjoint(m)> to
// rounding, in the inner product sum_p of the four maps.
Sky polar_sky_adjoint(const SkyView& maps, bool weigh_boundaries, double reach);
// Whether a copy of that reach can be made at `nside`: its stencils need kHalfWidth + 1 rings beyond
// reach and 40 rings at least (polar_copy.cpp), fewer than the sky's 4 NSIDE - 1.
bool polar_copy_fits(int nside, double reach);

}  // namespace pisco::detail
