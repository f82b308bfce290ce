// The convolution kernel (docs/cuda.md, "Kernel"): one warp per sample. The per-sample arithmetic lives in
// sample.hpp, shared with the host tests; this file adds the warp plumbing and the launcher.
#include "cuda/check.hpp"
#include "cuda/convolve.cuh"

#include <type_traits>

namespace pisco::detail::cuda {
namespace {

constexpr int warps_per_block = 8;
constexpr int block_threads = warps_per_block * warp_lanes;
constexpr unsigned full_mask = 0xffffffffu;

// The blocks of block_threads an SM each variant is compiled to hold (__launch_bounds__'s second
// argument; 0 leaves the registers to ptxas): as many as keep its pixel loop free of local memory
// (ptxas spills into the disc walk and the frame instead; tests/cuda/kernel_budgets.py holds every
// pixel loop to no local memory and to its instruction budget). Without a plate: the float32 path 6
// (40 registers a thread, 75% occupancy) on a radial profile, 5 (48, 62.5%) on a 2D grid of two weight
// columns, 4 (64, 50%) of four; the float64 path 4 on a radial profile. Beyond those, or behind a
// plate, local loads enter the loop (docs/cuda.md, "Budgets").
// A build with -DPISCO_CUDA_REGISTERS_BY_VARIANT=OFF (PISCO_CUDA_PTXAS_REGISTERS) leaves every variant
// to ptxas, to be timed beside this one.
template <bool Radial, bool Float64, bool Plate, int Columns>
constexpr int min_blocks() {
#ifdef PISCO_CUDA_PTXAS_REGISTERS
  return 0;
#else
  if (Plate) return 0;
  if (Float64) return Radial ? 4 : 0;
  if (Radial) return 6;
  return Columns == 2 ? 5 : 4;
#endif
}

// Calls f(plate, columns), both std::integral_constant, with the variant a detector's samples take:
// behind a plate always four weight columns (kernel_columns), elsewhere the detector's own layout.
template <class F>
void with_layout(const KernelDetector& det, bool plate, F&& f) {
  if (plate)
    f(std::true_type{}, std::integral_constant<int, 4>{});
  else if (det.columns == 2)
    f(std::false_type{}, std::integral_constant<int, 2>{});
  else
    f(std::false_type{}, std::integral_constant<int, 4>{});
}

template <class T>
__device__ __forceinline__ T warp_sum(T v) {
  // Butterfly: a fixed order, so the result does not depend on timing.
  for (int offset = warp_lanes / 2; offset > 0; offset /= 2) v += __shfl_xor_sync(full_mask, v, offset);
  return v;
}

// The disc d around longitude phi walked by the whole warp, 32 rings a pass, one a lane (sample.hpp, "The
// cooperative disc walk"): each pass's ranges staged in ring order in `begin`/`end` (staging_ranges
// each) with two ballots, and every batch_ranges of them handed to flush(count) with their pixel
// offsets in `offset` (a warp scan), the caps first and last: walk_disc's batches, cut the same way.
// Returns the disc's pixel count.
template <class Flush>
__device__ __forceinline__ std::uint32_t walk_disc_warp(const KernelSky& sky, const KernelDetector& det,
                                                        const DiscRings& d, double phi, std::uint32_t* begin,
                                                        std::uint32_t* end, std::uint32_t* offset, int lane,
                                                        Flush&& flush) {
  std::uint32_t pixels = 0;
  int pending = 0;  // ranges staged, the same in every lane
  // Hands out whole batches, and with `all` the rest as a last one.
  const auto cut = [&](bool all) {
    while (pending >= batch_ranges || (all && pending > 0)) {
      const int count = pending < batch_ranges ? pending : batch_ranges;
      __syncwarp();  // the staged ranges are visible to the warp
      std::uint32_t sum = lane < count ? end[lane] - begin[lane] : 0u;
      for (int o = 1; o < warp_lanes; o *= 2) {
        const std::uint32_t below = __shfl_up_sync(full_mask, sum, o);
        if (lane >= o) sum += below;
      }
      offset[lane + 1] = sum;
      if (lane == 0) offset[0] = 0;
      __syncwarp();
      flush(count);
      pixels += __shfl_sync(full_mask, sum, warp_lanes - 1);
      if (pending > count) unstage_batch(begin, end, pending, lane);
      pending -= count;
      __syncwarp();  // the staging rewritten before the next pass writes into it
    }
  };
  stage_cap(begin, end, pending, lane == 0, [&](auto&& emit) { emit_north_cap(sky.rings, d, emit); });
  for (std::int64_t base = d.first; base <= d.last; base += warp_lanes) {
    RingRanges rr;
    if (base + lane <= d.last) rr = ring_ranges(sky, d, phi, det.cos_rho_max, base + lane);
    const std::uint32_t one = __ballot_sync(full_mask, rr.count >= 1);
    const std::uint32_t two = __ballot_sync(full_mask, rr.count == 2);
    stage_ranges(begin, end, pending, one, two, lane, rr);
    pending += __popc(one) + __popc(two);
    cut(false);
  }
  stage_cap(begin, end, pending, lane == 0, [&](auto&& emit) { emit_south_cap(sky.rings, sky.nside, d, emit); });
  cut(true);
  return pixels;
}

// One sample's frame (sample_frame's bits), line of sight and disc rings, their transcendental
// functions spread over the warp's lanes (sample.hpp, angle_trig): the cosines and sines of the
// pointing's angles on lanes 0 to 5, the line of sight's angles (where they are not the pointing's)
// on lanes 0 and 1, the disc's cosines on lanes 0 to 2, each shuffled to every lane.
__device__ __forceinline__ SampleFrame<double> warp_sample_frame(const KernelSky& sky, const double* pointing,
                                                                 bool quaternions, const KernelDetector& det,
                                                                 int lane, double& theta, double& phi,
                                                                 DiscRings& d) {
  double trig[angle_trig_lanes] = {};
  if (!quaternions) {
    const double mine = lane < angle_trig_lanes ? angle_trig(pointing, lane) : 0.0;
    for (int k = 0; k < angle_trig_lanes; ++k) trig[k] = __shfl_sync(full_mask, mine, k);
  }
  Vec3<double> theta_p, phi_p, p;
  if (!detector_basis(pointing, quaternions, det, trig, theta_p, phi_p, p, theta, phi)) {
    const double mine = lane < 2 ? pisco_direction_angle(p, lane) : 0.0;
    theta = __shfl_sync(full_mask, mine, 0);
    phi = __shfl_sync(full_mask, mine, 1);
  }
  const double mine = lane < 3 ? disc_cos(theta, det.rho_max, lane) : 0.0;
  d = disc_rings_from_cos(sky.nside, theta, det.rho_max, __shfl_sync(full_mask, mine, 0),
                          __shfl_sync(full_mask, mine, 1), __shfl_sync(full_mask, mine, 2));
  return frame_with_zeta(theta_p, phi_p, p, det.cos_zeta, det.sin_zeta);
}

// One warp's sample: its frames (float64, and float32 for the pixels), its plate's Mueller matrix,
// and its disc walked by the warp a batch of ranges at a time in the warp's share of the block's
// shared arrays (walk_disc_warp), with batch(f, fd, first, offset, count, plate) run by the whole warp
// on each batch. Returns the disc's pixel count. Both kernels below start here.
template <bool Plate, class Batch>
__device__ __forceinline__ std::uint32_t walk_warp_sample(const KernelSky& sky, const KernelDetector& det,
                                                          const double* pointing, bool quaternions,
                                                          const double* plate_angle, std::size_t i, int warp,
                                                          int lane, Batch&& batch) {
  __shared__ std::uint32_t begin[warps_per_block][staging_ranges];
  __shared__ std::uint32_t end[warps_per_block][staging_ranges];
  __shared__ std::uint32_t offset[warps_per_block][warp_lanes + 1];
  double theta = 0.0, phi = 0.0;
  DiscRings d;
  const SampleFrame<double> fd = warp_sample_frame(sky, pointing + 4 * i, quaternions, det, lane, theta, phi, d);
  const SampleFrame<float> f = to_float(fd);
  PlateSample plate;
  if constexpr (Plate) plate = plate_sample(det, plate_angle[i]);
  std::uint32_t* my_begin = begin[warp];
  std::uint32_t* my_offset = offset[warp];
  return walk_disc_warp(sky, det, d, phi, my_begin, end[warp], my_offset, lane, [&](int count) {
    batch(f, fd, my_begin, my_offset, count, plate);
    __syncwarp();  // every lane is done with the batch before the staging moves on
  });
}

// With Norms (the adjoint's first pass, PerSample and no Monopole), each sample's normalization is
// written instead of its value. Columns: the float32 weights' layout (sample.hpp, FloatGrid).
template <bool Radial, bool Monopole, bool PerSample, bool Plate, bool Norms, int Columns>
__global__ void __launch_bounds__(block_threads, min_blocks<Radial, Monopole || PerSample, Plate, Columns>())
    convolve_kernel(KernelSky sky, KernelDetector det, ChunkArgs chunk) {
  const int warp = int(threadIdx.x) / warp_lanes;
  const int lane = int(threadIdx.x) % warp_lanes;
  const std::size_t i = std::size_t(blockIdx.x) * warps_per_block + warp;
  if (i >= chunk.count) return;  // whole warps only

  LaneSums acc;
  const std::uint32_t pixels = walk_warp_sample<Plate>(
      sky, det, chunk.pointing, chunk.quaternions, chunk.plate_angle, i, warp, lane,
      [&](const SampleFrame<float>& f, const SampleFrame<double>& fd, const std::uint32_t* first,
          const std::uint32_t* offset, int count, const PlateSample& plate) {
        process_batch<Radial, Monopole, PerSample, Plate, Columns>(sky, det, f, fd, first, offset, count, lane, acc,
                                                                   &plate);
      });

  const float sum = warp_sum(lane_total(acc));
  const double monopole_weight = Monopole ? warp_sum(acc.monopole) : 0.0;
  const double norm = PerSample ? warp_sum(acc.norm) : 0.0;
  if (lane == 0) {
    chunk.tod[i] = Norms ? norm : finish_sample(sum, monopole_weight, norm, sky.monopole, PerSample);
    atomicAdd(chunk.pixels, static_cast<unsigned long long>(pixels));
  }
}

// The adjoint's scatter (sample.hpp, scatter_batch): one warp per sample, its value times each pixel's
// adjoint weights added to the fixed-point maps with integer atomics.
template <bool Radial, bool Float64, bool Plate, bool Squares, int Columns>
__global__ void __launch_bounds__(block_threads, min_blocks<Radial, Float64, Plate, Columns>())
    scatter_kernel(KernelSky sky, KernelDetector det, AdjointArgs chunk) {
  const int warp = int(threadIdx.x) / warp_lanes;
  const int lane = int(threadIdx.x) % warp_lanes;
  const std::size_t i = std::size_t(blockIdx.x) * warps_per_block + warp;
  if (i >= chunk.count) return;  // whole warps only
  const double value = chunk.values[i];
  if (value == 0.0) return;  // the whole warp: nothing to scatter

  auto* sums = reinterpret_cast<unsigned long long*>(chunk.sums);
  const std::uint32_t pixels = walk_warp_sample<Plate>(
      sky, det, chunk.pointing, chunk.quaternions, chunk.plate_angle, i, warp, lane,
      [&](const SampleFrame<float>& f, const SampleFrame<double>& fd, const std::uint32_t* first,
          const std::uint32_t* offset, int count, const PlateSample& plate) {
        scatter_batch<Radial, Float64, Plate, Squares, Columns>(
            sky, det, f, fd, first, offset, count, lane, value, &plate,
            [&](std::size_t k, std::int64_t q) { atomicAdd(sums + k, static_cast<unsigned long long>(q)); });
      });
  if (lane == 0) atomicAdd(chunk.pixels, static_cast<unsigned long long>(pixels));
}

template <bool Radial, bool Float64, bool Plate, int Columns>
void launch_scatter(const KernelSky& sky, const KernelDetector& det, const AdjointArgs& chunk, bool squares,
                    cudaStream_t stream) {
  const unsigned blocks = unsigned((std::size_t(chunk.count) + warps_per_block - 1) / warps_per_block);
  if (squares)
    scatter_kernel<Radial, Float64, Plate, true, Columns><<<blocks, block_threads, 0, stream>>>(sky, det, chunk);
  else
    scatter_kernel<Radial, Float64, Plate, false, Columns><<<blocks, block_threads, 0, stream>>>(sky, det, chunk);
}

template <bool Radial, bool Float64>
void launch_scatter(const KernelSky& sky, const KernelDetector& det, const AdjointArgs& chunk, bool plate, bool squares,
                    cudaStream_t stream) {
  with_layout(det, plate, [&](auto plate_, auto columns) {
    launch_scatter<Radial, Float64, decltype(plate_)::value, decltype(columns)::value>(sky, det, chunk, squares, stream);
  });
}

template <bool Radial>
void launch_scatter(const KernelSky& sky, const KernelDetector& det, const AdjointArgs& chunk, bool float64, bool plate,
                    bool squares, cudaStream_t stream) {
  if (float64)
    launch_scatter<Radial, true>(sky, det, chunk, plate, squares, stream);
  else
    launch_scatter<Radial, false>(sky, det, chunk, plate, squares, stream);
}

template <bool Radial, bool Plate, int Columns>
void launch_norms(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, cudaStream_t stream) {
  const unsigned blocks = unsigned((std::size_t(chunk.count) + warps_per_block - 1) / warps_per_block);
  convolve_kernel<Radial, false, true, Plate, true, Columns><<<blocks, block_threads, 0, stream>>>(sky, det, chunk);
}


template <bool Radial, bool Monopole, bool PerSample, bool Plate, int Columns>
void launch(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, cudaStream_t stream) {
  const unsigned blocks = unsigned((std::size_t(chunk.count) + warps_per_block - 1) / warps_per_block);
  convolve_kernel<Radial, Monopole, PerSample, Plate, false, Columns><<<blocks, block_threads, 0, stream>>>(sky, det,
                                                                                                          chunk);
}

template <bool Radial, bool Monopole, bool PerSample>
void launch(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool plate, cudaStream_t stream) {
  with_layout(det, plate, [&](auto plate_, auto columns) {
    launch<Radial, Monopole, PerSample, decltype(plate_)::value, decltype(columns)::value>(sky, det, chunk, stream);
  });
}

template <bool Radial, bool Monopole>
void launch(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool per_sample, bool plate,
            cudaStream_t stream) {
  if (per_sample)
    launch<Radial, Monopole, true>(sky, det, chunk, plate, stream);
  else
    launch<Radial, Monopole, false>(sky, det, chunk, plate, stream);
}

template <bool Radial>
void launch(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool monopole,
            bool per_sample, bool plate, cudaStream_t stream) {
  if (monopole)
    launch<Radial, true>(sky, det, chunk, per_sample, plate, stream);
  else
    launch<Radial, false>(sky, det, chunk, per_sample, plate, stream);
}

}  // namespace

void launch_norms(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool radial, bool plate,
                  cudaStream_t stream) {
  if (chunk.count == 0) return;
  with_layout(det, plate, [&](auto plate_, auto columns) {
    if (radial)
      launch_norms<true, decltype(plate_)::value, decltype(columns)::value>(sky, det, chunk, stream);
    else
      launch_norms<false, decltype(plate_)::value, decltype(columns)::value>(sky, det, chunk, stream);
  });
  PISCO_CUDA_CHECK(cudaGetLastError());
}

void launch_scatter(const KernelSky& sky, const KernelDetector& det, const AdjointArgs& chunk, bool radial, bool float64,
                    bool plate, bool squares, cudaStream_t stream) {
  if (chunk.count == 0) return;
  if (radial)
    launch_scatter<true>(sky, det, chunk, float64, plate, squares, stream);
  else
    launch_scatter<false>(sky, det, chunk, float64, plate, squares, stream);
  PISCO_CUDA_CHECK(cudaGetLastError());
}

void check_kernel_image(const std::string& device) {
  cudaFuncAttributes attributes{};
  const cudaError_t status = cudaFuncGetAttributes(&attributes, convolve_kernel<false, false, false, false, false, 4>);
  if (status != cudaSuccess) {
    cudaGetLastError();
    throw Error("cuda: the kernel cannot run on " + device + ": " + cudaGetErrorString(status) +
                " (libpisco was built for the CUDA architectures " PISCO_CUDA_ARCHITECTURES
                "; rebuild with -DCMAKE_CUDA_ARCHITECTURES=...)");
  }
}

void launch_convolve(const KernelSky& sky, const KernelDetector& det, const ChunkArgs& chunk, bool radial,
                     bool monopole, bool per_sample, bool plate, cudaStream_t stream) {
  if (chunk.count == 0) return;
  if (radial)
    launch<true>(sky, det, chunk, monopole, per_sample, plate, stream);
  else
    launch<false>(sky, det, chunk, monopole, per_sample, plate, stream);
  PISCO_CUDA_CHECK(cudaGetLastError());
}

}  // namespace pisco::detail::cuda
