// The cuda backend (docs/cuda.md, "Streaming"): the sky, the ring table and the detectors' weights are uploaded once;
// pointing then streams through two slots, each with its own stream, pinned host buffers and device
// buffers, so that while one chunk computes the host fills the other and the copy engines move the
// third's data. The kernel is convolve.cu; what it computes per sample is sample.hpp.
#include <algorithm>
#include <array>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "core/poles.hpp"
#include "core/backend.hpp"
#include "gpu/fixed_point.hpp"
#include "gpu/streaming.hpp"
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
  DeviceArray<double> weights64;  // only on the float64 path
  DeviceArray<double> plate;  // aperture plates with float64 sums: (w_Q, w_U, w_V, 0) per node
  KernelDetector kernel;
};

// One of the two chunk slots.
struct Slot {
  Stream stream;
  PinnedArray<double> host_in, host_out;  // 4 pointing doubles and a plate angle a sample; TOD
  PinnedArray<unsigned long long> host_pixels;
  DeviceArray<double> dev_in, dev_out;
  DeviceArray<unsigned long long> dev_pixels;
  PinnedArray<double> host_values;  // the adjoint's scaled values, made at its first use
  DeviceArray<double> dev_values;
  SlotJob job;
  StagedPointing staged;  // the pointing dev_in holds

  explicit Slot(std::size_t capacity)
      : host_in(5 * capacity), host_out(capacity), host_pixels(1), dev_in(5 * capacity), dev_out(capacity),
        dev_pixels(1) {}
};

class CudaBackend final : public Backend {
 public:
  CudaBackend(std::shared_ptr<const EngineInputs> inputs, const SkyView& maps, const EngineOptions& options)
      : in_(std::move(inputs)), device_(open_device(options.text("device"))) {
    check_kernel_image(device_.description());
    const PreparedSky& sky = in_->sky;
    per_sample_ = in_->normalization == Normalization::per_sample;
    const double monopole = float32_monopole(maps);
    monopole_term_ = monopole != 0.0;

    // Each host table lives only until its upload.
    const CapBoundary boundary = cap_boundary(maps.nside(), in_->quadrature);
    pixels_ = upload(pixel_records(maps, monopole, boundary));
    if (float64()) vectors_ = upload(pixel_vectors(maps));
    rings_ = upload(sky.rings);
    sky_ = {pixels_.data(), vectors_.data(), rings_.data(), sky.nside, monopole, boundary};

    for (const PreparedDetector& d : in_->detectors) {
      DetectorData data;
      const int columns = kernel_columns(d);
      data.weights = upload(float_weights(d, columns));
      if (float64()) data.weights64 = upload(float64_weights(d));
      if (float64() && d.plate == PreparedDetector::Plate::aperture) data.plate = upload(plate_weights(d));
      data.kernel = kernel_detector(d, data.weights.data(), columns, data.weights64.data(), data.plate.data());
      detectors_.push_back(std::move(data));
    }

    std::size_t free_bytes = 0, total_bytes = 0;
    PISCO_CUDA_CHECK(cudaMemGetInfo(&free_bytes, &total_bytes));
    capacity_ = fit_chunk(options.number("chunk_samples"), free_bytes);
    slots_.reserve(chunk_slots);
    capacity_ = fit_chunk_halving<DeviceOutOfMemory>(
        capacity_,
        [&](std::size_t n) {
          for (std::size_t s = 0; s < chunk_slots; ++s) slots_.emplace_back(n);
        },
        [&] { slots_.clear(); }, "cuda: " + device_.description());
    ring_ = SlotRing<Slot>(slots_);
  }

  ~CudaBackend() override {
    for (Slot& s : slots_) cudaStreamSynchronize(s.stream.get());
  }

  std::string name() const override { return "cuda"; }
  std::string device() const override {
    return device_.description() + ", chunks of " + std::to_string(capacity_) + " samples";
  }

