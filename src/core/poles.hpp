// Where the equal-weight pixel sum is not enough (docs/physics.md, "The quadrature"). Over HEALPix
// rings the pixel sum is a trapezoidal rule in the ring index, exact to rounding for smooth beams
// except at two kinds of places:
// - the poles, where its end term, a third of a pixel's weight times the integrand at the pole, is
//   1e-2 of the TOD for a beam centred on one. Such samples are summed instead on a copy of the sky
//   turned by 90 deg about y, where they lie on the equator, with their pointing turned the same way.
//   The copy is resampled from the pixels around each pole (polar_copy.hpp).
// - the two rings where the polar caps meet the equatorial belt (z = +-2/3), where the rings' spacing
//   changes its law: the rule's slope jumps there, and Euler-Maclaurin's term for the jump is
//   -1/(12 NSIDE) of those rings' own pixel sum. That term is spread over each edge ring and its two
//   neighbours (kernel/cap_boundary.hpp), so that it holds for skies with power up to 3 NSIDE too.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "core/backend.hpp"
#include "kernel/cap_boundary.hpp"
#include "kernel/frame.hpp"
#include "pisco/engine.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/sky.hpp"

namespace pisco::detail {

// The rings about the caps' edges of `nside` with the weights of `quadrature` (cap_boundary.hpp:
// Euler-Maclaurin's jump term spread over each edge ring and its two neighbours).
CapBoundary cap_boundary(int nside, Quadrature quadrature);

// The pixels of those six rings as two runs [first, end): rings NSIDE - 1 to NSIDE + 1 and 3 NSIDE - 1
// to 3 NSIDE + 1.
std::array<std::pair<std::size_t, std::size_t>, 2> cap_boundary_runs(int nside);

// Multiplies the pixels of those six rings (all four Stokes maps) by their weights: a whole sky's, or
// the maps of the pixels [first, first + size) of a sky at `nside` (a polar copy's band).
void weigh_cap_boundaries(Sky& sky);
void weigh_cap_boundaries(int nside, std::size_t first, const std::array<std::span<double>, 4>& maps);

// The rotation R that takes the sky to its polar copy: 90 deg about y, (x, y, z) -> (z, y, -x). The
// poles land on the equator at phi = 0 and pi; the old equator's points (+-1, 0, 0) become the poles.
inline constexpr Q4 polar_rotation{0.0, 0.70710678118654752440, 0.0, 0.70710678118654752440};

// The angle from a pole within which a detector's samples go to the polar copy: its disc radius plus
// four pixel sizes, so that no ring within four of the pole meets the disc of a sample left on the
// sky. 0 (never) when that reaches 44 deg: a disc that large would reach the copy's own poles.
double polar_cut(double rho_max, int nside);

// The samples of one submission within `cut` of a pole (the detector's line of sight, its offset
// applied), ascending, and their pointing turned by R as boresight quaternions: q' = R q_boresight, so
// that the detector's q' q_offset = R q. Plate angles follow their samples; input() has sky = 1.
struct PolarSamples {
  std::vector<std::size_t> index;
  std::vector<Quat> quats;
  std::vector<double> plate_angle;
  PointingInput input() const;
};

// Fills `out` (cleared first); returns false when no sample is near a pole. `offset_angle` bounds the
// detector's distance from the boresight (0 on it), so that most samples are passed over without
// composing their rotation.
bool find_polar_samples(const PointingInput& in, const DetectorOffset& offset, double offset_angle, double cut,
                        PolarSamples& out);

// The runs [begin, end) of samples [0, n) that the sky's own pass sums when `polar` (ascending) go to
// the polar copy: every sample but those in runs of at least `gap` consecutive polar samples. A
// shorter run stays in its neighbours' submission: fewer, longer submissions (the adjoint's, whose
// scatter of such a sample is 0; the forward pass, which would sum it twice, gathers the sky's
// samples instead where the runs with gap 1 differ, SkyPass::begin). Empty runs are left out.
std::vector<std::array<std::size_t, 2>> sky_runs(const std::vector<std::size_t>& polar, std::size_t n,
                                                 std::size_t gap = 64);

}  // namespace pisco::detail
