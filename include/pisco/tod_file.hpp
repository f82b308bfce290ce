// TOD and pointing files (docs/formats.md, "TOD files" and "Pointing files"): HDF5, one group per detector.
//
// Layout of a TOD file ("pisco-tod-1"):
//   /                      string attributes given by the caller (units, nside, beam, backend, device,
//                          version, config, created, ...) plus pisco_format = "pisco-tod-1"
//   /<detector name>/      one group per detector, in focal-plane order (link creation order is
//                          tracked), with attributes zeta [rad], epsilon, gain (float64), beam (uint64)
//   /<detector>/signal     float64 or float32, one value per sample
//   /<detector>/theta,phi,psi   float64 pointing [rad], only when written with_pointing
//   /<detector>/quat       float64 (samples, 4): the same pointing as the rotation of the detector's
//                          antenna basis, x, y, z, w (quaternion.hpp), only when written with_pointing
//   /<detector>/flags      uint8, one per sample, only when written with_flags: 1 where the sample's
//                          disc holds an UNSEEN pixel of a masked sky (Engine::flag_samples), else 0
//
// A pointing input file (per-detector form) has the same layout without `signal`: groups named
// after detectors, each holding float64 (or float32) 1-D datasets theta, phi, psi of equal length.
// A TOD file written with_pointing is therefore also a pointing file.
//
// All HDF5 access is serialized inside the library (a process-wide lock), so these functions may be
// called from several threads; one TodWriter must not be used from two threads at once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"

namespace pisco {

enum class TodPrecision { float64, float32 };

// One TOD file written by several processes together (pisco-vk under MPI, docs/scaling.md), in the
// layout of a file written by one. The library knows nothing of MPI; the caller brings it here:
//  1. one process (the leader) calls TodWriter::create_shared(): the temporary file (file + suffix) is
//     created whole, the storage of every dataset allocated, and closed;
//  2. every process opens it with TodWriter::open_shared(), through parallel HDF5's MPI-IO driver on
//     the caller's communicator; opening, flushing and closing are then collective: every process
//     makes the same calls in the same order;
//  3. each process writes its own samples with write() (independent writes, any order);
//  4. every process calls commit(): flush and close, then `barrier`, then the leader renames the
//     temporary file to its final name. commit() cannot check that every sample was written (no
//     process sees the others' writes): the processes' shares of the work must cover the file.
// A shared writer destroyed without commit() closes the file (every process at the same point) and
// removes the temporary file.
struct SharedTodOptions {
  std::string temporary_suffix;  // the same in every process, e.g. ".tmp-<the leader's process id>"
  bool leader = false;           // the process that renames the file at commit()
  // The address of the MPI communicator (an MPI_Comm) of the processes that share the file: opened with
  // the MPI-IO driver on it. It needs a library built on parallel HDF5 (PISCO_WITH_MPI, docs/scaling.md;
  // otherwise pisco::Error of kind unavailable). Null: the file is opened by this process alone.
  const void* mpi_communicator = nullptr;
  std::function<void()> barrier;  // returns when every process has called it
};

// Writes a TOD file incrementally, chunk by chunk: only the chunk passed to write() is held in memory.
// The file is written under a temporary name in the same directory (file + ".tmp-<pid>") and renamed to
// `file` by commit(), replacing any existing file. Destroying the writer without commit() (for example
// while an exception propagates) closes and removes the temporary file, so no half-written output is
// ever left under the final name. Every failure throws pisco::Error naming the file and the operation.
class TodWriter {
 public:
  // Creates the temporary file with one group per detector of `focal_plane` and its datasets of
  // `samples_per_detector` samples (with `with_flags`, a uint8 dataset `flags` too). Detector names
  // must be unique, non-empty, and contain no '/'.
  TodWriter(const std::filesystem::path& file, const FocalPlane& focal_plane,
            std::size_t samples_per_detector, TodPrecision precision, bool with_pointing,
            const std::map<std::string, std::string>& attributes, bool with_flags = false,
            bool with_weights = false);
  ~TodWriter();

  // Shared files (SharedTodOptions): the leader creates the temporary file `file` + temporary_suffix
  // with the layout and attributes of the constructor's (samples never written are not filled), and
  // closes it; then every process opens it with open_shared(), given the same focal plane, sizes and
  // options. Errors as the constructor's; a failed create_shared() leaves no file.
  static void create_shared(const std::filesystem::path& file, const FocalPlane& focal_plane,
                            std::size_t samples_per_detector, TodPrecision precision, bool with_pointing,
                            const std::map<std::string, std::string>& attributes, bool with_flags,
                            const std::string& temporary_suffix, bool with_weights = false);
  static TodWriter open_shared(const std::filesystem::path& file, const FocalPlane& focal_plane,
                               std::size_t samples_per_detector, TodPrecision precision, bool with_pointing,
                               bool with_flags, const SharedTodOptions& options, bool with_weights = false);

