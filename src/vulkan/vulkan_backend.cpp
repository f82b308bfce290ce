// The vulkan backend (docs/vulkan.md; docs/physics.md, "Disc selection" and "Device backends"): the sky, ring table and weight grids are uploaded once; pointing
// then streams through two slots of bounded size, so that the host fills one chunk and reads the
// previous one back while the device convolves the other. Device memory is sky + beams + two chunks,
// whatever the length of the TOD.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <thread>
#include <limits>
#include <memory>
#include <numbers>

#include "adjoint.spv.h"
#include "adjoint_ff.spv.h"
#include "convolve.spv.h"
#include "convolve_ff.spv.h"
#include "core/backend.hpp"
#include "gpu/fixed_point.hpp"
#include "gpu/streaming.hpp"
#include "pisco/quaternion.hpp"
#include "interface.h"
#include "vulkan/buffer.hpp"
#include "vulkan/check.hpp"
#include "vulkan/context.hpp"
#include "vulkan/pipeline.hpp"
#include "vulkan/tables.hpp"
#include "vulkan/vulkan_options.hpp"

namespace pisco::detail {
namespace {

using vk::Buffer;
using vk::MemoryUse;

constexpr std::size_t default_chunk = std::size_t(1) << 18;  // samples: 6 MiB of pointing per slot
constexpr VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;

double mib(double bytes) { return bytes / double(1 << 20); }

class VulkanBackend final : public Backend {
 public:
  VulkanBackend(std::shared_ptr<const EngineInputs> inputs, const SkyView& sky, const EngineOptions& options);
  ~VulkanBackend() override;

  std::string name() const override { return "vulkan"; }
  std::string device() const override {
    const std::string forced = mode_.ff && device_->info().float64 ? ", float-float kernel (asked for)" : "";
    return device_->info().describe() + forced + ", chunks of " + std::to_string(chunk_) + " samples" +
           (device_->instance().validation() ? ", with the Khronos validation layer" : "");
  }
  void submit(std::size_t detector, const PointingInput& pointing, std::span<double> tod, bool accumulate,
              std::uint64_t ticket) override;
  std::uint64_t wait(std::uint64_t ticket) override;
  void set_polar_sky(const SkyBand& band) override;
  std::uint64_t adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                        bool squares) override;
  void take_adjoint(const std::array<std::span<double>, 4>& maps) override;
  std::uint64_t staged_samples() const override { return pisco::detail::staged_samples(slots_); }

 private:
  struct Slot {
    Buffer pointing, tod, counts, plate;
    VkCommandBuffer cmd = VK_NULL_HANDLE;
    VkFence fence = VK_NULL_HANDLE;
    VkDescriptorSet set = VK_NULL_HANDLE;
    VkDescriptorSet polar_set = VK_NULL_HANDLE;  // the same with the polar copy's band as the sky
    SlotJob job;
    StagedPointing staged;  // the samples `pointing` holds
    // The adjoint's, made at its first use: the scaled values, and the set with the maps.
    Buffer values;
    VkDescriptorSet adjoint_set = VK_NULL_HANDLE;
  };
  // The adjoint's device state (docs/vulkan.md, "The adjoint"), made at its first use: the kernel, the
  // fixed-point maps and their readback, and the float64 maps they are folded into.
  struct Adjoint {
    std::unique_ptr<vk::ComputePipeline> pipeline;
    Buffer sums, readback;  // 4 int64 a pixel
    VkCommandBuffer cmd = VK_NULL_HANDLE;
    VkFence fence = VK_NULL_HANDLE;
    std::array<std::vector<double>, 4> maps;  // I, Q, U, V
  };

