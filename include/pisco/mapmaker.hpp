// Binned I/Q/U map-making from TOD, streamed chunk by chunk (docs/physics.md, "Map-making and
// spectra").
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "pisco/focal_plane.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"

namespace pisco {
namespace detail {
class ThreadPool;
}

struct BinnedMaps {
  int nside = 0;
  std::vector<double> I, Q, U;            // HEALPix RING; unsolved pixels are pisco::unseen
  std::vector<std::uint32_t> hits;        // samples per pixel
  std::vector<double> rcond;              // reciprocal condition number of each pixel's 3x3 matrix
};

// A sample's weights (a_I, a_Q, a_U): the detector's response to the sky's I, Q and U in the pixel it
// points at, signal = a . (I, Q, U) for a sky smooth on the beam's scale (docs/physics.md, "The
// Map-making and spectra"): s/2 ((1 + eps), (1 - eps) cos 2g, (1 - eps) sin 2g) with g = psi + zeta; behind a
// half-wave plate (Detector::hwp), D(0) M(hwp_angle - gamma) R(g) with the plate's own Mueller matrix.
// What BinnedMapmaker::add bins, and what `[output] tod_weights` writes beside the TOD.
std::array<double, 3> stokes_weights(const Detector& detector, double psi, double hwp_angle = 0.0);

class BinnedMapmaker {
 public:
  // Pixels whose 3x3 normal matrix has a reciprocal condition number below rcond_min are cut.
  explicit BinnedMapmaker(int nside, double rcond_min = 1e-3);
  ~BinnedMapmaker();
  // Copies have the same maps and number of threads, and threads of their own.
  BinnedMapmaker(const BinnedMapmaker& other);
  BinnedMapmaker& operator=(const BinnedMapmaker& other);
  BinnedMapmaker(BinnedMapmaker&&) noexcept;
  BinnedMapmaker& operator=(BinnedMapmaker&&) noexcept;

  // The host threads add() runs on: 1 (the default) or more, 0 for all hardware threads (at most
  // Engine::max_threads()). The maps are the same bits whatever the number: each pixel's samples are
  // added in the order given (docs/physics.md, "Map-making and spectra").
  void set_threads(unsigned threads);
  unsigned threads() const noexcept { return threads_; }

  // Adds a chunk: the pixel of each sample is that of its beam centre, and the model is the
  // detector's D(gamma) = s/2 [(1+eps), (1-eps) cos 2gamma, (1-eps) sin 2gamma], gamma = psi + zeta;
  // with a half-wave plate (Detector::hwp), the plate-modulated D(0) M(hwp_angle - plate gamma)
  // R(gamma) (hwp.hpp), and `hwp_angle` (the plate's angle per sample) is then required.
  // Samples with a non-zero flag (`flags`: empty, or one per sample; Engine::flag_samples) are left out.
  void add(const Detector& detector, const PointingView& pointing, std::span<const double> tod,
           std::span<const double> hwp_angle = {}, std::span<const std::uint8_t> flags = {});
  // The same from the boresight's quaternions (quaternion.hpp) with the detector's offset
  // (Detector::offset) applied here, as the engine applies it: each sample's pixel from its line of
  // sight and its polarization angle's cos 2 gamma and sin 2 gamma from the rotation's columns, with
  // no angle computed on the way (docs/physics.md, "Map-making and spectra"). Equal to
  // detector_pointing() followed by add() to rounding (a sample within rounding of a pixel's edge may
  // fall on the other side). Checks as add(), and the quaternions as the engine does.
  void add_from_boresight(const Detector& detector, const QuatPointingView& boresight, std::span<const double> tod,
                          std::span<const double> hwp_angle = {}, std::span<const std::uint8_t> flags = {});
  // Solves every pixel; may be called again after more add() calls.
  BinnedMaps solve() const;

  int nside() const noexcept { return nside_; }

  // The normal equations accumulated so far, per pixel (RING order): the 6 entries of the upper
  // triangle of A^T A (00 01 02 11 12 22), the 3 of A^T d and the hits. Map-makers that each binned
  // part of the TOD (processes of an MPI run, docs/scaling.md) are combined by adding these: the sum
  // solves to the maps of all the TOD binned by one map-maker, to rounding.
  std::span<const double> normal_matrices() const noexcept { return ata_; }
  std::span<const double> normal_vectors() const noexcept { return atd_; }
  std::span<const std::uint32_t> hits() const noexcept { return hits_; }
  // Adds another map-maker's normal equations (same NSIDE: 6, 3 and 1 values per pixel) to this one's,
  // element by element. Throws pisco::Error on sizes that do not match.
  void add_normal_equations(std::span<const double> matrices, std::span<const double> vectors,
                            std::span<const std::uint32_t> hits);
  // The same with another map-maker of the same NSIDE.
  void add_normal_equations(const BinnedMapmaker& other) {
    add_normal_equations(other.normal_matrices(), other.normal_vectors(), other.hits());
  }

 private:
  int nside_;
  double rcond_min_;
  unsigned threads_ = 1;
  std::unique_ptr<detail::ThreadPool> pool_;  // made by the first add() with threads_ > 1
  // Bins the samples of `tod` whose pixel and weights sample(i, pixel, weights) gives (false: left
  // out), in order for each pixel, on threads_ threads.
  template <class Sample>
  void bin(std::span<const double> tod, const Sample& sample);
  // add()'s per-sample pixels and weights, kept between calls.
  std::vector<std::size_t> pixel_scratch_;
  std::vector<std::array<double, 3>> weight_scratch_;
  std::vector<double> ata_;  // 6 per pixel: upper triangle of A^T A
  std::vector<double> atd_;  // 3 per pixel
  std::vector<std::uint32_t> hits_;
};

}  // namespace pisco
