// The TodWriter: TOD files written chunk by chunk under a temporary name, renamed by commit()
// (layout: include/pisco/tod_file.hpp; docs/formats.md, "TOD files").
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <system_error>

#include "io/output_file.hpp"
#include "core/text.hpp"

#include "io/hdf5.hpp"
#include "pisco/quaternion.hpp"
#include "io/tod_layout.hpp"
#include "pisco/error.hpp"
#include "pisco/tod_file.hpp"

namespace pisco {

namespace fs = std::filesystem;
using namespace detail::hdf5;
namespace tod = detail::tod;

namespace {

constexpr hsize_t kChunkSamples = 16384;  // 128 KiB of float64 per chunk

// Disjoint, non-adjacent intervals [start, end) of written samples.
void add_interval(std::map<std::size_t, std::size_t>& intervals, std::size_t start, std::size_t end) {
  auto it = intervals.upper_bound(start);
  if (it != intervals.begin()) {
    auto previous = std::prev(it);
    if (previous->second >= start) {
      start = previous->first;
      end = std::max(end, previous->second);
      intervals.erase(previous);
    }
  }
  while (it != intervals.end() && it->first <= end) {
    end = std::max(end, it->second);
    it = intervals.erase(it);
  }
  intervals.emplace(start, end);
}

// Whether any of the intervals overlaps [start, end).
bool overlaps(const std::map<std::size_t, std::size_t>& intervals, std::size_t start, std::size_t end) {
  auto it = intervals.upper_bound(start);
  if (it != intervals.begin() && std::prev(it)->second > start) return true;
  return it != intervals.end() && it->first < end;
}

}  // namespace

// ================================================================ TodWriter

struct TodWriter::Impl {
  std::string where;      // the final file, for messages
  fs::path temporary;
  std::optional<detail::TemporaryListing> listed;  // pisco::temporary_files() while it exists
  Handle file;
  // Datasets are opened without a chunk cache: every write goes to the file at once, so that a full
  // disk fails the write that meets it (naming its samples) and nothing is left to flush at close.
  Handle dapl;
  std::vector<std::string> names;
  std::size_t samples = 0;
  TodPrecision precision = TodPrecision::float64;
  bool with_pointing = false;
  bool with_flags = false;
  bool with_weights = false;
  bool committed = false;
  bool closed = false;
  std::optional<SharedTodOptions> shared;  // a shared file (open_shared)
  std::vector<std::map<std::size_t, std::size_t>> written;  // per detector
  // The datasets of the detector written last (signal, theta, phi, psi): only one detector's are kept
  // open, so HDF5's chunk caches stay bounded whatever the number of detectors.
  std::size_t open_detector = static_cast<std::size_t>(-1);
  Handle datasets[7];  // signal, theta, phi, psi, quat, flags, weights
  std::vector<float> buffer;
  std::vector<Quat> quats;

  // The writer of `focal_plane`'s detectors, `samples` each, with the datasets asked for; its dataset
  // access list without a chunk cache.
  Impl(const std::string& where_, const FocalPlane& focal_plane, std::size_t samples_, TodPrecision precision_,
       bool with_pointing_, bool with_flags_, bool with_weights_)
      : where(where_), samples(samples_), precision(precision_), with_pointing(with_pointing_), with_flags(with_flags_),
        with_weights(with_weights_) {
    names.reserve(focal_plane.size());
    for (const Detector& d : focal_plane.detectors()) names.push_back(d.name);
    written.resize(focal_plane.size());
    dapl = checked(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose, where, "cannot create a dataset access list");
    check(H5Pset_chunk_cache(dapl.get(), 0, 0, 1.0), where, "cannot switch the chunk cache off");
  }

  ~Impl() {
    Session session;
    // Abandoned (an error, a full disk, a signal): nothing may fail on the way out, whatever the disk.
    if (!committed && file.valid()) abandon_file(file.get());
    for (Handle& d : datasets) d.reset();
    file.reset();
    if (!committed && !temporary.empty()) {
      std::error_code ec;
      fs::remove(temporary, ec);
    }
  }