  void setup(const vk::DeviceInfo& info, const SkyView& sky, const vk::VulkanOptions& settings);
  void release() noexcept;
  // A device-local uniform texel buffer holding `bytes` of `data`, viewed as R32G32B32A32_UINT texels
  // (src/kernel/interface.h): every table the kernel reads.
  Buffer upload(const void* data, std::size_t bytes, const char* what);
  // The same for a table of `count` records of `record_bytes`, packed straight into a bounded staging
  // buffer piece by piece: fill(first, n, dst) writes records [first, first + n) to dst. No host copy
  // of the whole table is ever made.
  Buffer upload_records(std::size_t count, std::size_t record_bytes,
                        const std::function<void(std::size_t, std::size_t, void*)>& fill, const char* what);
  void upload_sky(int nside, const std::array<std::span<const double>, 4>& maps, std::size_t first, Buffer& records,
                  Buffer& lo, const std::string& what);
  void make_slots(std::size_t chunk);
  // The buffers of a slot's descriptor sets by binding: the first PISCO_BINDINGS the forward kernel's,
  // all of them the adjoint's.
  std::array<const Buffer*, PISCO_ADJOINT_BINDINGS> bindings(const Slot& s) const;
  // A command buffer from the pool and an unsignalled fence for it.
  void make_command(VkCommandBuffer& cmd, VkFence& fence);
  double disc_pixels(const PreparedDetector& det) const;  // about how many sky pixels a disc holds
  vk::ComputePipeline::Specialization specialization(std::size_t detector) const;
  vk::PushConstants push_constants(std::size_t detector, bool quaternions) const;
  void dispatch(Slot& slot, vk::ComputePipeline& pipeline, VkDescriptorSet set,
                const vk::ComputePipeline::Specialization& spec, const vk::PushConstants& push,
                const PointingInput& pointing);
  // Waits for the slot's work; delivers its results to the job's span unless told not to (the
  // adjoint's scatter has none). Returns the pixels its samples' discs held.
  std::uint64_t collect(Slot& slot, bool results = true);
  // Samples per chunk for a detector: at most chunk_ and about 1e9 pixel evaluations.
  std::size_t chunk_for(const PreparedDetector& det) const;
  void prepare_adjoint();
  // One pass of the adjoint kernel over `pointing` through the slots: with norms, each sample's
  // normalization into `io`; without, the scatter of the scaled values `io`. Returns the pixels.
  std::uint64_t adjoint_pass(std::size_t detector, const PointingInput& pointing, std::span<double> io, bool norms,
                             bool squares);
  // Adds the fixed-point sums times 1/scale into the float64 maps and clears them.
  void fold(double scale);
  // Forgets every slot in flight after an error, once the device has finished with them.
  void abandon() noexcept;
  // abandon(), then the error with its context.
  [[noreturn]] void fail(const SlotJob& job, const std::string& what, ErrorKind kind);

