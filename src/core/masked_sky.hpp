// Masked skies in the engine (docs/physics.md, "Masked skies"): the UNSEEN pixels of the sky taken as
// 0 in what the backends get, and, under UnseenPolicy::flag, the samples whose disc holds one flagged
// with the disc selection of the convolution itself (kernel/disc.hpp).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/prepared.hpp"
#include "pisco/engine.hpp"
#include "pisco/sky.hpp"

namespace pisco::detail {

// The sky the backends get under `policy`: `sky` itself when it has no UNSEEN pixel; else, for zero
// and flag, a copy in `zeroed` with those pixels 0, their RING indices (ascending) in `masked` (flag
// only); for error, pisco::Error naming the Stokes map, the number of UNSEEN pixels and the first.
// `unseen` is their number.
SkyView sky_for_backends(const SkyView& sky, UnseenPolicy policy, std::optional<Sky>& zeroed,
                            std::vector<std::uint32_t>& masked, std::size_t& unseen);

// Whether the disc of detector `det` around each sample holds a pixel of `masked` (ascending RING
// indices): flags[i] = 1 or 0; returns the number flagged. The line of sight of each sample is the
// reference backend's (kernel/frame.hpp), the disc the convolution's (for_each_disc_range), and each
// ring range is looked up in `masked` by bisection.
std::size_t flag_discs(const PreparedSky& sky, const PreparedDetector& det, const std::vector<std::uint32_t>& masked,
                       const PointingView& boresight, std::span<std::uint8_t> flags);
std::size_t flag_discs(const PreparedSky& sky, const PreparedDetector& det, const std::vector<std::uint32_t>& masked,
                       const QuatPointingView& boresight, std::span<std::uint8_t> flags);

}  // namespace pisco::detail
