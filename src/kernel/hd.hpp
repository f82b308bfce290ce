// Host/device annotation for the functions shared by the float64 reference and the CUDA kernels.
#pragma once

#if defined(__CUDACC__)
#define PISCO_HD __host__ __device__ __forceinline__
#else
#define PISCO_HD inline
#endif

namespace pisco::detail {

// A float64 product rounded by itself, never fused with the addition or subtraction it feeds: nvcc
// fuses a * b + c into one fused multiply-add in device code by default (--fmad=true), where the host
// compiles expressions as written (-ffp-contract=off, CMakeLists.txt). The disc's ring bounds
// (kernel/disc.hpp) must be the same values on the host and on the device.
PISCO_HD double mul_rn(double a, double b) {
#if defined(__CUDA_ARCH__)
  return __dmul_rn(a, b);
#else
  return a * b;
#endif
}

}  // namespace pisco::detail
