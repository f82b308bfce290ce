// Owners of device memory, pinned host memory and streams: allocated by the constructor (throwing
// pisco::Error, or DeviceOutOfMemory), released by the destructor.
#pragma once

#include <cuda_runtime_api.h>

#include <cstddef>
#include <utility>
#include <vector>

#include "cuda/check.hpp"

namespace pisco::detail::cuda {

template <class T, bool Pinned>
class Array {
 public:
  Array() = default;
  explicit Array(std::size_t n) : n_(n) {
    if (n == 0) return;
    void* p = nullptr;
    if constexpr (Pinned)
      PISCO_CUDA_CHECK(cudaMallocHost(&p, n * sizeof(T)));
    else
      PISCO_CUDA_CHECK(cudaMalloc(&p, n * sizeof(T)));
    p_ = static_cast<T*>(p);
  }
  ~Array() { release(); }
  Array(Array&& o) noexcept : p_(std::exchange(o.p_, nullptr)), n_(std::exchange(o.n_, 0)) {}
  Array& operator=(Array&& o) noexcept {
    if (this != &o) {
      release();
      p_ = std::exchange(o.p_, nullptr);
      n_ = std::exchange(o.n_, 0);
    }
    return *this;
  }
  Array(const Array&) = delete;
  Array& operator=(const Array&) = delete;

  T* data() const noexcept { return p_; }
  std::size_t size() const noexcept { return n_; }

 private:
  void release() noexcept {
    // Errors are ignored here: a destructor cannot report them, and a lost device frees everything.
    if (p_) {
      if constexpr (Pinned)
        cudaFreeHost(p_);
      else
        cudaFree(p_);
    }
    p_ = nullptr;
  }
  T* p_ = nullptr;
  std::size_t n_ = 0;
};

template <class T>
using DeviceArray = Array<T, false>;
template <class T>
using PinnedArray = Array<T, true>;

// A device array holding a copy of `host` (synchronous: set-up only).
template <class T>
DeviceArray<T> upload(const std::vector<T>& host) {
  DeviceArray<T> d(host.size());
  if (!host.empty())
    PISCO_CUDA_CHECK(cudaMemcpy(d.data(), host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice));
  return d;
}

class Stream {
 public:
  Stream() { PISCO_CUDA_CHECK(cudaStreamCreateWithFlags(&s_, cudaStreamNonBlocking)); }
  ~Stream() {
    if (s_) cudaStreamDestroy(s_);
  }
  Stream(Stream&& o) noexcept : s_(std::exchange(o.s_, nullptr)) {}
  Stream& operator=(Stream&&) = delete;
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
  cudaStream_t get() const noexcept { return s_; }

 private:
  cudaStream_t s_ = nullptr;
};

}  // namespace pisco::detail::cuda