  void open_datasets(std::size_t detector) {
    if (open_detector == detector) return;
    for (Handle& d : datasets) d.reset();
    open_detector = static_cast<std::size_t>(-1);
    const std::string& name = names[detector];
    Handle group = checked(H5Gopen2(file.get(), name.c_str(), H5P_DEFAULT), H5Gclose, where,
                           "cannot open group " + in_quotes("/" + name) + " of the temporary file");
    datasets[0] = checked(H5Dopen2(group.get(), "signal", dapl.get()), H5Dclose, where,
                          "cannot open dataset " + in_quotes("/" + name + "/signal"));
    if (with_pointing) {
      for (int k = 0; k < 3; ++k)
        datasets[k + 1] = checked(H5Dopen2(group.get(), tod::pointing_names[k], dapl.get()), H5Dclose, where,
                                  "cannot open dataset " + in_quotes("/" + name + "/" + tod::pointing_names[k]));
      datasets[4] = checked(H5Dopen2(group.get(), tod::quat_name, dapl.get()), H5Dclose, where,
                            "cannot open dataset " + in_quotes("/" + name + "/" + tod::quat_name));
    }
    if (with_flags)
      datasets[5] = checked(H5Dopen2(group.get(), tod::flags_name, dapl.get()), H5Dclose, where,
                            "cannot open dataset " + in_quotes("/" + name + "/" + tod::flags_name));
    if (with_weights)
      datasets[6] = checked(H5Dopen2(group.get(), tod::weights_name, dapl.get()), H5Dclose, where,
                            "cannot open dataset " + in_quotes("/" + name + "/" + tod::weights_name));
    open_detector = detector;
  }

  // Samples [offset, offset + count) of dataset `which`; `columns` values a sample (1, 4 for quat, 3 for
  // weights).
  void write_slab(int which, const char* name, std::size_t detector, std::size_t offset, std::size_t count,
                  hid_t mem_type, const void* data, hsize_t columns = 1) {
    const std::string what = "dataset " + in_quotes("/" + names[detector] + "/" + name);
    const int rank = columns == 1 ? 1 : 2;
    const hsize_t start[2] = {offset, 0}, size[2] = {count, columns};
    Handle memory = checked(H5Screate_simple(rank, size, nullptr), H5Sclose, where,
                            "cannot create the memory dataspace for " + what);
    Handle space = checked(H5Dget_space(datasets[which].get()), H5Sclose, where,
                           "cannot get the dataspace of " + what);
    check(H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, size, nullptr), where,
          "cannot select samples " + std::to_string(offset) + ".." + std::to_string(offset + count - 1) +
              " of " + what);
    check(H5Dwrite(datasets[which].get(), mem_type, memory.get(), space.get(), H5P_DEFAULT, data), where,
          "cannot write samples " + std::to_string(offset) + ".." + std::to_string(offset + count - 1) +
              " of " + what);
  }
};

TodWriter::TodWriter(const fs::path& file, const FocalPlane& focal_plane, std::size_t samples_per_detector,
                     TodPrecision precision, bool with_pointing,
                     const std::map<std::string, std::string>& attributes, bool with_flags, bool with_weights)
    : file_(file),
      temporary_(detail::temporary_name(file)),
      samples_(samples_per_detector) {
  create(focal_plane, samples_per_detector, precision, with_pointing, attributes, with_flags, with_weights, false);
}

