// Engine inputs prepared once, in the layout every backend consumes: the sky's geometry and ring table
// of the disc selection, and one weight grid per detector (docs/physics.md, "The measurement
// equation": the 16-element beamsor collapsed to the 4-vector w a total-power detector needs). The
// sky's pixels are packed by each backend itself, straight from pisco::Sky into the layout it keeps
// (vk::pack_sky in src/vulkan/tables.hpp, pixel_records in src/cuda/device_data.hpp, the simd and cpu
// backends' own records), so that no full-sky copy is made that the backend does not hold.
#pragma once

#include <cstddef>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "kernel/disc.hpp"
#include "kernel/frame.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/sky.hpp"

namespace pisco::detail {

struct PreparedSky {
  int nside = 0;
  double pixel_area = 0.0;
  std::size_t npix = 0;
  std::vector<RingEntry> rings;
};

// Pixel centres' unit vectors of a RING sky, in pieces: what each backend packs beside the Stokes
// values. Thread-safe (const).
class PixelVectors {
 public:
  explicit PixelVectors(int nside);
  ~PixelVectors();
  // The unit vectors of pixels [first, first + count) into xyz (3 doubles each), on `threads` threads.
  void get(std::size_t first, std::size_t count, double* xyz, unsigned threads = 1) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct PreparedDetector {
  double cos_zeta = 1.0, sin_zeta = 0.0;
  DetectorOffset offset;  // from the boresight; inactive on it
  double rho_max = 0.0, cos_rho_max = 1.0;
  bool radial = false;  // weights are a radial profile in r = sin(rho) rather than a 2D grid
  int grid_n = 0;
  double grid_a = 0.0, grid_inv_step = 0.0;
  // w(x, y) = (Omega_pix / Omega~) s/2 [(1+eps) B_T. + (1-eps) B_Q.], 4 per node, x fastest
  // (radial: 4 per node along r).
  std::vector<double> weights;
  // Per-sample normalization only: (Omega_pix B_TT / Omega~, 0, 0, 0) per node.
  std::vector<double> norm_weights;

  // Half-wave plate (docs/physics.md, "Half-wave plates"). At the aperture, the backends weigh each
  // pixel with the effective weights w M(theta), M(theta) = R(-theta) M0 R(theta), theta the plate's
  // angle from the detector's axis per sample (PointingInput::plate_angle). Between the optics and
  // the detector, the engine combines four row detectors (rows), each the plain kernel with one row
  // of the beamsor, as d = D(0) M(theta) (s_T, s_Q, s_U, s_V).
  enum class Plate { none, aperture, detector };
  Plate plate = Plate::none;
  double plate_mueller[4][4] = {};  // M0
  double plate_gamma = 0.0;
  double d0[2] = {0.0, 0.0};        // D(0) = (s/2 (1+eps), s/2 (1-eps), 0, 0)
  std::size_t rows[4] = {0, 0, 0, 0};  // detector placement: the row detectors' indices
  std::size_t owner = 0;  // the focal-plane detector this one is (or is a row detector of), for messages
};

struct EngineInputs {
  PreparedSky sky;
  std::vector<PreparedDetector> detectors;
  Normalization normalization = Normalization::integral;
  Quadrature quadrature = Quadrature::plain;  // the engine sets its own (core/poles.hpp)
};

PreparedSky prepare_sky(const SkyView& sky);
// The float64 reference's pixel table: 8 doubles per pixel, the unit vector kx, ky, kz, 0, then
// I, Q, U, V (one cache line per pixel).
std::vector<double> reference_pixels(const SkyView& sky, unsigned threads);
// The same for pixels [first, first + count) of maps of that many values each (a band of the sky,
// core/polar_copy.hpp).
std::vector<double> reference_pixels(int nside, std::size_t first, const std::array<std::span<const double>, 4>& maps,
                                     unsigned threads);
// The detector's weights in float32 for the float32 backends (vulkan, cuda), 4 per node, with those
// below 2^-64 of the largest (and any below float32's smallest normal number) set to zero.
// A Gaussian's tail reaches float32's subnormal range within a Table 1 disc (below 1.2e-38 from
// about 13 sigma), and CPUs take a slow microcode path for every operation on a subnormal number:
// on lavapipe, the third of a 10 deg disc's pixels beyond 13 sigma made the whole disc take about
// twice as long. What is dropped adds up to less than 1e-12 of the response. One rule for both
// float32 backends (docs/vulkan.md, "Precision").
std::vector<float> float32_weights(const PreparedDetector& detector);
// The weight columns a device table needs for `detector`: 2 when its w_U and w_V vanish at every node
// (any beam without cross-polar response or Mueller leakage into U and V), so that a node and its
// neighbour fit one 16-byte texel, (w_I, w_Q) of each; 4 otherwise. The vulkan and cuda backends'
// layouts (docs/vulkan.md, docs/cuda.md).
int weight_columns(const PreparedDetector& detector);
// The monopole the float32 backends take out of the sky (docs/vulkan.md, "Precision"): the mean I0 of
// I when it dominates the map, that is when |I0| > 10 x the RMS of I - I0; 0 otherwise. They add
// I0 sum_k w_I(k) back in float64.
double float32_monopole(const SkyView& sky);
PreparedDetector prepare_detector(const Detector& detector, const Beamsor& beam, double pixel_area,
                                  Normalization normalization);
// Row `row` of the detector's beamsor as a detector of its own: weights Omega_pix / Omega~ B_row,.(x, y),
// no plate (the detector-placement plate's s_row).
PreparedDetector prepare_row_detector(const Detector& detector, const Beamsor& beam, double pixel_area,
                                      Normalization normalization, int row);
// The focal plane as check_focal_plane() has accepted it (the Engine checks it first).
EngineInputs prepare_inputs(const SkyView& sky, const std::vector<Beamsor>& beams,
                            const FocalPlane& focal_plane, Normalization normalization);


}  // namespace pisco::detail
