// The cuda backend (DESIGN 7): the sky, the ring table and the detectors' weights are uploaded once;
// pointing then streams through two slots, each with its own stream, pinned host buffers and device
// buffers, so that while one chunk computes the host fills the other and the copy engines move the
// third's data. The kernel is convolve.cu; what it computes per sample is sample.hpp.
#include <algorithm>
#include <cstring>
#include <memory>

#include "core/backend.hpp"
#include "cuda/buffer.hpp"
#include "cuda/check.hpp"
#include "cuda/chunk.hpp"
#include "cuda/context.hpp"
#include "cuda/convolve.cuh"
#include "cuda/device_data.hpp"

namespace pisco::detail {
namespace cuda {
namespace {

struct DetectorData {
  DeviceArray<float> weights;
  DeviceArray<double> exact;  // only where float64 sums are needed
  KernelDetector kernel;
};

// One of the two chunk slots.
struct Slot {
  Stream stream;
  PinnedArray<double> host_in, host_out;  // theta | phi | psi, each `capacity` long; TOD
  PinnedArray<unsigned long long> host_pixels;
  DeviceArray<double> dev_in, dev_out;
  DeviceArray<unsigned long long> dev_pixels;
  std::size_t offset = 0, count = 0;
  bool busy = false;

  explicit Slot(std::size_t capacity)
      : host_in(3 * capacity), host_out(capacity), host_pixels(1), dev_in(3 * capacity), dev_out(capacity),
        dev_pixels(1) {}
};

class CudaBackend final : public Backend {
 public:
  CudaBackend(std::shared_ptr<const EngineInputs> inputs, const EngineOptions& options)
      : in_(std::move(inputs)), device_(open_device(options.device)) {
    check_kernel_image(device_.description());
    const PreparedSky& sky = in_->sky;
    per_sample_ = in_->normalization == Normalization::per_sample;
    const double monopole = float32_monopole(sky);
    monopole_term_ = monopole != 0.0;
    const bool exact = monopole_term_ || per_sample_;

    pixels_ = upload(pixel_records(sky, monopole));
    if (exact) vectors_ = upload(pixel_vectors(sky));
    rings_ = upload(sky.rings);
    sky_ = {pixels_.data(), vectors_.data(), rings_.data(), sky.nside, monopole};

    for (const PreparedDetector& d : in_->detectors) {
      DetectorData data;
      data.weights = upload(float_weights(d));
      if (exact) data.exact = upload(exact_weights(d));
      data.kernel = kernel_detector(d, data.weights.data(), data.exact.data());
      detectors_.push_back(std::move(data));
    }

    std::size_t free_bytes = 0, total_bytes = 0;
    PISCO_CUDA_CHECK(cudaMemGetInfo(&free_bytes, &total_bytes));
    capacity_ = fit_chunk(options.chunk_samples, free_bytes);
    slots_.reserve(chunk_slots);
    for (;;) {
      try {
        for (std::size_t s = 0; s < chunk_slots; ++s) slots_.emplace_back(capacity_);
        break;
      } catch (const DeviceOutOfMemory&) {
        slots_.clear();
        capacity_ = halve_chunk(capacity_);
      }
    }
  }

  ~CudaBackend() override {
    for (Slot& s : slots_) cudaStreamSynchronize(s.stream.get());
  }

  std::string name() const override { return "cuda"; }
  std::string device() const override {
    return device_.description() + ", chunks of " + std::to_string(capacity_) + " samples";
  }

  std::uint64_t convolve(std::size_t detector, const PointingView& pointing, std::span<double> tod) override {
    make_current(device_);
    const DetectorData& det = detectors_.at(detector);
    const bool radial = in_->detectors.at(detector).radial;
    std::uint64_t pixels = 0;
    auto finish = [&](Slot& s) {
      PISCO_CUDA_CHECK(cudaStreamSynchronize(s.stream.get()));
      std::memcpy(tod.data() + s.offset, s.host_out.data(), s.count * sizeof(double));
      pixels += *s.host_pixels.data();
      s.busy = false;
    };
    try {
      std::size_t chunk = 0, count = 0;
      for (std::size_t offset = 0; offset < pointing.size(); offset += count, ++chunk) {
        Slot& s = slots_[chunk % slots_.size()];
        if (s.busy) finish(s);  // the chunk two back: its buffers are free again
        count = std::min(capacity_, pointing.size() - offset);
        s.offset = offset;
        s.count = count;
        enqueue(s, det.kernel, radial, pointing, offset, count);
        s.busy = true;
      }
      for (std::size_t k = 0; k < slots_.size(); ++k) {  // oldest first
        Slot& s = slots_[(chunk + k) % slots_.size()];
        if (s.busy) finish(s);
      }
    } catch (...) {
      for (Slot& s : slots_) {
        cudaStreamSynchronize(s.stream.get());
        s.busy = false;
      }
      throw;
    }
    return pixels;
  }

 private:
  void enqueue(Slot& s, const KernelDetector& det, bool radial, const PointingView& pointing,
               std::size_t offset, std::size_t count) {
    const cudaStream_t stream = s.stream.get();
    const std::size_t bytes = count * sizeof(double);
    double* host = s.host_in.data();
    double* dev = s.dev_in.data();
    const double* sources[3] = {pointing.theta.data(), pointing.phi.data(), pointing.psi.data()};
    for (std::size_t a = 0; a < 3; ++a) {
      std::memcpy(host + a * capacity_, sources[a] + offset, bytes);
      PISCO_CUDA_CHECK(
          cudaMemcpyAsync(dev + a * capacity_, host + a * capacity_, bytes, cudaMemcpyHostToDevice, stream));
    }
    PISCO_CUDA_CHECK(cudaMemsetAsync(s.dev_pixels.data(), 0, sizeof(unsigned long long), stream));
    const ChunkArgs args{dev, dev + capacity_, dev + 2 * capacity_, s.dev_out.data(), s.dev_pixels.data(),
                         std::uint32_t(count)};
    launch_convolve(sky_, det, args, radial, monopole_term_, per_sample_, stream);
    PISCO_CUDA_CHECK(cudaMemcpyAsync(s.host_out.data(), s.dev_out.data(), bytes, cudaMemcpyDeviceToHost, stream));
    PISCO_CUDA_CHECK(cudaMemcpyAsync(s.host_pixels.data(), s.dev_pixels.data(), sizeof(unsigned long long),
                                     cudaMemcpyDeviceToHost, stream));
  }

  std::shared_ptr<const EngineInputs> in_;
  DeviceContext device_;
  bool per_sample_ = false, monopole_term_ = false;
  DeviceArray<PixelRecord> pixels_;
  DeviceArray<double> vectors_;
  DeviceArray<RingEntry> rings_;
  KernelSky sky_{};
  std::vector<DetectorData> detectors_;
  std::size_t capacity_ = 0;
  std::vector<Slot> slots_;
};

}  // namespace
}  // namespace cuda

BackendEntry cuda_backend_entry() {
  // Above vulkan and cpu: on an NVIDIA machine "auto" runs the native backend.
  return {"cuda", 20, [] { return cuda::probe(); },
          [](std::shared_ptr<const EngineInputs> in, const EngineOptions& o) -> std::unique_ptr<Backend> {
            return std::make_unique<cuda::CudaBackend>(std::move(in), o);
          }};
}

}  // namespace pisco::detail