  // Beside the sky, on the same device and with the same ring table, read through the sky's pixel
  // numbers (band_indexed).
  void set_polar_sky(const SkyBand& band) override {
    make_current(device_);
    const std::array<std::span<const double>, 4> maps{band.maps[0], band.maps[1], band.maps[2], band.maps[3]};
    polar_pixels_ = upload(pixel_records(band.nside, band.first, maps, sky_.monopole, sky_.boundary));
    if (sky_.vectors) polar_vectors_ = upload(pixel_vectors(band.nside, band.first, band.size()));
    polar_sky_ = sky_;
    polar_sky_.pixels = band_indexed(polar_pixels_.data(), band.first);
    polar_sky_.vectors = sky_.vectors ? band_indexed(polar_vectors_.data(), 4 * band.first) : nullptr;
  }

  void submit(std::size_t detector, const PointingInput& pointing, std::span<double> tod, bool accumulate,
              std::uint64_t ticket) override {
    make_current(device_);
    const DetectorData& det = detectors_.at(detector);
    const bool radial = in_->detectors.at(detector).radial;
    SlotJob current;
    try {
      for (std::size_t offset = 0; offset < pointing.size(); offset += capacity_) {
        const std::size_t count = std::min(capacity_, pointing.size() - offset);
        Slot& s = ring_.acquire([&](Slot& done) {
          current = done.job;
          return complete(done);
        });
        current = SlotJob{false, ticket, detector, offset, pointing.size(), tod.subspan(offset, count), accumulate};
        enqueue(s, det.kernel, radial, in_->detectors.at(detector).plate == PreparedDetector::Plate::aperture,
                pointing.subspan(offset, count));
        s.job = current;
        s.job.busy = true;
      }
    } catch (const Error& e) {
      fail(current, e.what(), e.kind());
    }
  }