  std::shared_ptr<const EngineInputs> in_;
  std::unique_ptr<vk::Device> device_;
  std::unique_ptr<vk::ComputePipeline> pipeline_;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  Buffer sky_, sky_lo_, rings_, weights_, weights64_;
  // The polar copy's band in the sky's layout (set_polar_sky): its tables start at pixel polar_first_.
  Buffer polar_sky_, polar_sky_lo_;
  std::uint32_t polar_first_ = 0;
  vk::Grids grids_;      // the beam grids' offsets and layouts (their tables are on the device)
  vk::KernelMode mode_;  // the float64 path, and float-float or float64 numbers
  std::size_t chunk_ = 0;
  std::array<Slot, 2> slots_;
  SlotRing<Slot> ring_{slots_};
  Adjoint adjoint_;
  long lose_device_after_ = vk::injected_faults().lose_device_after;
  long completed_chunks_ = 0;
};

VulkanBackend::VulkanBackend(std::shared_ptr<const EngineInputs> inputs, const SkyView& sky, const EngineOptions& options)
    : in_(std::move(inputs)) {
  const vk::VulkanOptions settings = vk::vulkan_options(options);
  auto instance = vk::Instance::get();
  const vk::DeviceInfo info = vk::choose_device(vk::enumerate_devices(*instance), settings.device);
  device_ = std::make_unique<vk::Device>(std::move(instance), info);
  try {
    setup(info, sky, settings);
  } catch (const Error& e) {
    release();  // the destructor does not run for a constructor that throws
    throw Error(std::string(e.what()) + " (device " + info.describe() + ")", e.kind());
  } catch (...) {
    release();
    throw;
  }
}

void VulkanBackend::setup(const vk::DeviceInfo& info, const SkyView& sky_maps, const vk::VulkanOptions& settings) {
  const auto& fn = device_->fn();

  VkCommandPoolCreateInfo pi{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pi.queueFamilyIndex = info.queue_family;
  PISCO_VK(fn.vkCreateCommandPool(device_->handle(), &pi, nullptr, &pool_));
  const bool ff = vk::use_float_float(info.float64, info.name, settings.arithmetic);
  const std::span<const std::uint32_t> spirv =
      ff ? std::span<const std::uint32_t>(pisco_spv_convolve_ff, sizeof(pisco_spv_convolve_ff) / sizeof(std::uint32_t))
         : std::span<const std::uint32_t>(pisco_spv_convolve, sizeof(pisco_spv_convolve) / sizeof(std::uint32_t));
  // A set a slot for the sky, another for its polar copy.
  pipeline_ = std::make_unique<vk::ComputePipeline>(*device_, spirv, PISCO_BINDINGS, std::uint32_t(2 * slots_.size()));

  // The sky in float32 without its monopole I0, which float32 cannot carry next to micro-kelvin
  // anisotropies (docs/vulkan.md, "Precision"): I0 sum_k w_I(k) is added back by the kernel's float64
  // path. Packed from the maps straight into the staging buffer, a piece at a time.
  const PreparedSky& sky = in_->sky;
  const std::size_t npix = sky.npix;
  mode_ = vk::kernel_mode(*in_, sky_maps, ff);

  // Texel indices are signed 32-bit integers in the kernel.
  double max_texels = std::min(double(info.max_texel_buffer_elements), double(std::numeric_limits<std::int32_t>::max()));
  if (const std::size_t f = vk::injected_faults().texels_max) max_texels = std::min(max_texels, double(f));
  if (2.0 * double(npix) > max_texels)
    throw Error("vulkan: an NSIDE " + std::to_string(sky.nside) + " sky needs " + std::to_string(2 * npix) +
                " texels in one texel buffer, but " + info.name + " binds at most " +
                std::to_string(std::uint64_t(max_texels)) + " (maxTexelBufferElements); use the cpu backend", ErrorKind::device);
  upload_sky(sky.nside, {sky_maps.I(), sky_maps.Q(), sky_maps.U(), sky_maps.V()}, 0, sky_, sky_lo_, "the sky");
  const std::vector<std::uint32_t> rings = vk::pack_rings(sky, mode_.boundary, mode_.ff);
  rings_ = upload(rings.data(), rings.size() * sizeof(std::uint32_t), "the ring table");

  grids_ = vk::pack_grids(*in_, mode_);
  // The float32 grids take at least one texel a node, the float64 ones exactly one.
  if (double(grids_.w32.size() / 4) > max_texels)
    throw Error("vulkan: the beam grids need " + std::to_string(grids_.w32.size() / 4) + " texels, but " + info.name +
                " binds at most " + std::to_string(std::uint64_t(max_texels)) +
                " (maxTexelBufferElements); use a coarser grid_step", ErrorKind::device);
  weights_ = upload(grids_.w32.data(), grids_.w32.size() * sizeof(float), "the beam grids");
  weights64_ = upload(grids_.w64.data(), grids_.w64.size() * sizeof(double), "the float64 beam grids");
  // Only the offsets and layouts stay on the host.
  grids_.w32 = {};
  grids_.w64 = {};

  // Chunks: as asked, or the default, within the device's buffer range and dispatch limits.
  const std::size_t by_range = info.max_storage_buffer_range / (4 * sizeof(double));
  const std::size_t by_groups = std::size_t(info.max_groups_x) * info.max_groups_y;  // one sample per group at worst
  std::size_t chunk = settings.chunk_samples ? settings.chunk_samples : default_chunk;
  chunk = std::max<std::size_t>(1, std::min({chunk, by_range, by_groups}));
  make_slots(chunk);
  // Compile, at set-up, the pipelines the detectors will use.
  for (std::size_t d = 0; d < in_->detectors.size(); ++d) pipeline_->prepare(specialization(d));
  device_->check_validation("setting up");
}

Buffer VulkanBackend::upload(const void* data, std::size_t bytes, const char* what) {
  return upload_records(
      bytes, 1, [&](std::size_t first, std::size_t n, void* dst) { std::memcpy(dst, static_cast<const char*>(data) + first, n); },
      what);
}

Buffer VulkanBackend::upload_records(std::size_t count, std::size_t record_bytes,
                                     const std::function<void(std::size_t, std::size_t, void*)>& fill,
                                     const char* what) {
  const auto& fn = device_->fn();
  const std::size_t bytes = count * record_bytes;
  try {
    // Staging of at most 64 MiB (whole texels and records), reused for every piece.
    const std::size_t per_piece = std::max<std::size_t>(1, std::min(count, (std::size_t(64) << 20) / record_bytes / 16 * 16));
    Buffer staging(*device_, per_piece * record_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::upload);
    Buffer target(*device_, bytes, VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                  MemoryUse::device);
    target.make_texel_view(VK_FORMAT_R32G32B32A32_UINT);
    VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    ai.commandPool = pool_;
    ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ai.commandBufferCount = 1;
    VkCommandBuffer cmd = VK_NULL_HANDLE;
    PISCO_VK(fn.vkAllocateCommandBuffers(device_->handle(), &ai, &cmd));
    // Whatever happens below, the copy is finished (or abandoned) before the buffers go.
    struct Guard {
      const vk::Device& device;
      VkCommandPool pool;
      VkCommandBuffer cmd;
      ~Guard() {
        device.fn().vkDeviceWaitIdle(device.handle());
        device.fn().vkFreeCommandBuffers(device.handle(), pool, 1, &cmd);
      }
    } guard{*device_, pool_, cmd};
    for (std::size_t first = 0; first < count; first += per_piece) {
      const std::size_t n = std::min(per_piece, count - first);
      fill(first, n, staging.mapped());
      PISCO_VK(fn.vkResetCommandBuffer(cmd, 0));
      VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
      bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
      PISCO_VK(fn.vkBeginCommandBuffer(cmd, &bi));
      const VkBufferCopy region{0, first * record_bytes, n * record_bytes};
      fn.vkCmdCopyBuffer(cmd, staging.handle(), target.handle(), 1, &region);
      VkMemoryBarrier barrier{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
      barrier.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
      barrier.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
      fn.vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &barrier,
                              0, nullptr, 0, nullptr);
      PISCO_VK(fn.vkEndCommandBuffer(cmd));
      VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
      si.commandBufferCount = 1;
      si.pCommandBuffers = &cmd;
      PISCO_VK(fn.vkQueueSubmit(device_->queue(), 1, &si, VK_NULL_HANDLE));
      PISCO_VK(fn.vkQueueWaitIdle(device_->queue()));
    }
    return target;
  } catch (const vk::OutOfMemory& e) {
    throw Error("vulkan: out of memory uploading " + std::string(what) + " (" + std::to_string(int(mib(double(bytes)))) +
                " MiB) to " + device_->info().name + ": " + e.what(), ErrorKind::device);
  }
}

// Two slots of `chunk` samples; on out-of-memory, half the chunk, down to one sample.
std::array<const Buffer*, PISCO_ADJOINT_BINDINGS> VulkanBackend::bindings(const Slot& s) const {
  std::array<const Buffer*, PISCO_ADJOINT_BINDINGS> b{};
  b[PISCO_BINDING_SKY] = &sky_;
  b[PISCO_BINDING_SKY_LO] = &sky_lo_;
  b[PISCO_BINDING_RINGS] = &rings_;
  b[PISCO_BINDING_WEIGHTS] = &weights_;
  b[PISCO_BINDING_WEIGHTS64] = &weights64_;
  b[PISCO_BINDING_POINTING] = &s.pointing;
  b[PISCO_BINDING_TOD] = &s.tod;
  b[PISCO_BINDING_COUNT] = &s.counts;
  b[PISCO_BINDING_PLATE] = &s.plate;
  b[PISCO_BINDING_MAPS] = &adjoint_.sums;
  b[PISCO_BINDING_VALUES] = &s.values;
  return b;
}

void VulkanBackend::make_slots(std::size_t chunk) {
  chunk = fit_chunk_halving<vk::OutOfMemory>(
      chunk,
      [&](std::size_t n) {
        for (Slot& s : slots_) {
          s.staged.forget();
          s.pointing = Buffer(*device_, n * 4 * sizeof(double), storage, MemoryUse::upload);
          s.tod = Buffer(*device_, n * sizeof(double), storage, MemoryUse::readback);
          s.counts = Buffer(*device_, n * sizeof(std::uint32_t), storage, MemoryUse::readback);
          // float64: the plate's angle; float-float: cos 2 angle and sin 2 angle.
          s.plate = Buffer(*device_, n * (mode_.ff ? 2 : 1) * sizeof(double), storage, MemoryUse::upload);
        }
      },
      [&] {
        for (Slot& s : slots_) s = Slot{};
      },
      "vulkan: " + device_->info().name);
  chunk_ = chunk;
  for (Slot& s : slots_) {
    make_command(s.cmd, s.fence);
    const auto all = bindings(s);
    s.set = pipeline_->make_set(std::span<const Buffer* const>(all).first(PISCO_BINDINGS));
  }
}

VulkanBackend::~VulkanBackend() { release(); }

// Everything made on the device, in reverse order; safe on a partly set-up backend.
void VulkanBackend::release() noexcept {
  if (!device_) return;
  const auto& fn = device_->fn();
  fn.vkDeviceWaitIdle(device_->handle());
  for (Slot& s : slots_)
    if (s.fence) fn.vkDestroyFence(device_->handle(), s.fence, nullptr);
  for (Slot& s : slots_) s = Slot{};
  for (Buffer* b : {&sky_, &sky_lo_, &rings_, &weights_, &weights64_, &polar_sky_, &polar_sky_lo_}) *b = Buffer();
  pipeline_.reset();
  if (adjoint_.fence) fn.vkDestroyFence(device_->handle(), adjoint_.fence, nullptr);
  adjoint_ = Adjoint{};
  if (pool_) fn.vkDestroyCommandPool(device_->handle(), pool_, nullptr);
  pool_ = VK_NULL_HANDLE;
}

// The kernel for this detector: its weight layout, the float64 path, and how many invocations share
// one sample: enough that none walks more than about 16,000 pixels (lavapipe ends an invocation
// after 65,535 loop iterations; on GPUs, large discs gain parallelism).
double VulkanBackend::disc_pixels(const PreparedDetector& det) const {
  return 12.0 * double(in_->sky.nside) * double(in_->sky.nside) * (1.0 - det.cos_rho_max) / 2.0;
}

vk::ComputePipeline::Specialization VulkanBackend::specialization(std::size_t detector) const {
  const PreparedDetector& det = in_->detectors.at(detector);
  const double disc = disc_pixels(det);
  std::uint32_t parts = 1;
  while (parts < PISCO_WG_SIZE && disc / parts > 16384.0) parts *= 2;
  // lavapipe (a CPU device) ends an invocation after 65,535 loop iterations without an error.
  if (device_->info().type == VK_PHYSICAL_DEVICE_TYPE_CPU && disc / parts > 60000.0)
    throw Error("vulkan: discs of rho_max = " + std::to_string(std::acos(det.cos_rho_max) * 180 / std::numbers::pi) +
                " deg at NSIDE " + std::to_string(in_->sky.nside) + " hold about " + std::to_string(std::size_t(disc)) +
                " pixels, more than " + device_->info().name +
                " can sum in one workgroup; use a smaller rho_max, a GPU or the cpu backend");
  vk::ComputePipeline::Specialization spec{};
  spec[PISCO_SPEC_RADIAL] = det.radial ? 1u : 0u;
  spec[PISCO_SPEC_FLOAT64] = mode_.float64 ? 1u : 0u;
  spec[PISCO_SPEC_PARTS] = parts;
  spec[PISCO_SPEC_COLUMNS] = grids_.columns.at(detector);
  spec[PISCO_SPEC_PLATE] = det.plate == PreparedDetector::Plate::aperture ? 1u : 0u;
  return spec;
}

vk::PushConstants VulkanBackend::push_constants(std::size_t detector, bool quaternions) const {
  return vk::push_constants(*in_, grids_, mode_, detector, quaternions);
}

// Fills the slot's pointing (4 doubles a sample, src/kernel/interface.h) and queues its kernel.
void VulkanBackend::dispatch(Slot& slot, vk::ComputePipeline& pipeline, VkDescriptorSet set,
                             const vk::ComputePipeline::Specialization& spec, const vk::PushConstants& push_in,
                             const PointingInput& pointing) {
  const auto& fn = device_->fn();
  const std::size_t n = pointing.size();
  // Pointing the slot already holds (PointingInput::shared: the same boresight chunk for another
  // detector) is not packed again; the plate angles, the detector's own, always are.
  if (!slot.staged.reuse(pointing.shared, pointing.shared_first, n, pointing.quaternions))
    vk::pack_pointing(pointing, mode_.ff, static_cast<double*>(slot.pointing.mapped()));
  if (!pointing.plate_angle.empty())
    vk::pack_plate(pointing.plate_angle, mode_.ff, static_cast<double*>(slot.plate.mapped()));
  vk::PushConstants push = push_in;
  push.sample_count = std::uint32_t(n);
  const std::size_t per_group = PISCO_WG_SIZE / spec[PISCO_SPEC_PARTS];
  const std::size_t groups = (n + per_group - 1) / per_group;
  const std::uint32_t gx = std::uint32_t(std::min<std::size_t>(groups, device_->info().max_groups_x));
  const std::uint32_t gy = std::uint32_t((groups + gx - 1) / gx);
  push.groups_x = gx;

  PISCO_VK(fn.vkResetCommandBuffer(slot.cmd, 0));
  VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  PISCO_VK(fn.vkBeginCommandBuffer(slot.cmd, &bi));
  pipeline.record(slot.cmd, spec, set, push, gx, gy);
  VkMemoryBarrier barrier{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  barrier.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  barrier.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  fn.vkCmdPipelineBarrier(slot.cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &barrier, 0,
                          nullptr, 0, nullptr);
  PISCO_VK(fn.vkEndCommandBuffer(slot.cmd));
  PISCO_VK(fn.vkResetFences(device_->handle(), 1, &slot.fence));
  VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  si.commandBufferCount = 1;
  si.pCommandBuffers = &slot.cmd;
  PISCO_VK(fn.vkQueueSubmit(device_->queue(), 1, &si, slot.fence));
}

std::uint64_t VulkanBackend::collect(Slot& slot, bool results) {
  const auto& fn = device_->fn();
  PISCO_VK(fn.vkWaitForFences(device_->handle(), 1, &slot.fence, VK_TRUE, std::numeric_limits<std::uint64_t>::max()));
  if (lose_device_after_ >= 0 && completed_chunks_++ >= lose_device_after_)
    vk::fail(VK_ERROR_DEVICE_LOST, "vkWaitForFences (PISCO_VK_TEST_FAULT)");
  slot.tod.invalidate();
  slot.counts.invalidate();
  if (results) {
    auto* tod = static_cast<double*>(slot.tod.mapped());
    if (mode_.ff)
      for (std::size_t i = 0; i < slot.job.tod.size(); ++i) tod[i] = vk::from_ff_bits(tod[i]);
    deliver(slot.job, tod);
  }
  const auto* counts = static_cast<const std::uint32_t*>(slot.counts.mapped());
  std::uint64_t pixels = 0;
  for (std::size_t i = 0; i < slot.job.tod.size(); ++i) pixels += counts[i];
  return pixels;
}

void VulkanBackend::abandon() noexcept {
  ring_.abandon();
  for (Slot& s : slots_) s.staged.forget();
  device_->fn().vkDeviceWaitIdle(device_->handle());
}

void VulkanBackend::fail(const SlotJob& job, const std::string& what, ErrorKind kind) {
  abandon();
  throw SubmissionError(job.detector, what + " (device " + device_->info().name + ", detector " +
                                          std::to_string(job.detector) + ", samples " + std::to_string(job.first) +
                                          " to " + std::to_string(job.first + job.tod.size() - 1) + " of a chunk of " +
                                          std::to_string(job.total) + ")",
                        kind);
}

// The sky's tables for pixels [first, first + maps' size) of the maps: the records (vectors and
// Stokes values) and the float64 vectors' residuals, packed straight into the staging buffer a piece at
// a time.
void VulkanBackend::upload_sky(int nside, const std::array<std::span<const double>, 4>& maps, std::size_t first,
                               Buffer& records, Buffer& lo, const std::string& what) {
  const std::size_t count = maps[0].size();
  const PixelVectors vectors(nside);
  const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<double> xyz;
  const auto positions = [&](std::size_t at, std::size_t n) {
    xyz.resize(3 * n);
    vectors.get(first + at, n, xyz.data(), threads);
  };
  records = upload_records(
      count, 8 * sizeof(float),
      [&](std::size_t at, std::size_t n, void* dst) {
        positions(at, n);
        vk::pack_sky(maps, first, mode_, first + at, n, xyz.data(), static_cast<float*>(dst));
      },
      what.c_str());
  lo = upload_records(
      mode_.vectors64() ? count : 1, 4 * sizeof(float),
      [&](std::size_t at, std::size_t n, void* dst) {
        auto* out = static_cast<float*>(dst);
        if (!mode_.vectors64()) {
          std::fill(out, out + 4 * n, 0.0f);
          return;
        }
        positions(at, n);
        vk::pack_sky_lo(n, xyz.data(), out);
      },
      (what + "'s float64 pixel vectors").c_str());
}

// The band packed as the sky is (upload_sky), uploaded beside it, and a descriptor set a slot that binds it
// in the sky's place; the kernel reads it from pixel SKY_FIRST (src/kernel/kernel.glsl).
void VulkanBackend::set_polar_sky(const SkyBand& band) {
  if (polar_sky_.handle() != VK_NULL_HANDLE) throw Error("vulkan: the polar copy is given once per sky");
  upload_sky(band.nside, {band.maps[0], band.maps[1], band.maps[2], band.maps[3]}, band.first, polar_sky_,
             polar_sky_lo_, "the sky's polar copy");
  polar_first_ = std::uint32_t(band.first);
  for (Slot& s : slots_) {
    auto all = bindings(s);
    all[PISCO_BINDING_SKY] = &polar_sky_;
    all[PISCO_BINDING_SKY_LO] = &polar_sky_lo_;
    s.polar_set = pipeline_->make_set(std::span<const Buffer* const>(all).first(PISCO_BINDINGS));
  }
}

void VulkanBackend::submit(std::size_t detector, const PointingInput& pointing, std::span<double> tod,
                           bool accumulate, std::uint64_t ticket) {
  const PreparedDetector& det = in_->detectors.at(detector);
  const vk::PushConstants push = push_constants(detector, pointing.quaternions);
  vk::ComputePipeline::Specialization spec = specialization(detector);
  if (pointing.sky) spec[PISCO_SPEC_SKY_FIRST] = polar_first_;
  const std::size_t chunk = chunk_for(det);
  SlotJob current;
  try {
    for (std::size_t begin = 0; begin < pointing.size(); begin += chunk) {
      const std::size_t n = std::min(chunk, pointing.size() - begin);
      Slot& slot = ring_.acquire([&](Slot& s) {
        current = s.job;
        return collect(s);
      });
      current = SlotJob{false, ticket, detector, begin, pointing.size(), tod.subspan(begin, n), accumulate};
      dispatch(slot, *pipeline_, pointing.sky ? slot.polar_set : slot.set, spec, push, pointing.subspan(begin, n));
      slot.job = current;
      slot.job.busy = true;
    }
  } catch (const Error& e) {
    fail(current, e.what(), e.kind());
  } catch (...) {
    abandon();
    throw;
  }
}

std::uint64_t VulkanBackend::wait(std::uint64_t ticket) {
  SlotJob current;
  try {
    ring_.drain(ticket, [&](Slot& s) {
      current = s.job;
      return collect(s);
    });
  } catch (const Error& e) {
    fail(current, e.what(), e.kind());
  } catch (...) {
    abandon();
    throw;
  }
  device_->check_validation("convolving");
  return ring_.take_pixels();
}

// Chunks of at most chunk_ samples and about 1e9 pixel evaluations, so that no submission runs for
// long enough to meet a driver's watchdog on large discs.
std::size_t VulkanBackend::chunk_for(const PreparedDetector& det) const {
  const double disc = disc_pixels(det);
  return std::max<std::size_t>(1, std::min<std::size_t>(chunk_, std::size_t(1e9 / std::max(disc, 1.0))));
}

void VulkanBackend::prepare_adjoint() {
  if (adjoint_.pipeline) return;
  const vk::DeviceInfo& info = device_->info();
  if (!info.int64_atomics)
    throw Error("vulkan: " + info.name +
                    " lacks shaderInt64 or shaderBufferInt64Atomics, which the adjoint's deterministic fixed-point "
                    "sums need; use the cpu or simd backend for the adjoint",
                ErrorKind::unavailable);
  const std::span<const std::uint32_t> spirv =
      mode_.ff ? std::span<const std::uint32_t>(pisco_spv_adjoint_ff, sizeof(pisco_spv_adjoint_ff) / sizeof(std::uint32_t))
               : std::span<const std::uint32_t>(pisco_spv_adjoint, sizeof(pisco_spv_adjoint) / sizeof(std::uint32_t));
  const std::size_t bytes = 4 * in_->sky.npix * sizeof(std::int64_t);
  if (bytes > info.max_storage_buffer_range)
    throw Error("vulkan: the adjoint's maps of an NSIDE " + std::to_string(in_->sky.nside) + " sky take " +
                    std::to_string(int(mib(double(bytes)))) + " MiB in one storage buffer, but " + info.name +
                    " binds at most " + std::to_string(int(mib(double(info.max_storage_buffer_range)))) +
                    " MiB (maxStorageBufferRange); use the cpu or simd backend for the adjoint",
                ErrorKind::device);
  try {
    adjoint_.pipeline = std::make_unique<vk::ComputePipeline>(*device_, spirv, PISCO_ADJOINT_BINDINGS, std::uint32_t(slots_.size()));
    adjoint_.sums = Buffer(*device_, bytes, storage | VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                           MemoryUse::device);
    adjoint_.readback = Buffer(*device_, bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT, MemoryUse::readback);
    for (Slot& s : slots_) s.values = Buffer(*device_, chunk_ * sizeof(double), storage, MemoryUse::upload);
  } catch (const vk::OutOfMemory& e) {
    adjoint_ = Adjoint{};
    throw Error("vulkan: out of memory for the adjoint's maps (" + std::to_string(int(mib(2.0 * double(bytes)))) +
                    " MiB) on " + info.name + ": " + e.what(),
                ErrorKind::device);
  }
  for (Slot& s : slots_) {
    const auto all = bindings(s);
    s.adjoint_set = adjoint_.pipeline->make_set(all);
  }
  make_command(adjoint_.cmd, adjoint_.fence);
  fold(0.0);  // device memory starts undefined: clear the sums
}

void VulkanBackend::make_command(VkCommandBuffer& cmd, VkFence& fence) {
  const auto& fn = device_->fn();
  VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  ai.commandPool = pool_;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  PISCO_VK(fn.vkAllocateCommandBuffers(device_->handle(), &ai, &cmd));
  VkFenceCreateInfo fi{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  PISCO_VK(fn.vkCreateFence(device_->handle(), &fi, nullptr, &fence));
}

void VulkanBackend::fold(double scale) {
  const auto& fn = device_->fn();
  VkCommandBuffer cmd = adjoint_.cmd;
  PISCO_VK(fn.vkResetCommandBuffer(cmd, 0));
  VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  PISCO_VK(fn.vkBeginCommandBuffer(cmd, &bi));
  const auto barrier = [&](VkPipelineStageFlags from, VkAccessFlags src, VkPipelineStageFlags to, VkAccessFlags dst) {
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = src;
    b.dstAccessMask = dst;
    fn.vkCmdPipelineBarrier(cmd, from, to, 0, 1, &b, 0, nullptr, 0, nullptr);
  };
  const VkDeviceSize bytes = adjoint_.sums.size();
  barrier(VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT,
          VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
  if (scale > 0.0) {
    const VkBufferCopy region{0, 0, bytes};
    fn.vkCmdCopyBuffer(cmd, adjoint_.sums.handle(), adjoint_.readback.handle(), 1, &region);
    barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
            VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_READ_BIT);
  }
  fn.vkCmdFillBuffer(cmd, adjoint_.sums.handle(), 0, bytes, 0u);
  barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
          VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  PISCO_VK(fn.vkEndCommandBuffer(cmd));
  PISCO_VK(fn.vkResetFences(device_->handle(), 1, &adjoint_.fence));
  VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd;
  PISCO_VK(fn.vkQueueSubmit(device_->queue(), 1, &si, adjoint_.fence));
  PISCO_VK(fn.vkWaitForFences(device_->handle(), 1, &adjoint_.fence, VK_TRUE, std::numeric_limits<std::uint64_t>::max()));
  if (scale > 0.0) {
    adjoint_.readback.invalidate();
    fold_fixed_point(static_cast<const std::int64_t*>(adjoint_.readback.mapped()), in_->sky.npix, scale, adjoint_.maps);
  }
}

std::uint64_t VulkanBackend::adjoint_pass(std::size_t detector, const PointingInput& pointing, std::span<double> io,
                                          bool norms, bool squares) {
  const PreparedDetector& det = in_->detectors.at(detector);
  const vk::PushConstants push = push_constants(detector, pointing.quaternions);
  vk::ComputePipeline::Specialization spec = specialization(detector);
  spec[PISCO_SPEC_NORMS] = norms ? 1u : 0u;
  spec[PISCO_SPEC_SQUARES] = squares ? 1u : 0u;
  const std::size_t chunk = chunk_for(det);
  SlotJob current;
  const auto complete = [&](Slot& s) {
    current = s.job;
    return collect(s, norms);
  };
  try {
    for (std::size_t begin = 0; begin < pointing.size(); begin += chunk) {
      const std::size_t n = std::min(chunk, pointing.size() - begin);
      Slot& slot = ring_.acquire(complete);
      current = SlotJob{false, 0, detector, begin, pointing.size(), io.subspan(begin, n), false};
      if (!norms) {
        auto* values = static_cast<double*>(slot.values.mapped());
        for (std::size_t i = 0; i < n; ++i) values[i] = mode_.ff ? vk::ff_bits(io[begin + i]) : io[begin + i];
      }
      dispatch(slot, *adjoint_.pipeline, slot.adjoint_set, spec, push, pointing.subspan(begin, n));
      slot.job = current;
      slot.job.busy = true;
    }
    ring_.drain(std::numeric_limits<std::uint64_t>::max(), complete);
  } catch (const Error& e) {
    fail(current, e.what(), e.kind());
  } catch (...) {
    abandon();
    throw;
  }
  return ring_.take_pixels();
}

// The adjoint (docs/vulkan.md, "The adjoint"): batches of samples, each with its own fixed-point scale;
// with the per-sample normalization, a first pass computes every sample's norm as the forward kernel
// does, and the host divides the TOD by it before the scale is chosen.
std::uint64_t VulkanBackend::adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                                     bool squares) {
  prepare_adjoint();
  if (adjoint_.maps[0].empty())
    for (auto& m : adjoint_.maps) m.assign(in_->sky.npix, 0.0);
  const std::uint64_t pixels = fixed_point_adjoint(
      pointing, tod, adjoint_weight_bound(in_->detectors.at(detector)), squares, mode_.per_sample,
      [&](const PointingInput& part, std::span<double> norms) { adjoint_pass(detector, part, norms, true, squares); },
      [&](const PointingInput& part, std::span<double> values) { return adjoint_pass(detector, part, values, false, squares); },
      [&](double scale) { fold(scale); });
  device_->check_validation("the adjoint");
  return pixels;
}

void VulkanBackend::take_adjoint(const std::array<std::span<double>, 4>& maps) { hand_over_adjoint(adjoint_.maps, maps); }

}  // namespace

void attach_vulkan_backend(BackendEntry& e) {
  e.probe = [] {
    try {
      auto instance = vk::Instance::get();
      const auto devices = vk::enumerate_devices(*instance);
      std::string usable, unusable;
      for (const auto& d : devices)
        (d.unusable.empty() ? usable : unusable) +=
            (std::to_string(d.index) + ": " + d.describe() + (d.unusable.empty() ? "" : " (" + d.unusable + ")") + "; ");
      if (usable.empty())
        return BackendInfo{"vulkan", false,
                           devices.empty() ? "no Vulkan device was found (for a CPU device, install mesa-vulkan-drivers)"
                                           : "no usable Vulkan device: " + unusable.substr(0, unusable.size() - 2),
                           {}, {}};
      const vk::DeviceInfo chosen = vk::choose_device(devices, "auto");
      const std::string pick = chosen.describe();
      std::string detail = usable + unusable;
      BackendInfo info{"vulkan", true, detail.substr(0, detail.size() - 2) + " (auto: " + pick + ")", {}, {}};
      for (const auto& d : devices)
        if (d.unusable.empty() && d.type == chosen.type) info.devices.push_back(d.index);
      info.capabilities.device_memory = chosen.device_memory;
      info.capabilities.adjoint = chosen.int64_atomics;
      return info;
    } catch (const Error& e) {
      return BackendInfo{"vulkan", false, e.what(), {}, {}};
    }
  };
  e.create = [](std::shared_ptr<const EngineInputs> in, const SkyView& sky,
                const EngineOptions& o) -> std::unique_ptr<Backend> {
    return std::make_unique<VulkanBackend>(std::move(in), sky, o);
  };
  e.auto_priority = [] {
    try {
      const auto d = vk::choose_device(vk::enumerate_devices(*vk::Instance::get()), "auto");
      return d.type == VK_PHYSICAL_DEVICE_TYPE_CPU ? -1 : 10;
    } catch (const Error&) {
      return -1;
    }
  };
}

}  // namespace pisco::detail
