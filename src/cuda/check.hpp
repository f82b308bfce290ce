// Every CUDA runtime call goes through PISCO_CUDA_CHECK, which throws pisco::Error naming the call,
// the file and line, and the runtime's own message. Out-of-memory is its own type so that the driver
// can retry with smaller chunks (docs/formats.md, "Errors and partial files").
#pragma once

#include <cuda_runtime_api.h>

#include <string>

#include "pisco/error.hpp"

namespace pisco::detail::cuda {

class DeviceOutOfMemory : public Error {
 public:
  using Error::Error;
};

[[noreturn]] inline void throw_cuda_error(cudaError_t status, const char* call, const char* file, int line) {
  std::string message = std::string("CUDA: ") + call + " failed at " + file + ":" + std::to_string(line) +
                        ": " + cudaGetErrorString(status) + " (" + cudaGetErrorName(status) + ")";
  if (status == cudaErrorMemoryAllocation) {
    cudaGetLastError();  // not sticky: clear it so that a retry starts clean
    throw DeviceOutOfMemory(message, ErrorKind::device);
  }
  const bool absent = status == cudaErrorNoDevice || status == cudaErrorInsufficientDriver ||
                      status == cudaErrorNoKernelImageForDevice;
  throw Error(message, absent ? ErrorKind::unavailable : ErrorKind::device);
}

}  // namespace pisco::detail::cuda

#define PISCO_CUDA_CHECK(call)                                                              \
  do {                                                                                      \
    const cudaError_t pisco_cuda_status_ = (call);                                          \
    if (pisco_cuda_status_ != cudaSuccess)                                                  \
      ::pisco::detail::cuda::throw_cuda_error(pisco_cuda_status_, #call, __FILE__, __LINE__); \
  } while (0)