  // The adjoint (docs/cuda.md, "The adjoint"): batches of samples, each with its own fixed-point scale
  // (gpu/fixed_point.hpp); with the per-sample normalization, a first pass computes every sample's
  // norm as the forward kernel does, and the host divides the TOD by it before the scale is chosen.
  std::uint64_t adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                        bool squares) override {
    make_current(device_);
    prepare_adjoint();
    if (maps_[0].empty())
      for (auto& m : maps_) m.assign(in_->sky.npix, 0.0);
    return fixed_point_adjoint(
        pointing, tod, adjoint_weight_bound(in_->detectors.at(detector)), squares, per_sample_,
        [&](const PointingInput& part, std::span<double> norms) { adjoint_pass(detector, part, norms, true, squares); },
        [&](const PointingInput& part, std::span<double> values) {
          return adjoint_pass(detector, part, values, false, squares);
        },
        [&](double scale) {
          try {
            const std::size_t bytes = 4 * in_->sky.npix * sizeof(std::int64_t);
            PISCO_CUDA_CHECK(cudaMemcpy(host_sums_.data(), sums_.data(), bytes, cudaMemcpyDeviceToHost));
            PISCO_CUDA_CHECK(cudaMemset(sums_.data(), 0, bytes));
          } catch (const Error& e) {
            throw SubmissionError(detector, std::string(e.what()) + " (device " + device_.description() +
                                                ", the adjoint's maps)",
                                  e.kind());
          }
          fold_fixed_point(host_sums_.data(), in_->sky.npix, scale, maps_);
        });
  }

  void take_adjoint(const std::array<std::span<double>, 4>& maps) override { hand_over_adjoint(maps_, maps); }

  std::uint64_t staged_samples() const override { return pisco::detail::staged_samples(slots_); }

  std::uint64_t wait(std::uint64_t ticket) override {
    make_current(device_);
    SlotJob current;
    try {
      ring_.drain(ticket, [&](Slot& done) {
        current = done.job;
        return complete(done);
      });
    } catch (const Error& e) {
      fail(current, e.what(), e.kind());
    }
    return ring_.take_pixels();
  }

 private:
  std::uint64_t complete(Slot& s) {
    PISCO_CUDA_CHECK(cudaStreamSynchronize(s.stream.get()));
    deliver(s.job, s.host_out.data());
    return *s.host_pixels.data();
  }

  [[noreturn]] void fail(const SlotJob& job, const std::string& what, ErrorKind kind) {
    for (Slot& s : slots_) {
      cudaStreamSynchronize(s.stream.get());
      s.staged.forget();
    }
    ring_.abandon();
    throw SubmissionError(job.detector, what + " (device " + device_.description() + ", detector " +
                                            std::to_string(job.detector) + ", samples " + std::to_string(job.first) +
                                            " to " + std::to_string(job.first + job.tod.size() - 1) +
                                            " of a chunk of " + std::to_string(job.total) + ")",
                          kind);
  }

  // The adjoint's device maps (4 int64 a pixel), their pinned readback and the slots' value buffers.
  void prepare_adjoint() {
    if (sums_.size()) return;
    const std::size_t n = 4 * in_->sky.npix;
    try {
      DeviceArray<std::int64_t> sums(n);
      PISCO_CUDA_CHECK(cudaMemset(sums.data(), 0, n * sizeof(std::int64_t)));
      PinnedArray<std::int64_t> host(n);
      for (Slot& s : slots_) {
        s.host_values = PinnedArray<double>(capacity_);
        s.dev_values = DeviceArray<double>(capacity_);
      }
      sums_ = std::move(sums);
      host_sums_ = std::move(host);
    } catch (const DeviceOutOfMemory& e) {
      throw Error("cuda: out of memory for the adjoint's maps (" + std::to_string(n * sizeof(std::int64_t) >> 20) +
                      " MiB) on " + device_.description() + ": " + e.what(),
                  ErrorKind::device);
    }
  }

  // One pass of the adjoint over `pointing` through the slots: with norms, each sample's
  // normalization into `io`; without, the scatter of the scaled values `io`. Returns the pixels.
  std::uint64_t adjoint_pass(std::size_t detector, const PointingInput& pointing, std::span<double> io, bool norms,
                             bool squares) {
    const DetectorData& det = detectors_.at(detector);
    const PreparedDetector& prepared = in_->detectors.at(detector);
    const bool plate = prepared.plate == PreparedDetector::Plate::aperture;
    SlotJob current;
    const auto complete = [&](Slot& done) {
      current = done.job;
      PISCO_CUDA_CHECK(cudaStreamSynchronize(done.stream.get()));
      if (norms) deliver(done.job, done.host_out.data());
      return *done.host_pixels.data();
    };
    try {
      for (std::size_t offset = 0; offset < pointing.size(); offset += capacity_) {
        const std::size_t count = std::min(capacity_, pointing.size() - offset);
        Slot& s = ring_.acquire(complete);
        current = SlotJob{false, 0, detector, offset, pointing.size(), io.subspan(offset, count), false};
        const PointingInput chunk = pointing.subspan(offset, count);
        const cudaStream_t stream = s.stream.get();
        stage(s, plate, chunk);
        if (norms) {
          const ChunkArgs args{s.dev_in.data(), chunk.quaternions, s.dev_in.data() + 4 * count, s.dev_out.data(),
                               s.dev_pixels.data(), std::uint32_t(count)};
          launch_norms(sky_, det.kernel, args, prepared.radial, plate, stream);
          PISCO_CUDA_CHECK(cudaMemcpyAsync(s.host_out.data(), s.dev_out.data(), count * sizeof(double),
                                           cudaMemcpyDeviceToHost, stream));
        } else {
          std::memcpy(s.host_values.data(), io.data() + offset, count * sizeof(double));
          PISCO_CUDA_CHECK(cudaMemcpyAsync(s.dev_values.data(), s.host_values.data(), count * sizeof(double),
                                           cudaMemcpyHostToDevice, stream));
          const AdjointArgs args{s.dev_in.data(), chunk.quaternions, s.dev_in.data() + 4 * count, s.dev_values.data(),
                                 sums_.data(), s.dev_pixels.data(), std::uint32_t(count)};
          launch_scatter(sky_, det.kernel, args, prepared.radial, float64(), plate, squares, stream);
        }
        PISCO_CUDA_CHECK(cudaMemcpyAsync(s.host_pixels.data(), s.dev_pixels.data(), sizeof(unsigned long long),
                                         cudaMemcpyDeviceToHost, stream));
        s.job = current;
        s.job.busy = true;
      }
      ring_.drain(std::numeric_limits<std::uint64_t>::max(), complete);
    } catch (const Error& e) {
      fail(current, e.what(), e.kind());
    }
    return ring_.take_pixels();
  }

  // Copies a chunk's pointing (4 doubles a sample) and plate angles to the slot's device buffer and
  // clears its pixel counter. Pointing the buffer already holds (PointingInput::shared: the same
  // boresight chunk for another detector) is not copied again; the plate angles, the detector's own,
  // always are.
  void stage(Slot& s, bool plate, const PointingInput& pointing) {
    const cudaStream_t stream = s.stream.get();
    const std::size_t count = pointing.size();
    double* host = s.host_in.data();
    if (s.staged.reuse(pointing.shared, pointing.shared_first, count, pointing.quaternions)) {
      if (plate) {
        std::memcpy(host + 4 * count, pointing.plate_angle.data(), count * sizeof(double));
        PISCO_CUDA_CHECK(cudaMemcpyAsync(s.dev_in.data() + 4 * count, host + 4 * count, count * sizeof(double),
                                         cudaMemcpyHostToDevice, stream));
      }
      PISCO_CUDA_CHECK(cudaMemsetAsync(s.dev_pixels.data(), 0, sizeof(unsigned long long), stream));
      return;
    }
    if (pointing.quaternions) {
      std::memcpy(host, pointing.quats.quats.data(), count * sizeof(Quat));
    } else {
      for (std::size_t i = 0; i < count; ++i) {
        host[4 * i] = pointing.angles.theta[i];
        host[4 * i + 1] = pointing.angles.phi[i];
        host[4 * i + 2] = pointing.angles.psi[i];
        host[4 * i + 3] = 0.0;
      }
    }
    // The plate angles after the pointing, in the same copy.
    if (plate) std::memcpy(host + 4 * count, pointing.plate_angle.data(), count * sizeof(double));
    const std::size_t doubles = (plate ? 5 : 4) * count;
    PISCO_CUDA_CHECK(cudaMemcpyAsync(s.dev_in.data(), host, doubles * sizeof(double), cudaMemcpyHostToDevice, stream));
    PISCO_CUDA_CHECK(cudaMemsetAsync(s.dev_pixels.data(), 0, sizeof(unsigned long long), stream));
  }

  void enqueue(Slot& s, const KernelDetector& det, bool radial, bool plate, const PointingInput& pointing) {
    const cudaStream_t stream = s.stream.get();
    const std::size_t count = pointing.size();
    stage(s, plate, pointing);
    const ChunkArgs args{s.dev_in.data(), pointing.quaternions, s.dev_in.data() + 4 * count, s.dev_out.data(),
                         s.dev_pixels.data(), std::uint32_t(count)};
    launch_convolve(pointing.sky ? polar_sky_ : sky_, det, args, radial, monopole_term_, per_sample_, plate, stream);
    PISCO_CUDA_CHECK(
        cudaMemcpyAsync(s.host_out.data(), s.dev_out.data(), count * sizeof(double), cudaMemcpyDeviceToHost, stream));
    PISCO_CUDA_CHECK(cudaMemcpyAsync(s.host_pixels.data(), s.dev_pixels.data(), sizeof(unsigned long long),
                                     cudaMemcpyDeviceToHost, stream));
  }

  std::shared_ptr<const EngineInputs> in_;
  DeviceContext device_;
  bool per_sample_ = false, monopole_term_ = false;
  // The float64 path: the monopole's weight or the per-sample normalization summed in float64.
  bool float64() const { return monopole_term_ || per_sample_; }
  DeviceArray<PixelRecord> pixels_;
  DeviceArray<double> vectors_;
  DeviceArray<RingEntry> rings_;
  KernelSky sky_{};
  // The polar copy's band (set_polar_sky).
  DeviceArray<PixelRecord> polar_pixels_;
  DeviceArray<double> polar_vectors_;
  KernelSky polar_sky_{};
  std::vector<DetectorData> detectors_;
  std::size_t capacity_ = 0;
  std::vector<Slot> slots_;
  SlotRing<Slot> ring_;
  DeviceArray<std::int64_t> sums_;      // the adjoint's fixed-point maps, 4 a pixel
  PinnedArray<std::int64_t> host_sums_;
  std::array<std::vector<double>, 4> maps_;  // the adjoint's float64 maps, I Q U V
};

}  // namespace
}  // namespace cuda

void attach_cuda_backend(BackendEntry& e) {
  e.probe = [] { return cuda::probe(); };
  e.create = [](std::shared_ptr<const EngineInputs> in, const SkyView& sky,
                const EngineOptions& o) -> std::unique_ptr<Backend> {
    return std::make_unique<cuda::CudaBackend>(std::move(in), sky, o);
  };
}

}  // namespace pisco::detail
