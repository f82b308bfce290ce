// HDF5 pointing files of boresight quaternions (docs/formats.md, "Pointing files"): the form in which
// frameworks (TOAST's `boresight_radec`, litebird_sim's pointings) hand pointing over. Read in chunks,
// so that a season's pointing is never held in memory whole.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <vector>

#include "pisco/quaternion.hpp"

namespace pisco {

class BoresightFile {
 public:
  // Opens `file` and checks its dataset `boresight`: floating point, shape (N, 4), quaternions
  // (x, y, z, w). Throws pisco::Error naming the file and what was expected.
  explicit BoresightFile(const std::filesystem::path& file);
  ~BoresightFile();
  BoresightFile(BoresightFile&&) noexcept;
  BoresightFile& operator=(BoresightFile&&) noexcept;

  // Whether `file` is an HDF5 file with a dataset `boresight` (a pointing file of this kind rather than
  // one of per-detector angles, read_pointing_hdf5).
  static bool holds_boresight(const std::filesystem::path& file);

  std::size_t size() const noexcept;
  const std::filesystem::path& path() const noexcept;
  // Samples [first, first + count) into `out` (resized). Throws pisco::Error naming the file and the
  // sample for a non-finite quaternion or one whose norm is further than 1e-6 from 1.
  void read(std::size_t first, std::size_t count, std::vector<Quat>& out) const;

  // Whether the file has a dataset `hwp_angle` (one half-wave plate angle per sample, radians, in the
  // focal-plane frame, as TOAST's observations keep it), and samples [first, first + count) of it.
  bool has_hwp_angle() const noexcept;
  void read_hwp_angle(std::size_t first, std::size_t count, std::vector<double>& out) const;

  // Writes `quats` as a pointing file (under a temporary name, then renamed), with optional `times`
  // (seconds) and `hwp_angle` (radians) datasets of the same length.
  static void write(const std::filesystem::path& file, const std::vector<Quat>& quats,
                    const std::vector<double>& times = {}, const std::vector<double>& hwp_angle = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pisco
