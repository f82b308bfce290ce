// What the vulkan kernel reads (src/kernel/interface.h), built on the host: the sky and ring tables, the
// beam grids, the push constants and the pointing of a dispatch, for the float64 kernel or the
// float-float one (docs/vulkan.md, "Devices without float64"). Plain C++ with no Vulkan call, so that
// the kernel's host tests (tests/test_kernel_host.cpp) run the shader source on the very tables the
// device gets.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "kernel/cap_boundary.hpp"
#include "vulkan/vulkan_options.hpp"
#include "core/backend.hpp"
#include "core/prepared.hpp"
#include "interface.h"

namespace pisco::detail::vk {

// A float64 number as the float-float kernel takes it (src/kernel/ff.glsl): the pair (hi, lo) of float32
// with hi + lo = x to about 48 bits, in the 8 bytes the float64 kernel reads as one double.
double ff_bits(double x);
double from_ff_bits(double bits);

// Whether the kernel's float64 work runs in float-float on a device (`device_float64`: it has
// shaderFloat64) for EngineOptions::arithmetic: "auto" (float-float only where float64 is missing),
// "float-float" or "float64". Throws pisco::Error naming the device for float64 on a device without it,
// and for an unknown value.
bool use_float_float(bool device_float64, const std::string& device_name, Arithmetic arithmetic);

// How the kernel runs for a set of inputs.
struct KernelMode {
  bool float64 = false;   // the monopole and normalization path (PISCO_SPEC_FLOAT64)
  bool ff = false;        // every float64 number as a float-float pair (the convolve_ff kernel)
  double monopole = 0.0;  // I0, taken out of the float32 sky (docs/vulkan.md, "Precision")
  bool per_sample = false;
  CapBoundary boundary;   // the rings where the caps meet the belt (kernel/cap_boundary.hpp)
  // The kernel needs the float64 pixel vectors (sky_lo): on the float64 path, and always in float-float.
  bool vectors64() const { return float64 || ff; }
};
KernelMode kernel_mode(const EngineInputs& in, const SkyView& sky, bool ff);

// Pixels [first, first + n): 8 floats each (kx, ky, kz, I - I0, Q, U, V, 0), from their unit vectors xyz.
void pack_sky(const SkyView& sky, const KernelMode& mode, std::size_t first, std::size_t n, const double* xyz, float* out);
// The same from maps whose first value is pixel maps_first's (a band of the sky, core/polar_copy.hpp).
void pack_sky(const std::array<std::span<const double>, 4>& maps, std::size_t maps_first, const KernelMode& mode,
              std::size_t first, std::size_t n, const double* xyz, float* out);
// 4 floats a pixel: k - float(k), 0.
void pack_sky_lo(std::size_t n, const double* xyz, float* out);
// One texel a ring: z (two words), first pixel, count | shifted << 31; then two texels of the
// monopole's weights on the rings about the caps' edges, boundary.weight(ring) for ring 0 to 3 as
// cap_boundary_ring numbers them (two words each).
std::vector<std::uint32_t> pack_rings(const PreparedSky& sky, const CapBoundary& boundary, bool ff);

// Every detector's beam grid: float32 weight pairs, and the float64 (or float-float) tables.
struct Grids {
  std::vector<float> w32;                  // 4 floats a texel
  std::vector<double> w64;                 // 2 numbers a texel
  std::vector<std::uint32_t> offset;       // per detector, first texel in w32
  std::vector<std::uint32_t> offset64;     // per detector, first node in w64 (plate detectors: 3 texels a node)
  std::vector<std::uint32_t> plate_offset64;  // per detector, the texel of its plate's M0 in w64
  std::vector<std::uint32_t> columns;      // per detector: weight columns stored (2 or 4)
};
Grids pack_grids(const EngineInputs& in, const KernelMode& mode);

// The push constants of `detector`, but for sample_count and groups_x.
PushConstants push_constants(const EngineInputs& in, const Grids& grids, const KernelMode& mode, std::size_t detector,
                             bool quaternions);

// The pointing of n samples: 4 numbers each (angles (theta, phi, psi, 0) or a quaternion; in float-float
// always a quaternion); and the plate's per-sample values (its angle; in float-float cos 2 angle and
// sin 2 angle), when the detector has one.
void pack_pointing(const PointingInput& pointing, bool ff, double* out);
void pack_plate(std::span<const double> plate_angle, bool ff, double* out);

}  // namespace pisco::detail::vk
