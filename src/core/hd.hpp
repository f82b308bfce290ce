// Host/device annotation for the functions shared by the float64 reference and the CUDA kernels.
#pragma once

#if defined(__CUDACC__)
#define PISCO_HD __host__ __device__ __forceinline__
#else
#define PISCO_HD inline
#endif
