// pisco::detector_pointing (pisco/pointing.hpp) over part of a chunk, and over a whole chunk on the
// threads of a pool, and angles as quaternions on a pool: the same arithmetic per sample, so the same
// bits whatever the threads.
#pragma once

#include <cstddef>
#include <vector>

#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"

namespace pisco::detail {

class ThreadPool;

// Samples [begin, end) of `out`, which already has the boresight's size.
void detector_pointing_range(const PointingView& boresight, const Quat& offset, Pointing& out, std::size_t begin,
                             std::size_t end);
void detector_pointing_range(const QuatPointingView& boresight, const Quat& offset, Pointing& out, std::size_t begin,
                             std::size_t end);

// The whole chunk, in blocks of samples on the pool's threads; `out` is resized to the boresight's size.
template <class View>
void detector_pointing(const View& boresight, const Quat& offset, Pointing& out, ThreadPool& pool);

// Angle pointing as quaternions (pisco::quat_from_pointing), in blocks of samples on the pool's
// threads; `out` is resized to the pointing's size.
void pointing_quats(const PointingView& pointing, std::vector<Quat>& out, ThreadPool& pool);

}  // namespace pisco::detail
