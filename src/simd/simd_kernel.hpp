// The simd backend's per-sample kernel (docs/simd.md), compiled once per instruction set by Highway
// (simd_kernel.cpp) and chosen at run time: plain C++ types only, so that the backend's driver
// (simd_backend.cpp) needs no Highway header.
//
// The driver computes each sample's antenna frame with the reference's own code (kernel/frame.hpp) and
// its disc's ranges with disc_ranges (the reference's, kernel/disc.hpp, in vectors); the kernel
// evaluates the disc's pixels, range by range, a vector of float32 lanes at a time, with the
// formulas of kernel/contribution-inl.hpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "kernel/cap_boundary.hpp"
#include "kernel/contribution.hpp"
#include "kernel/disc.hpp"

namespace pisco::detail::simd {

// The sky as the kernel reads it: structure of arrays, one float32 array per quantity, each padded
// past the last pixel by pad_floats (a range's last vector is loaded whole and its surplus lanes
// masked). I is stored without the monopole I0.
constexpr std::size_t pad_floats = 64;

struct KernelSky {
  const float* kx;
  const float* ky;
  const float* kz;
  const float* i;  // I - I0
  const float* q;
  const float* u;
  const float* v;
  // The reference's float64 unit vectors, one array per component, padded as the float32 arrays;
  // only for the float64 path (null otherwise).
  const double* vx;
  const double* vy;
  const double* vz;
  double monopole;        // I0
  // The rings where the polar caps meet the belt and their weight (kernel/cap_boundary.hpp): the monopole's
  // weight sum counts their pixels with it.
  detail::CapBoundary boundary;
};

// A detector's weights: the float32 table (float32_weights) as records of two columns, columns 0
// and 1 in records[0], 2 and 3 in records[1] (absent, columns = 2, when w_U and w_V vanish at every
// node). Record k is four floats, (w_a(k), w_b(k), w_a(k + 1), w_b(k + 1)): the two ends of an
// interpolation along r or x in one 16-byte load (zero past the last node); the reference's float64
// tables for the float64 path.
struct KernelDetector {
  const float* records[2];
  int columns;  // 2 or 4
  bool radial;
  int grid_n;
  float grid_a, grid_inv_step;
  const double* weights;       // reference table (w_I, w_Q, w_U, w_V) per node, float64 path
  // The float64 path's records: (w(k), w(k + 1)) of the reference's columns w_I, w_Q, w_U, w_V
  // (0 to 3) and of the normalization weight (4, per-sample normalization only); null without it.
  const double* pairs64[5];
  const double* norm_weights;  // (wn, 0, 0, 0) per node, per-sample normalization only
  double grid_a_d, grid_inv_step_d;
};

// One sample: its frame in float64, its disc as ranges [begin, end), the plate's M(theta) in float64
// (aperture plates; null otherwise), and which float64 sums it needs.
struct SampleInput {
  const SampleFrame<double>* frame;
  const std::uint32_t* ranges;  // begin, end pairs
  std::size_t range_count;
  const double* plate;  // 16, row-major
  bool monopole;        // sum I0 w_I in float64 (the sky's monopole was removed)
  bool per_sample;      // sum the normalization weight in float64
};

// The sample's sums: the float32 contributions (Kahan-compensated per lane, lanes added in float64
// in lane order), the monopole's weight and the normalization, both float64.
struct SampleSums {
  double sum = 0.0;
  double monopole_weight = 0.0;
  double norm = 0.0;
};

// The adjoint of one sample (docs/physics.md, "The adjoint"): its value d scattered onto the pixels
// of its disc's ranges, each pixel's float32 weights (stokes_adjoint of the forward's own float32
// evaluation) times d added in float64 to accumulators (the backend's task windows), structure of
// arrays, pixel p of range r (on ring k = rings[r]) at p + ring_offset[k].
// The backend's task windows are laid out ring by ring with a gap after each row: rings of 4 nside
// float64 pixels are a multiple of 4 KiB long from NSIDE 128 on, and a disc's ranges on consecutive
// rings would otherwise fall on the same few sets of the processor's level-1 cache.
constexpr std::uint32_t window_gap = 8;  // float64s: a 64-byte cache line

struct ScatterInput {
  const SampleFrame<double>* frame;
  const std::uint32_t* ranges;   // begin, end pairs of sky pixels, each within one ring
  const std::uint32_t* rings;        // each range's ring
  const std::uint32_t* ring_offset;  // by ring: pixel p of that ring is at maps[c][p + offset] (modulo 2^32)
  std::size_t range_count;
  const double* plate;  // 16, row-major; null without an aperture plate
  double value;         // d (divided by its norm with the per-sample normalization)
  bool squares;         // add (d a)^2 instead of d a
  std::size_t limit;    // map entries below it belong to the caller's thread: a range's last vector
                        // may add zeros to those past the range (read and written back) below it
  double* maps[4];      // I, Q, U, V accumulators (V untouched with two columns and no plate)
  // The normal pass (the backend's normal, Engine::normal): d is not `value` but the sample's own
  // forward value, the sum of the same pixels' responses as the forward kernel sums them, computed
  // here from the same weights (float32 lanes, Kahan-compensated, without the float64 path): the
  // forward's bits when the ranges are the forward's own (a polar cap split by ring would group its
  // pixels into other vectors; the driver sums such discs with the forward kernel instead). The
  // disc's `pixels` weights wait in `scratch` (normal_scratch_floats) until d is known.
  bool normal = false;
  std::size_t pixels = 0;
  float* scratch = nullptr;
};

// The floats of the normal pass's scratch for a disc of `pixels` pixels in `ranges` ranges: eight
// columns of weights with their padding, the stretches of ranges, and room to align them.
constexpr std::size_t normal_scratch_floats(std::size_t pixels, std::size_t ranges) {
  return 8 * (pixels + 3 * 64 + 16) + 4 * (2 * ranges + 2) + 16;
}

// The kernel compiled for one instruction set.
struct Kernel {
  std::size_t index = 0;    // in Highway's dispatch table
  std::string description;  // e.g. "AVX2, 8 float32 lanes"
};

// The kernel for the instruction set `name`: a Highway target name, case-insensitive ("AVX3" for
// AVX-512, "AVX2", "SSE4", "EMU128", "NEON", ...), or "" / "auto" for the best the processor supports.
// Throws pisco::Error listing the instruction sets this machine can run when `name` is not one of them.
// Each engine keeps its own choice: nothing process-wide changes.
Kernel choose_kernel(const std::string& name);

// The ring table's z, pixels per radian (ring_pixels_per_radian) and pixel-centre shift (ring_shift)
// as arrays, entry r - 1 for ring r, padded past the last ring: the disc walk loads them a vector of
// rings at a time.
struct RingColumns {
  static constexpr std::size_t pad = 16;
  std::vector<double> z, scale, shift;
  explicit RingColumns(const std::vector<RingEntry>& rings);
};

// Writes the [begin, end) pixel ranges of the disc of radius rho around (theta0, phi0) at the start of
// `ranges` and returns how many numbers it wrote (two a range): exactly for_each_disc_range's (empty
// ranges left out), the rings' arctangents taken in vectors. `columns` are `rings`' own (RingColumns).
// `ranges` is a buffer: grown when it may be too short for the disc, never shrunk, its entries past
// the returned count left as they were.
// `redone`, when given, counts the rings redone with the reference's scalar arithmetic because a
// bound fell within the vector arithmetic's margin of an integer: count / 2 pi x 1e-12 + `margin`
// (tests widen it to send every ring through the scalar arithmetic).
std::size_t disc_ranges(const Kernel& kernel, const RingEntry* rings, const RingColumns& columns, std::int64_t nside,
                        double theta0, double phi0, double rho, double cos_rho, std::vector<std::uint32_t>& ranges,
                        std::size_t* redone = nullptr, double margin = 1e-9);

// Evaluates one sample with `kernel`.
void convolve_sample(const Kernel& kernel, const KernelSky& sky, const KernelDetector& det, const SampleInput& in,
                     SampleSums& out);
// Scatters one sample with `kernel`.
void scatter_sample(const Kernel& kernel, const KernelSky& sky, const KernelDetector& det, const ScatterInput& in);

}  // namespace pisco::detail::simd
