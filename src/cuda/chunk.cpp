#include "cuda/chunk.hpp"

#include <algorithm>
#include <string>

#include "pisco/error.hpp"

namespace pisco::detail::cuda {

std::size_t fit_chunk(std::size_t requested, std::size_t free_device_bytes) {
  if (requested > 0) return std::min(requested, max_chunk_samples);
  const std::size_t fitted = free_device_bytes / 2 / bytes_per_chunk_sample;
  return std::max<std::size_t>(1, std::min(default_chunk_samples, fitted));
}


}  // namespace pisco::detail::cuda
