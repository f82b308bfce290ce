// Chunk sizing for the streamed pointing (docs/cuda.md, "Streaming"): device memory stays bounded by
// the sky, the beams and two chunks whatever the TOD length.
#pragma once

#include <cstddef>

namespace pisco::detail::cuda {

// Device (and pinned host) bytes per sample of chunk capacity: 4 pointing doubles (angles or a
// quaternion) and a plate angle in, the TOD out, two slots.
constexpr std::size_t chunk_slots = 2;
constexpr std::size_t bytes_per_chunk_sample = chunk_slots * 6 * sizeof(double);
// Samples per chunk when the user asks for none: large enough to keep an H100 busy (one chunk is
// ~2 ms of work at 5 deg discs), small enough that the Table 1 workload streams in several chunks so
// that upload, compute and download overlap.
constexpr std::size_t default_chunk_samples = std::size_t(1) << 18;
constexpr std::size_t max_chunk_samples = std::size_t(1) << 30;  // kernel sample indices are 32-bit

// The chunk capacity: `requested` when non-zero (capped at max_chunk_samples), otherwise the default
// capped so that the slots take at most half of `free_device_bytes`; at least 1.
std::size_t fit_chunk(std::size_t requested, std::size_t free_device_bytes);

}  // namespace pisco::detail::cuda