namespace {

// A TOD file's name and detectors, checked before anything is made: a file in a directory that
// exists, and detector names that can name HDF5 groups, each once.
void check_target(const fs::path& file, const FocalPlane& focal_plane) {
  const std::string where = file.string();
  if (file.empty() || !file.has_filename()) throw Error(where + ": not a file name (expected a TOD file path)");
  std::error_code ec;
  if (fs::is_directory(file, ec)) throw Error(where + ": is a directory (expected a TOD file path)");
  const fs::path parent = file.parent_path();
  if (!parent.empty() && !fs::is_directory(parent, ec))
    throw Error(where + ": directory " + in_quotes(parent.string()) + " does not exist");
  if (focal_plane.size() == 0) throw Error(where + ": the focal plane has no detectors (nothing to write)");
  std::set<std::string> seen;
  for (const Detector& d : focal_plane.detectors()) {
    if (!valid_link_name(d.name))
      throw Error(where + ": detector name " + in_quotes(d.name) +
                  " cannot name an HDF5 group (expected a non-empty name without '/')");
    if (!seen.insert(d.name).second)
      throw Error(where + ": detector name " + in_quotes(d.name) + " appears twice (expected unique names)");
  }
}

// The dataspace of a detector's dataset, (samples) or (samples, width), and its creation list,
// chunked along samples.
struct Layout {
  Handle space, list;
};
Layout layout(std::size_t samples, hsize_t width, const std::string& where, const std::string& what) {
  const hsize_t dims[2] = {static_cast<hsize_t>(samples), width};
  const int rank = width ? 2 : 1;
  Layout l{checked(H5Screate_simple(rank, dims, nullptr), H5Sclose, where, "cannot create the " + what + " dataspace"),
           checked(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, where, "cannot create a dataset creation list")};
  if (samples > 0) {
    const hsize_t chunk[2] = {std::min<hsize_t>(dims[0], kChunkSamples), width};
    check(H5Pset_chunk(l.list.get(), rank, chunk), where, "cannot set the dataset chunk size");
  }
  return l;
}

// The datasets' layouts: the signal (and the angles), the quaternions (samples, 4), the weights
// (samples, 3) and the flags.
struct Layouts {
  hid_t signal_type;
  Layout signal, quat, weights, flags;
};
Layouts layouts(std::size_t samples, TodPrecision precision, bool shared, const std::string& where) {
  Layouts l{precision == TodPrecision::float32 ? H5T_IEEE_F32LE : H5T_IEEE_F64LE, layout(samples, 0, where, "TOD"),
            layout(samples, 4, where, "quaternion"), layout(samples, 3, where, "weights"), layout(samples, 0, where, "TOD")};
  // Samples never written read back as NaN (commit() refuses such a file anyway); flags as unflagged (0).
  const double nan = std::numeric_limits<double>::quiet_NaN();
  check(H5Pset_fill_value(l.signal.list.get(), H5T_NATIVE_DOUBLE, &nan), where, "cannot set the dataset fill value");
  // A shared file: all storage allocated now, so that the processes that open it write into it
  // independently (with parallel HDF5, allocation is collective), and nothing filled (each process
  // writes its own samples; filling would write the whole file once more).
  if (shared)
    for (const Layout* x : {&l.signal, &l.quat, &l.flags, &l.weights}) {
      check(H5Pset_alloc_time(x->list.get(), H5D_ALLOC_TIME_EARLY), where, "cannot set the allocation time");
      check(H5Pset_fill_time(x->list.get(), H5D_FILL_TIME_NEVER), where, "cannot set the fill time");
    }
  return l;
}

// One of a detector's datasets, with a string attribute when `attribute` is given.
void create_dataset(hid_t group, const std::string& detector, const char* name, hid_t type, const Layout& l, hid_t dapl,
                    const std::string& where, const char* attribute = nullptr, const char* value = nullptr) {
  const std::string path = in_quotes("/" + detector + "/" + name);
  Handle ds = checked(H5Dcreate2(group, name, type, l.space.get(), H5P_DEFAULT, l.list.get(), dapl), H5Dclose, where,
                      "cannot create dataset " + path);
  if (attribute) write_string_attribute(ds.get(), attribute, value, where);
  if (!ds.close()) fail(where, "cannot close dataset " + path);
}

// A detector's group: its attributes and datasets.
void create_group(hid_t file, hid_t dapl, const Detector& d, const Layouts& l, bool with_pointing, bool with_flags,
                  bool with_weights, const std::string& where) {
  const std::string group_path = in_quotes("/" + d.name);
  Handle group = checked(H5Gcreate2(file, d.name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, where,
                         "cannot create group " + group_path);
  write_scalar_attribute(group.get(), "zeta", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &d.zeta, where, d.name);
  write_scalar_attribute(group.get(), "epsilon", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &d.epsilon, where, d.name);
  write_scalar_attribute(group.get(), "gain", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &d.gain, where, d.name);
  const std::uint64_t beam = d.beam;
  write_scalar_attribute(group.get(), "beam", H5T_STD_U64LE, H5T_NATIVE_UINT64, &beam, where, d.name);
  create_dataset(group.get(), d.name, "signal", l.signal_type, l.signal, dapl, where);
  if (with_pointing) {
    for (const char* name : tod::pointing_names)
      create_dataset(group.get(), d.name, name, H5T_IEEE_F64LE, l.signal, dapl, where);
    create_dataset(group.get(), d.name, tod::quat_name, H5T_IEEE_F64LE, l.quat, dapl, where, "layout",
                   "the detector's antenna basis as a rotation, x, y, z, w (scalar last): q z^ q* is the "
                   "line of sight, q x^ q* the axis zeta is measured from");
  }
  if (with_flags)
    create_dataset(group.get(), d.name, tod::flags_name, H5T_STD_U8LE, l.flags, dapl, where, "meaning", tod::flags_meaning);
  if (with_weights)
    create_dataset(group.get(), d.name, tod::weights_name, H5T_IEEE_F64LE, l.weights, dapl, where, "meaning",
                   tod::weights_meaning);
  if (!group.close()) fail(where, "cannot close group " + group_path);
}

}  // namespace

void TodWriter::create(const FocalPlane& focal_plane, std::size_t samples_per_detector, TodPrecision precision,
                       bool with_pointing, const std::map<std::string, std::string>& attributes, bool with_flags,
                       bool with_weights, bool shared) {
  const fs::path& file = file_;
  Session session;
  const std::string where = file.string();
  check_target(file, focal_plane);
  std::error_code ec;

  impl_ = std::make_unique<Impl>(where, focal_plane, samples_per_detector, precision, with_pointing, with_flags,
                                 with_weights);
  Impl& s = *impl_;

  Handle fcpl = checked(H5Pcreate(H5P_FILE_CREATE), H5Pclose, where, "cannot create a file creation list");
  // Track link creation order so that readers list detectors in focal-plane order.
  check(H5Pset_link_creation_order(fcpl.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED), where,
        "cannot set the link creation order");
  Handle fapl = file_access_plist(where);
  s.listed.emplace(temporary_);
  const bool was_there = std::filesystem::exists(std::filesystem::symlink_status(temporary_, ec));
  const hid_t created = H5Fcreate(temporary_.c_str(), H5F_ACC_TRUNC, fcpl.get(), fapl.get());
  // HDF5 may have made the file before it failed (a full disk while writing its superblock); what
  // was in the way before is not the writer's to remove.
  if (created < 0 && !was_there) std::filesystem::remove(temporary_, ec);
  s.file = checked(created, H5Fclose, where, "cannot create the temporary file " + in_quotes(temporary_.string()));
  s.temporary = temporary_;  // from here on, the Impl removes the temporary file if anything fails
  inject_write_fault(s.file.get(), file);

  for (const auto& [key, value] : attributes) {
    if (key == "pisco_format") continue;  // always written below
    if (key.empty()) throw Error(where + ": an attribute has an empty name");
    write_string_attribute(s.file.get(), key, value, where);
  }
  write_string_attribute(s.file.get(), "pisco_format", tod::format, where);

  const Layouts l = layouts(samples_per_detector, precision, shared, where);
  for (const Detector& d : focal_plane.detectors())
    create_group(s.file.get(), s.dapl.get(), d, l, with_pointing, with_flags, with_weights, where);
}

void TodWriter::create_shared(const fs::path& file, const FocalPlane& focal_plane, std::size_t samples_per_detector,
                              TodPrecision precision, bool with_pointing,
                              const std::map<std::string, std::string>& attributes, bool with_flags,
                              const std::string& temporary_suffix, bool with_weights) {
  TodWriter w;
  w.file_ = file;
  w.temporary_ = fs::path(file.string() + temporary_suffix);
  w.samples_ = samples_per_detector;
  w.create(focal_plane, samples_per_detector, precision, with_pointing, attributes, with_flags, with_weights, true);
  Session session;
  Impl& s = *w.impl_;
  const std::string where = file.string();
  check_room_for_metadata(s.file.get(), s.temporary, where);
  check(H5Fflush(s.file.get(), H5F_SCOPE_GLOBAL), where,
        "cannot flush the temporary file " + in_quotes(s.temporary.string()));
  if (!s.file.close()) fail(where, "cannot close the temporary file " + in_quotes(s.temporary.string()));
  s.closed = true;
  s.committed = true;  // kept: the processes open it next (open_shared)
}

TodWriter TodWriter::open_shared(const fs::path& file, const FocalPlane& focal_plane, std::size_t samples_per_detector,
                                 TodPrecision precision, bool with_pointing, bool with_flags,
                                 const SharedTodOptions& options, bool with_weights) {
  Session session;
  const std::string where = file.string();
  TodWriter w;
  w.file_ = file;
  w.temporary_ = fs::path(file.string() + options.temporary_suffix);
  w.samples_ = samples_per_detector;
  w.impl_ = std::make_unique<Impl>(where, focal_plane, samples_per_detector, precision, with_pointing, with_flags,
                                   with_weights);
  Impl& s = *w.impl_;
  s.shared = options;
  Handle fapl = file_access_plist(where);
  if (options.mpi_communicator) {
#ifdef H5_HAVE_PARALLEL
    check(H5Pset_fapl_mpio(fapl.get(), *static_cast<const MPI_Comm*>(options.mpi_communicator), MPI_INFO_NULL),
          where, "cannot set the MPI-IO driver of parallel HDF5");
#else
    throw Error(where + ": a file shared by several processes needs a library built on parallel HDF5 "
                        "(PISCO_WITH_MPI; docs/scaling.md)",
                ErrorKind::unavailable);
#endif
  }
  s.listed.emplace(w.temporary_);
  s.file = checked(H5Fopen(w.temporary_.c_str(), H5F_ACC_RDWR, fapl.get()), H5Fclose, where,
                   "cannot open the temporary file " + in_quotes(w.temporary_.string()));
  s.temporary = w.temporary_;  // from here on, the Impl removes the temporary file if anything fails
  return w;
}

TodWriter::~TodWriter() = default;
TodWriter::TodWriter(TodWriter&&) noexcept = default;
TodWriter& TodWriter::operator=(TodWriter&&) noexcept = default;

void TodWriter::write(std::size_t detector, std::size_t offset, std::span<const double> signal,
                      const PointingView* pointing, std::span<const std::uint8_t> flags,
                      std::span<const double> weights) {
  Session session;
  const std::string where = file_.string();
  if (!impl_) throw Error(where + ": TodWriter::write() on a moved-from writer");
  Impl& s = *impl_;
  if (s.closed) throw Error(where + ": TodWriter::write() after commit()");
  if (detector >= s.names.size())
    throw Error(where + ": detector index " + std::to_string(detector) + " is beyond the focal plane (" +
                std::to_string(s.names.size()) + " detectors)");
  const std::string& name = s.names[detector];
  const std::size_t count = signal.size();
  if (offset > s.samples || count > s.samples - offset) {
    const std::string range = count <= std::numeric_limits<std::size_t>::max() - offset
                                  ? "samples [" + std::to_string(offset) + ", " + std::to_string(offset + count) + ")"
                                  : std::to_string(count) + " samples from offset " + std::to_string(offset);
    throw Error(where + ": detector " + in_quotes(name) + ": " + range + " are beyond the " +
                std::to_string(s.samples) + " samples per detector (expected offset + size <= " +
                std::to_string(s.samples) + ")");
  }
  if (s.with_pointing) {
    if (pointing == nullptr)
      throw Error(where + ": detector " + in_quotes(name) +
                  ": the file is written with pointing, but write() got no pointing chunk");
    if (pointing->theta.size() != count || pointing->phi.size() != count || pointing->psi.size() != count)
      throw Error(where + ": detector " + in_quotes(name) + ": pointing chunk of (" +
                  std::to_string(pointing->theta.size()) + ", " + std::to_string(pointing->phi.size()) + ", " +
                  std::to_string(pointing->psi.size()) + ") samples for " + std::to_string(count) +
                  " signal samples (expected equal lengths)");
  }
  if (!flags.empty() && flags.size() != count)
    throw Error(where + ": detector " + in_quotes(name) + ": " + std::to_string(flags.size()) + " flags for " +
                std::to_string(count) + " signal samples (expected equal lengths, or no flags)");
  if (!flags.empty() && !s.with_flags)
    throw Error(where + ": detector " + in_quotes(name) + ": flags given, but the file is written without flags");
  if (s.with_weights && weights.size() != 3 * count)
    throw Error(where + ": detector " + in_quotes(name) + ": " + std::to_string(weights.size()) + " weights for " +
                std::to_string(count) + " signal samples (expected 3 a sample, I, Q, U: the file is written with weights)");
  if (!s.with_weights && !weights.empty())
    throw Error(where + ": detector " + in_quotes(name) + ": weights given, but the file is written without weights");
  if (count == 0) return;
  // Every value finite, and a float32 file's signal within float32's range (beyond it the conversion
  // would store inf): checked before anything is written.
  const auto refuse = [&](const char* dataset, std::size_t i, double v, const std::string& why) {
    throw Error(where + ": detector " + in_quotes(name) + ": " + dataset + " of sample " + std::to_string(offset + i) +
                " is " + detail::number_text(v) + why);
  };
  const bool narrow = s.precision == TodPrecision::float32;
  for (std::size_t i = 0; i < count; ++i) {
    if (!std::isfinite(signal[i])) refuse("the signal", i, signal[i], "; a TOD file holds finite values only");
    if (narrow && std::isinf(static_cast<float>(signal[i])))
      refuse("the signal", i, signal[i],
             ", beyond float32's range (3.4e38) of this file's float32 signal; write it as float64");
  }
  if (s.with_pointing) {
    const std::span<const double> angles[3] = {pointing->theta, pointing->phi, pointing->psi};
    const char* names[3] = {"theta", "phi", "psi"};
    for (int k = 0; k < 3; ++k)
      for (std::size_t i = 0; i < count; ++i)
        if (!std::isfinite(angles[k][i])) refuse(names[k], i, angles[k][i], "; a TOD file holds finite values only");
  }
  for (std::size_t i = 0; i < weights.size(); ++i)
    if (!std::isfinite(weights[i]))
      refuse("a weight", i / 3, weights[i], "; a TOD file holds finite values only");

  // The chunks this write allocates, in every dataset it writes to: those it touches that no earlier
  // write did.
  std::size_t chunks = 0;
  for (std::size_t c = offset / kChunkSamples; c <= (offset + count - 1) / kChunkSamples; ++c)
    chunks += !overlaps(s.written[detector], c * kChunkSamples, (c + 1) * kChunkSamples);
  const std::size_t per_sample = (s.precision == TodPrecision::float32 ? 4 : 8) + (s.with_pointing ? 7 * 8 : 0) +
                                 (s.with_flags ? 1 : 0) + (s.with_weights ? 3 * 8 : 0);
  check_room_for_data(s.temporary, static_cast<unsigned long long>(chunks) * kChunkSamples * per_sample, where,
                      "samples " + std::to_string(offset) + ".." + std::to_string(offset + count - 1) + " of detector " +
                          in_quotes(name));
  s.open_datasets(detector);
  if (s.precision == TodPrecision::float32) {
    s.buffer.resize(count);
    std::transform(signal.begin(), signal.end(), s.buffer.begin(), [](double v) { return static_cast<float>(v); });
    s.write_slab(0, "signal", detector, offset, count, H5T_NATIVE_FLOAT, s.buffer.data());
  } else {
    s.write_slab(0, "signal", detector, offset, count, H5T_NATIVE_DOUBLE, signal.data());
  }
  if (s.with_pointing) {
    s.write_slab(1, "theta", detector, offset, count, H5T_NATIVE_DOUBLE, pointing->theta.data());
    s.write_slab(2, "phi", detector, offset, count, H5T_NATIVE_DOUBLE, pointing->phi.data());
    s.write_slab(3, "psi", detector, offset, count, H5T_NATIVE_DOUBLE, pointing->psi.data());
    s.quats.resize(count);
    for (std::size_t i = 0; i < count; ++i)
      s.quats[i] = quat_from_pointing(pointing->theta[i], pointing->phi[i], pointing->psi[i]);
    s.write_slab(4, tod::quat_name, detector, offset, count, H5T_NATIVE_DOUBLE, s.quats.data(), 4);
  }
  if (s.with_flags && !flags.empty())
    s.write_slab(5, tod::flags_name, detector, offset, count, H5T_NATIVE_UINT8, flags.data());
  if (s.with_weights)
    s.write_slab(6, tod::weights_name, detector, offset, count, H5T_NATIVE_DOUBLE, weights.data(), 3);
  add_interval(s.written[detector], offset, offset + count);
}

void TodWriter::commit() {
  Session session;
  const std::string where = file_.string();
  if (!impl_) throw Error(where + ": TodWriter::commit() on a moved-from writer");
  Impl& s = *impl_;
  if (s.closed) throw Error(where + ": TodWriter::commit() called twice");
  for (std::size_t d = 0; d < s.names.size() && !s.shared; ++d) {
    const auto& intervals = s.written[d];
    if (s.samples == 0) break;
    if (intervals.size() == 1 && intervals.begin()->first == 0 && intervals.begin()->second == s.samples)
      continue;
    const std::size_t first_missing =
        (intervals.empty() || intervals.begin()->first > 0) ? 0 : intervals.begin()->second;
    throw Error(where + ": detector " + in_quotes(s.names[d]) + ": sample " + std::to_string(first_missing) +
                " of " + std::to_string(s.samples) + " was never written (expected every sample before commit())");
  }
  // Everything reaches the disk before any handle is closed: a full disk fails here, and the writer,
  // still uncommitted, abandons the file (a close that failed would leave HDF5 broken).
  check_room_for_metadata(s.file.get(), s.temporary, where);
  check(H5Fflush(s.file.get(), H5F_SCOPE_GLOBAL), where,
        "cannot flush the temporary file " + in_quotes(s.temporary.string()));
  bool ok = true;
  for (Handle& d : s.datasets) ok = d.close() && ok;
  s.open_detector = static_cast<std::size_t>(-1);
  if (!ok) fail(where, "cannot close the datasets of the temporary file " + in_quotes(s.temporary.string()));
  if (!s.file.close()) {
    s.closed = true;
    fail(where, "cannot close the temporary file " + in_quotes(s.temporary.string()));
  }
  s.closed = true;
  if (s.shared) {
    if (s.shared->barrier) s.shared->barrier();
    if (!s.shared->leader) {  // the leader renames the file
      s.committed = true;
      s.listed.reset();
      return;
    }
  }
  std::error_code ec;
  fs::rename(s.temporary, file_, ec);
  if (ec)
    throw Error(where + ": cannot rename the temporary file " + in_quotes(s.temporary.string()) + " to it: " +
                ec.message());
  s.committed = true;
  s.listed.reset();
}

}  // namespace pisco
