// TOD and pointing files in HDF5 (DESIGN 5, 9, 12), written through the HDF5 C API.
#include "pisco/tod_file.hpp"

#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <mutex>
#include <set>
#include <system_error>
#include <utility>

#include "pisco/error.hpp"

namespace pisco {

namespace fs = std::filesystem;

namespace {

constexpr const char* kFormat = "pisco-tod-1";
constexpr hsize_t kChunkSamples = 16384;  // 128 KiB of float64 per chunk
const char* const kPointingNames[3] = {"theta", "phi", "psi"};

// All HDF5 calls of the library go through one lock (HDF5 builds without thread safety exist), with
// HDF5's automatic error printing switched off for the duration and restored afterwards.
std::recursive_mutex& hdf5_mutex() {
  static std::recursive_mutex m;
  return m;
}

class Session {
 public:
  Session() : lock_(hdf5_mutex()) {
    saved_ = H5Eget_auto2(H5E_DEFAULT, &func_, &data_) >= 0;
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~Session() {
    H5Eclear2(H5E_DEFAULT);
    if (saved_) H5Eset_auto2(H5E_DEFAULT, func_, data_);
  }
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

 private:
  std::lock_guard<std::recursive_mutex> lock_;
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
  bool saved_ = false;
};

// The most specific message on HDF5's error stack (then cleared), as " (HDF5: ...)", or "".
herr_t walk_error(unsigned n, const H5E_error2_t* e, void* data) {
  if (n == 0 && e != nullptr && e->desc != nullptr) *static_cast<std::string*>(data) = e->desc;
  return 0;
}

std::string hdf5_detail() {
  std::string desc;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, walk_error, &desc);
  H5Eclear2(H5E_DEFAULT);
  return desc.empty() ? std::string() : " (HDF5: " + desc + ")";
}

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw Error(where + ": " + what + hdf5_detail());
}

// An HDF5 identifier closed with the matching H5?close.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer close) : id_(id), close_(close) {}
  ~Handle() { reset(); }
  Handle(Handle&& o) noexcept : id_(std::exchange(o.id_, H5I_INVALID_HID)), close_(o.close_) {}
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = std::exchange(o.id_, H5I_INVALID_HID);
      close_ = o.close_;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const noexcept { return id_; }
  bool valid() const noexcept { return id_ >= 0; }
  // Closes now; returns false if HDF5 reported a failure.
  bool close() {
    if (!valid()) return true;
    const herr_t status = close_(std::exchange(id_, H5I_INVALID_HID));
    return status >= 0;
  }
  void reset() noexcept {
    if (valid()) close_(std::exchange(id_, H5I_INVALID_HID));
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
  Closer close_ = nullptr;
};

Handle checked(hid_t id, Handle::Closer close, const std::string& where, const std::string& what) {
  if (id < 0) fail(where, what);
  return Handle(id, close);
}

void check(herr_t status, const std::string& where, const std::string& what) {
  if (status < 0) fail(where, what);
}

std::string in_quotes(const std::string& s) { return "'" + s + "'"; }

std::string format_double(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

// A detector name usable as an HDF5 group name at the root: non-empty, no '/', not "." or "..".
bool valid_group_name(const std::string& name) {
  return !name.empty() && name.find('/') == std::string::npos && name != "." && name != "..";
}

Handle file_access_plist(const std::string& where) {
  Handle fapl = checked(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, where, "cannot create a file access list");
  check(H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG), where, "cannot set the file close degree");
#if H5_VERSION_GE(1, 10, 7)
  // Lock where the file system supports it; do not fail where it does not (NFS, some containers).
  check(H5Pset_file_locking(fapl.get(), true, true), where, "cannot set file locking");
#endif
  return fapl;
}

// ---------------------------------------------------------------- attributes

void write_string_attribute(hid_t loc, const std::string& key, const std::string& value,
                            const std::string& where) {
  const std::string what = "attribute " + in_quotes(key);
  Handle type = checked(H5Tcopy(H5T_C_S1), H5Tclose, where, "cannot create the string type for " + what);
  check(H5Tset_size(type.get(), H5T_VARIABLE), where, "cannot size the string type for " + what);
  check(H5Tset_cset(type.get(), H5T_CSET_UTF8), where, "cannot set UTF-8 for " + what);
  Handle space = checked(H5Screate(H5S_SCALAR), H5Sclose, where, "cannot create the dataspace for " + what);
  Handle attr = checked(H5Acreate2(loc, key.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT),
                        H5Aclose, where, "cannot create " + what);
  const char* text = value.c_str();
  check(H5Awrite(attr.get(), type.get(), &text), where, "cannot write " + what);
  if (!attr.close()) fail(where, "cannot close " + what);
}

void write_scalar_attribute(hid_t loc, const char* key, hid_t file_type, hid_t mem_type, const void* value,
                            const std::string& where, const std::string& group) {
  const std::string what = "attribute " + in_quotes(key) + " of group " + in_quotes("/" + group);
  Handle space = checked(H5Screate(H5S_SCALAR), H5Sclose, where, "cannot create the dataspace for " + what);
  Handle attr = checked(H5Acreate2(loc, key, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
                        where, "cannot create " + what);
  check(H5Awrite(attr.get(), mem_type, value), where, "cannot write " + what);
  if (!attr.close()) fail(where, "cannot close " + what);
}

herr_t collect_attribute_name(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

// The value of a scalar (one-element) string or numeric attribute as text; false for other shapes/types.
bool attribute_as_text(hid_t attr, std::string& out, const std::string& where, const std::string& what) {
  Handle type = checked(H5Aget_type(attr), H5Tclose, where, "cannot get the type of " + what);
  Handle space = checked(H5Aget_space(attr), H5Sclose, where, "cannot get the dataspace of " + what);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) return false;
  const H5T_class_t cls = H5Tget_class(type.get());
  if (cls == H5T_STRING) {
    const htri_t variable = H5Tis_variable_str(type.get());
    if (variable < 0) fail(where, "cannot inspect the string type of " + what);
    if (variable > 0) {
      Handle mem = checked(H5Tcopy(H5T_C_S1), H5Tclose, where, "cannot create a string type for " + what);
      check(H5Tset_size(mem.get(), H5T_VARIABLE), where, "cannot size a string type for " + what);
      check(H5Tset_cset(mem.get(), H5Tget_cset(type.get())), where, "cannot set the character set for " + what);
      char* text = nullptr;
      check(H5Aread(attr, mem.get(), &text), where, "cannot read " + what);
      out = text != nullptr ? text : "";
      H5free_memory(text);
      return true;
    }
    const std::size_t size = H5Tget_size(type.get());
    std::string buffer(size + 1, '\0');
    check(H5Aread(attr, type.get(), buffer.data()), where, "cannot read " + what);
    buffer.resize(std::min(buffer.find('\0'), size));
    if (H5Tget_strpad(type.get()) == H5T_STR_SPACEPAD)
      buffer.erase(buffer.find_last_not_of(' ') + 1);
    out = buffer;
    return true;
  }
  if (cls == H5T_INTEGER) {
    if (H5Tget_sign(type.get()) == H5T_SGN_NONE) {
      unsigned long long v = 0;
      check(H5Aread(attr, H5T_NATIVE_ULLONG, &v), where, "cannot read " + what);
      out = std::to_string(v);
    } else {
      long long v = 0;
      check(H5Aread(attr, H5T_NATIVE_LLONG, &v), where, "cannot read " + what);
      out = std::to_string(v);
    }
    return true;
  }
  if (cls == H5T_FLOAT) {
    double v = 0.0;
    check(H5Aread(attr, H5T_NATIVE_DOUBLE, &v), where, "cannot read " + what);
    out = format_double(v);
    return true;
  }
  return false;
}

// A numeric scalar attribute of a detector group; pisco::Error if it is missing or not numeric.
template <typename T>
T read_numeric_attribute(hid_t group, const char* key, hid_t mem_type, const std::string& where,
                         const std::string& group_name, const char* expected) {
  const std::string what = "attribute " + in_quotes(key) + " of group " + in_quotes("/" + group_name);
  const htri_t exists = H5Aexists(group, key);
  if (exists < 0) fail(where, "cannot look up " + what);
  if (exists == 0) throw Error(where + ": group " + in_quotes("/" + group_name) + " has no attribute " +
                               in_quotes(key) + " (expected " + expected + ")");
  Handle attr = checked(H5Aopen(group, key, H5P_DEFAULT), H5Aclose, where, "cannot open " + what);
  Handle type = checked(H5Aget_type(attr.get()), H5Tclose, where, "cannot get the type of " + what);
  Handle space = checked(H5Aget_space(attr.get()), H5Sclose, where, "cannot get the dataspace of " + what);
  const H5T_class_t cls = H5Tget_class(type.get());
  if ((cls != H5T_FLOAT && cls != H5T_INTEGER) || H5Sget_simple_extent_npoints(space.get()) != 1)
    throw Error(where + ": " + what + " is not a numeric scalar (expected " + expected + ")");
  T value{};
  check(H5Aread(attr.get(), mem_type, &value), where, "cannot read " + what + " (expected " + expected + ")");
  return value;
}

// ---------------------------------------------------------------- reading

Handle open_for_reading(const fs::path& file, const std::string& where) {
  std::error_code ec;
  const fs::file_status status = fs::status(file, ec);
  if (!fs::exists(status)) throw Error(where + ": no such file (expected an HDF5 file)");
  if (fs::is_directory(status)) throw Error(where + ": is a directory (expected an HDF5 file)");
  const htri_t is_hdf5 = H5Fis_hdf5(file.c_str());
  if (is_hdf5 < 0) fail(where, "cannot read the file (expected an HDF5 file)");
  if (is_hdf5 == 0) throw Error(where + ": not an HDF5 file");
  Handle fapl = file_access_plist(where);
  return checked(H5Fopen(file.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose, where,
                 "cannot open the HDF5 file for reading");
}

herr_t collect_link_name(hid_t, const char* name, const H5L_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

// The groups at the root, in creation order where tracked and indexed, else in name order.
std::vector<std::string> root_groups(hid_t file, const std::string& where) {
  Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  Handle gcpl = checked(H5Gget_create_plist(root.get()), H5Pclose, where,
                        "cannot get the root group's creation properties");
  unsigned order_flags = 0;
  check(H5Pget_link_creation_order(gcpl.get(), &order_flags), where, "cannot get the link creation order");
  const H5_index_t index = (order_flags & H5P_CRT_ORDER_INDEXED) ? H5_INDEX_CRT_ORDER : H5_INDEX_NAME;
  std::vector<std::string> links;
  check(H5Literate(root.get(), index, H5_ITER_INC, nullptr, collect_link_name, &links), where,
        "cannot list the root group");
  std::vector<std::string> groups;
  for (const std::string& name : links) {
    const hid_t object = H5Oopen(root.get(), name.c_str(), H5P_DEFAULT);
    if (object < 0) {  // a dangling soft or external link: not a detector
      H5Eclear2(H5E_DEFAULT);
      continue;
    }
    Handle guard(object, H5Oclose);
    if (H5Iget_type(object) == H5I_GROUP) groups.push_back(name);
  }
  return groups;
}

std::string list_for_message(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string s;
  const std::size_t shown = std::min<std::size_t>(names.size(), 10);
  for (std::size_t i = 0; i < shown; ++i) s += (i ? ", " : "") + names[i];
  if (shown < names.size()) s += ", ... (" + std::to_string(names.size()) + " in all)";
  return s;
}

Handle open_detector_group(hid_t file, const std::string& where, const std::string& detector) {
  if (!valid_group_name(detector))
    throw Error(where + ": " + in_quotes(detector) +
                " is not a valid detector name (expected a non-empty group name without '/')");
  const htri_t exists = H5Lexists(file, detector.c_str(), H5P_DEFAULT);
  if (exists < 0) fail(where, "cannot look up group " + in_quotes("/" + detector));
  if (exists == 0)
    throw Error(where + ": no group " + in_quotes("/" + detector) + " for detector " + in_quotes(detector) +
                " (groups in the file: " + list_for_message(root_groups(file, where)) + ")");
  Handle object = checked(H5Oopen(file, detector.c_str(), H5P_DEFAULT), H5Oclose, where,
                          "cannot open " + in_quotes("/" + detector));
  if (H5Iget_type(object.get()) != H5I_GROUP)
    throw Error(where + ": " + in_quotes("/" + detector) + " is not a group (expected one group per detector)");
  return object;
}

// A 1-D floating-point dataset of a detector group.
struct FloatDataset {
  Handle dataset;
  hsize_t length = 0;
};

FloatDataset open_float_dataset(hid_t group, const std::string& where, const std::string& detector,
                                const char* name, const std::string& expected) {
  const std::string path = in_quotes("/" + detector + "/" + name);
  const htri_t exists = H5Lexists(group, name, H5P_DEFAULT);
  if (exists < 0) fail(where, "cannot look up dataset " + path);
  if (exists == 0)
    throw Error(where + ": group " + in_quotes("/" + detector) + " has no dataset " + in_quotes(name) +
                " (expected " + expected + ")");
  const hid_t object = H5Oopen(group, name, H5P_DEFAULT);
  if (object < 0) fail(where, "cannot open " + path);
  const H5I_type_t kind = H5Iget_type(object);
  H5Oclose(object);
  if (kind != H5I_DATASET) throw Error(where + ": " + path + " is not a dataset (expected " + expected + ")");
  FloatDataset out;
  out.dataset = checked(H5Dopen2(group, name, H5P_DEFAULT), H5Dclose, where, "cannot open dataset " + path);
  Handle type = checked(H5Dget_type(out.dataset.get()), H5Tclose, where, "cannot get the type of " + path);
  if (H5Tget_class(type.get()) != H5T_FLOAT)
    throw Error(where + ": dataset " + path + " is not floating point (expected " + expected + ")");
  Handle space = checked(H5Dget_space(out.dataset.get()), H5Sclose, where, "cannot get the dataspace of " + path);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) fail(where, "cannot get the rank of " + path);
  if (rank != 1)
    throw Error(where + ": dataset " + path + " has " + std::to_string(rank) +
                " dimensions (expected " + expected + ")");
  hsize_t dims[1] = {0};
  if (H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0) fail(where, "cannot get the size of " + path);
  out.length = dims[0];
  return out;
}

std::vector<double> read_all(const FloatDataset& ds, const std::string& where, const std::string& path) {
  std::vector<double> values(static_cast<std::size_t>(ds.length));
  if (!values.empty())
    check(H5Dread(ds.dataset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), where,
          "cannot read dataset " + in_quotes(path));
  return values;
}

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

}  // namespace

// ================================================================ TodWriter

struct TodWriter::Impl {
  std::string where;      // the final file, for messages
  fs::path temporary;
  Handle file;
  std::vector<std::string> names;
  std::size_t samples = 0;
  TodPrecision precision = TodPrecision::float64;
  bool with_pointing = false;
  bool committed = false;
  bool closed = false;
  std::vector<std::map<std::size_t, std::size_t>> written;  // per detector
  // The datasets of the detector written last (signal, theta, phi, psi): only one detector's are kept
  // open, so HDF5's chunk caches stay bounded whatever the number of detectors.
  std::size_t open_detector = static_cast<std::size_t>(-1);
  Handle datasets[4];
  std::vector<float> buffer;

  ~Impl() {
    Session session;
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
    datasets[0] = checked(H5Dopen2(group.get(), "signal", H5P_DEFAULT), H5Dclose, where,
                          "cannot open dataset " + in_quotes("/" + name + "/signal"));
    if (with_pointing)
      for (int k = 0; k < 3; ++k)
        datasets[k + 1] = checked(H5Dopen2(group.get(), kPointingNames[k], H5P_DEFAULT), H5Dclose, where,
                                  "cannot open dataset " + in_quotes("/" + name + "/" + kPointingNames[k]));
    open_detector = detector;
  }

  void write_slab(int which, const char* name, std::size_t detector, std::size_t offset, std::size_t count,
                  hid_t mem_type, const void* data) {
    const std::string what = "dataset " + in_quotes("/" + names[detector] + "/" + name);
    const hsize_t start[1] = {offset}, size[1] = {count};
    Handle memory = checked(H5Screate_simple(1, size, nullptr), H5Sclose, where,
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
                     const std::map<std::string, std::string>& attributes)
    : file_(file),
      temporary_(fs::path(file.string() + ".tmp-" + std::to_string(::getpid()))),
      samples_(samples_per_detector) {
  Session session;
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
    if (!valid_group_name(d.name))
      throw Error(where + ": detector name " + in_quotes(d.name) +
                  " cannot name an HDF5 group (expected a non-empty name without '/')");
    if (!seen.insert(d.name).second)
      throw Error(where + ": detector name " + in_quotes(d.name) + " appears twice (expected unique names)");
  }

  impl_ = std::make_unique<Impl>();
  Impl& s = *impl_;
  s.where = where;
  s.names.reserve(focal_plane.size());
  for (const Detector& d : focal_plane.detectors()) s.names.push_back(d.name);
  s.samples = samples_per_detector;
  s.precision = precision;
  s.with_pointing = with_pointing;
  s.written.resize(focal_plane.size());

  Handle fcpl = checked(H5Pcreate(H5P_FILE_CREATE), H5Pclose, where, "cannot create a file creation list");
  // Track link creation order so that readers list detectors in focal-plane order.
  check(H5Pset_link_creation_order(fcpl.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED), where,
        "cannot set the link creation order");
  Handle fapl = file_access_plist(where);
  s.file = checked(H5Fcreate(temporary_.c_str(), H5F_ACC_TRUNC, fcpl.get(), fapl.get()), H5Fclose, where,
                   "cannot create the temporary file " + in_quotes(temporary_.string()));
  s.temporary = temporary_;  // from here on, the Impl removes the temporary file if anything fails

  for (const auto& [key, value] : attributes) {
    if (key == "pisco_format") continue;  // always written below
    if (key.empty()) throw Error(where + ": an attribute has an empty name");
    write_string_attribute(s.file.get(), key, value, where);
  }
  write_string_attribute(s.file.get(), "pisco_format", kFormat, where);

  const hsize_t dims[1] = {static_cast<hsize_t>(samples_per_detector)};
  Handle space = checked(H5Screate_simple(1, dims, nullptr), H5Sclose, where, "cannot create the TOD dataspace");
  Handle dcpl = checked(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, where, "cannot create a dataset creation list");
  if (samples_per_detector > 0) {
    const hsize_t chunk[1] = {std::min<hsize_t>(dims[0], kChunkSamples)};
    check(H5Pset_chunk(dcpl.get(), 1, chunk), where, "cannot set the dataset chunk size");
  }
  // Samples never written read back as NaN (commit() refuses such a file anyway).
  const double nan = std::numeric_limits<double>::quiet_NaN();
  check(H5Pset_fill_value(dcpl.get(), H5T_NATIVE_DOUBLE, &nan), where, "cannot set the dataset fill value");
  const hid_t signal_type = precision == TodPrecision::float32 ? H5T_IEEE_F32LE : H5T_IEEE_F64LE;

  for (const Detector& d : focal_plane.detectors()) {
    const std::string group_path = in_quotes("/" + d.name);
    Handle group = checked(H5Gcreate2(s.file.get(), d.name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                           H5Gclose, where, "cannot create group " + group_path);
    write_scalar_attribute(group.get(), "zeta", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &d.zeta, where, d.name);
    write_scalar_attribute(group.get(), "epsilon", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &d.epsilon, where, d.name);
    write_scalar_attribute(group.get(), "gain", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &d.gain, where, d.name);
    const std::uint64_t beam = d.beam;
    write_scalar_attribute(group.get(), "beam", H5T_STD_U64LE, H5T_NATIVE_UINT64, &beam, where, d.name);
    Handle signal = checked(H5Dcreate2(group.get(), "signal", signal_type, space.get(), H5P_DEFAULT, dcpl.get(),
                                       H5P_DEFAULT),
                            H5Dclose, where, "cannot create dataset " + in_quotes("/" + d.name + "/signal"));
    if (!signal.close()) fail(where, "cannot close dataset " + in_quotes("/" + d.name + "/signal"));
    if (with_pointing)
      for (const char* name : kPointingNames) {
        const std::string path = in_quotes("/" + d.name + "/" + name);
        Handle ds = checked(H5Dcreate2(group.get(), name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, dcpl.get(),
                                       H5P_DEFAULT),
                            H5Dclose, where, "cannot create dataset " + path);
        if (!ds.close()) fail(where, "cannot close dataset " + path);
      }
    if (!group.close()) fail(where, "cannot close group " + group_path);
  }
}

TodWriter::~TodWriter() = default;
TodWriter::TodWriter(TodWriter&&) noexcept = default;
TodWriter& TodWriter::operator=(TodWriter&&) noexcept = default;

void TodWriter::write(std::size_t detector, std::size_t offset, std::span<const double> signal,
                      const PointingView* pointing) {
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
  if (count == 0) return;

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
  }
  add_interval(s.written[detector], offset, offset + count);
}

void TodWriter::commit() {
  Session session;
  const std::string where = file_.string();
  if (!impl_) throw Error(where + ": TodWriter::commit() on a moved-from writer");
  Impl& s = *impl_;
  if (s.closed) throw Error(where + ": TodWriter::commit() called twice");
  for (std::size_t d = 0; d < s.names.size(); ++d) {
    const auto& intervals = s.written[d];
    if (s.samples == 0) break;
    if (intervals.size() == 1 && intervals.begin()->first == 0 && intervals.begin()->second == s.samples)
      continue;
    const std::size_t first_missing =
        (intervals.empty() || intervals.begin()->first > 0) ? 0 : intervals.begin()->second;
    throw Error(where + ": detector " + in_quotes(s.names[d]) + ": sample " + std::to_string(first_missing) +
                " of " + std::to_string(s.samples) + " was never written (expected every sample before commit())");
  }
  bool ok = true;
  for (Handle& d : s.datasets) ok = d.close() && ok;
  s.open_detector = static_cast<std::size_t>(-1);
  if (!ok) fail(where, "cannot close the datasets of the temporary file " + in_quotes(s.temporary.string()));
  if (!s.file.close()) {
    s.closed = true;
    fail(where, "cannot close the temporary file " + in_quotes(s.temporary.string()));
  }
  s.closed = true;
  std::error_code ec;
  fs::rename(s.temporary, file_, ec);
  if (ec)
    throw Error(where + ": cannot rename the temporary file " + in_quotes(s.temporary.string()) + " to it: " +
                ec.message());
  s.committed = true;
}

// ================================================================ reading

std::vector<TodFileDetector> read_tod_detectors(const fs::path& file) {
  Session session;
  const std::string where = file.string();
  Handle h = open_for_reading(file, where);
  std::vector<TodFileDetector> out;
  for (const std::string& name : root_groups(h.get(), where)) {
    Handle group = checked(H5Gopen2(h.get(), name.c_str(), H5P_DEFAULT), H5Gclose, where,
                           "cannot open group " + in_quotes("/" + name));
    TodFileDetector d;
    d.name = name;
    d.zeta = read_numeric_attribute<double>(group.get(), "zeta", H5T_NATIVE_DOUBLE, where, name, "a float64 in rad");
    d.epsilon = read_numeric_attribute<double>(group.get(), "epsilon", H5T_NATIVE_DOUBLE, where, name, "a float64");
    d.gain = read_numeric_attribute<double>(group.get(), "gain", H5T_NATIVE_DOUBLE, where, name, "a float64");
    d.beam = static_cast<std::size_t>(read_numeric_attribute<std::uint64_t>(
        group.get(), "beam", H5T_NATIVE_UINT64, where, name, "an unsigned integer beam index"));
    out.push_back(std::move(d));
  }
  return out;
}

std::vector<double> read_tod_signal(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_for_reading(file, where);
  Handle group = open_detector_group(h.get(), where, detector);
  const FloatDataset ds =
      open_float_dataset(group.get(), where, detector, "signal", "a 1-D float64 or float32 dataset 'signal'");
  return read_all(ds, where, "/" + detector + "/signal");
}

std::map<std::string, std::string> read_tod_attributes(const fs::path& file) {
  Session session;
  const std::string where = file.string();
  Handle h = open_for_reading(file, where);
  Handle root = checked(H5Gopen2(h.get(), "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  std::vector<std::string> names;
  check(H5Aiterate2(root.get(), H5_INDEX_NAME, H5_ITER_INC, nullptr, collect_attribute_name, &names), where,
        "cannot list the file attributes");
  std::map<std::string, std::string> out;
  for (const std::string& name : names) {
    const std::string what = "file attribute " + in_quotes(name);
    Handle attr = checked(H5Aopen(root.get(), name.c_str(), H5P_DEFAULT), H5Aclose, where, "cannot open " + what);
    std::string value;
    if (attribute_as_text(attr.get(), value, where, what)) out.emplace(name, std::move(value));
  }
  return out;
}

Pointing read_pointing_hdf5(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_for_reading(file, where);
  Handle group = open_detector_group(h.get(), where, detector);
  const std::string expected = "1-D float64 or float32 datasets theta, phi and psi of equal length, in rad";
  FloatDataset ds[3];
  for (int k = 0; k < 3; ++k) ds[k] = open_float_dataset(group.get(), where, detector, kPointingNames[k], expected);
  const std::string origin = where + ":/" + detector;
  if (ds[1].length != ds[0].length || ds[2].length != ds[0].length)
    throw Error(origin + ": datasets theta, phi and psi have different lengths (" + std::to_string(ds[0].length) +
                ", " + std::to_string(ds[1].length) + ", " + std::to_string(ds[2].length) +
                "; expected equal lengths)");
  Pointing p;
  p.theta = read_all(ds[0], where, "/" + detector + "/theta");
  p.phi = read_all(ds[1], where, "/" + detector + "/phi");
  p.psi = read_all(ds[2], where, "/" + detector + "/psi");
  check_pointing(p.view(), origin.c_str());
  return p;
}

std::vector<std::string> pointing_detectors(const fs::path& file) {
  Session session;
  const std::string where = file.string();
  Handle h = open_for_reading(file, where);
  return root_groups(h.get(), where);
}

}  // namespace pisco
