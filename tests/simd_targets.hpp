// The simd backend's instruction sets this machine runs, for the tests that run each of them
// (test_simd_disc, test_simd_kernel).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "pisco/error.hpp"
#include "simd/simd_kernel.hpp"

namespace pisco_test {

// Highway's names and the simd backend's kernels, best first.
inline std::vector<std::pair<std::string, pisco::detail::simd::Kernel>> simd_kernels() {
  std::vector<std::pair<std::string, pisco::detail::simd::Kernel>> out;
  for (const char* name : {"AVX3", "AVX2", "SSE4", "EMU128", "NEON", "SCALAR"}) {
    try {
      out.emplace_back(name, pisco::detail::simd::choose_kernel(name));
    } catch (const pisco::Error&) {
    }
  }
  return out;
}

}  // namespace pisco_test