  TodWriter(TodWriter&&) noexcept;
  TodWriter& operator=(TodWriter&&) noexcept;
  TodWriter(const TodWriter&) = delete;
  TodWriter& operator=(const TodWriter&) = delete;

  // Writes signal[0..n) to samples [offset, offset + n) of detector `detector` (float32 files round
  // to nearest). With with_pointing, `pointing` is required and must have n samples; without it,
  // `pointing` is ignored. `flags` (n values, files written with_flags only) go to the `flags`
  // dataset; samples written without flags read back as 0. With with_weights, `weights` (3 n values:
  // each sample's response to I, Q, U, pisco::stokes_weights) go to the `weights` dataset (samples, 3).
  // Throws pisco::Error on a detector index beyond the focal plane, a range beyond
  // samples_per_detector, a missing or mis-sized pointing chunk, flags or weights, after commit(), or
  // when the disk is full (the write that meets it names its samples); and, before writing anything,
  // on a signal, pointing or weight value that is not finite or a signal beyond float32's range in a
  // float32 file (naming the file, the detector and the sample).
  void write(std::size_t detector, std::size_t offset, std::span<const double> signal,
             const PointingView* pointing = nullptr, std::span<const std::uint8_t> flags = {},
             std::span<const double> weights = {});

  // Checks that every sample of every detector was written (else pisco::Error naming the detector and
  // the first missing sample, and the temporary file is removed when the writer is destroyed), closes
  // the file and renames it to its final name, replacing an existing file.
  void commit();

  const std::filesystem::path& path() const noexcept { return file_; }
  const std::filesystem::path& temporary_path() const noexcept { return temporary_; }
  std::size_t samples_per_detector() const noexcept { return samples_; }

 private:
  struct Impl;
  TodWriter() = default;
  void create(const FocalPlane& focal_plane, std::size_t samples_per_detector, TodPrecision precision,
              bool with_pointing, const std::map<std::string, std::string>& attributes, bool with_flags,
              bool with_weights, bool shared);
  std::filesystem::path file_, temporary_;
  std::size_t samples_ = 0;
  std::unique_ptr<Impl> impl_;
};

// A detector as recorded in a TOD file.
struct TodFileDetector {
  std::string name;
  double zeta = 0.0, epsilon = 0.0, gain = 1.0;
  std::size_t beam = 0;
};

// The detectors of a TOD file in the order they were written (name order for files written without
// link creation order). Throws pisco::Error on a missing or non-HDF5 file or a group missing an attribute.
std::vector<TodFileDetector> read_tod_detectors(const std::filesystem::path& file);

// The whole `signal` dataset of one detector, converted to double.
std::vector<double> read_tod_signal(const std::filesystem::path& file, const std::string& detector);

// The detector quaternions (`quat`, (samples, 4)) of a TOD file written with pointing.
std::vector<Quat> read_tod_quats(const std::filesystem::path& file, const std::string& detector);

// The `weights` of one detector (written with_weights), 3 values a sample (I, Q, U), sample after
// sample; throws pisco::Error naming the file and detector when the file has none.
std::vector<double> read_tod_weights(const std::filesystem::path& file, const std::string& detector);

// The `flags` of one detector (written with_flags); empty when the file has none (no sample flagged).
std::vector<std::uint8_t> read_tod_flags(const std::filesystem::path& file, const std::string& detector);

// The root attributes of a file: string attributes as they are, numeric scalar attributes formatted as
// text; pisco_format included.
std::map<std::string, std::string> read_tod_attributes(const std::filesystem::path& file);

// Reads and checks the (theta, phi, psi) pointing of one detector. Throws pisco::Error, naming the file,
// the group and the dataset and what was expected, on a missing file, a file that is not HDF5, a missing
// group or dataset, a dataset that is not a 1-D float array, datasets of different lengths, and (through
// check_pointing, origin "file:/detector") a non-finite value or theta outside [0, pi] naming the sample.
Pointing read_pointing_hdf5(const std::filesystem::path& file, const std::string& detector);

// The detector groups at the root of a pointing (or TOD) file, in creation order where the file tracks
// it, else in name order.
std::vector<std::string> pointing_detectors(const std::filesystem::path& file);

}  // namespace pisco
