#include "cuda/context.hpp"

#include <cuda_runtime_api.h>

#include <cstdio>

#include "cuda/check.hpp"
#include "cuda/device_choice.hpp"

namespace pisco::detail::cuda {
namespace {

DeviceContext describe(int index) {
  cudaDeviceProp p{};
  PISCO_CUDA_CHECK(cudaGetDeviceProperties(&p, index));
  return {index, p.name, p.major, p.minor, p.multiProcessorCount, p.totalGlobalMem};
}

std::vector<std::string> device_names() {
  int n = 0;
  PISCO_CUDA_CHECK(cudaGetDeviceCount(&n));
  std::vector<std::string> names;
  for (int i = 0; i < n; ++i) names.push_back(describe(i).name);
  return names;
}

}  // namespace

std::string DeviceContext::description() const {
  char mem[32];
  std::snprintf(mem, sizeof mem, "%.1f GiB", double(memory) / double(1ull << 30));
  return name + " (device " + std::to_string(index) + ", sm_" + std::to_string(sm_major) +
         std::to_string(sm_minor) + ", " + std::to_string(multiprocessors) + " SMs, " + mem + ")";
}

BackendInfo probe() {
  int n = 0;
  const cudaError_t status = cudaGetDeviceCount(&n);
  if (status != cudaSuccess) {
    cudaGetLastError();
    return {"cuda", false, std::string(cudaGetErrorString(status)) + " (" + cudaGetErrorName(status) + ")", {}, {}};
  }
  if (n == 0) return {"cuda", false, "no CUDA-capable device is detected", {}, {}};
  try {
    std::string detail;
    for (int i = 0; i < n; ++i) detail += (i ? "; " : "") + describe(i).description();
    BackendInfo info{"cuda", true, detail, {}, {}};
    for (int i = 0; i < n; ++i) info.devices.push_back(std::size_t(i));
    info.capabilities.device_memory = describe(0).memory;
    info.capabilities.adjoint = true;  // 64-bit integer atomics, on every architecture CUDA builds for
    return info;
  } catch (const Error& e) {
    return {"cuda", false, e.what(), {}, {}};
  }
}

DeviceContext open_device(const std::string& request) {
  const int index = choose_device(device_names(), request);
  DeviceContext d = describe(index);
  make_current(d);
  return d;
}

void make_current(const DeviceContext& device) { PISCO_CUDA_CHECK(cudaSetDevice(device.index)); }

}  // namespace pisco::detail::cuda
