#include "io/hdf5.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <set>
#include <array>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>

#include "io/input_file.hpp"
#include "io/output_file.hpp"
#include "core/text.hpp"
#include "pisco/error.hpp"

namespace pisco::detail::hdf5 {

namespace fs = std::filesystem;

namespace {

bool probe_child = false;  // this process is run_isolated's child

std::recursive_mutex& hdf5_mutex() {
  static std::recursive_mutex m;
  // run_isolated's child: the parent's lock was copied held by a thread the child does not have (a
  // recursive mutex records its owner's thread id, and the child's differs), so the child has its own.
  static std::recursive_mutex child;
  return probe_child ? child : m;
}

herr_t walk_error(unsigned n, const H5E_error2_t* e, void* data) {
  if (n == 0 && e != nullptr && e->desc != nullptr) *static_cast<std::string*>(data) = e->desc;
  return 0;
}

herr_t collect_link_name(hid_t, const char* name, const H5L_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

herr_t collect_attribute_name(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

// "the root group" or "group '/a/b'", as messages name a group.
std::string group_text(const std::string& path) { return path == "/" ? "the root group" : "group " + in_quotes(path); }

}  // namespace

// ---------------------------------------------------------------- session, errors, text

Session::Session() : lock_(hdf5_mutex()) {
  saved_ = H5Eget_auto2(H5E_DEFAULT, &func_, &data_) >= 0;
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

Session::~Session() {
  H5Eclear2(H5E_DEFAULT);
  if (saved_) H5Eset_auto2(H5E_DEFAULT, func_, data_);
}

std::string hdf5_detail() {
  std::string desc;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, walk_error, &desc);
  H5Eclear2(H5E_DEFAULT);
  // The file driver's messages span lines and carry the time, descriptor and buffer of the failed
  // call ("file write failed: time = ..., errno = 28, error message = 'No space left on device', ..."):
  // keep what failed and the system's reason, on one line.
  const std::string marker = "error message = '";
  if (const auto m = desc.find(marker); m != std::string::npos) {
    const auto end = desc.find('\'', m + marker.size());
    const std::string reason = desc.substr(m + marker.size(), end == std::string::npos ? end : end - m - marker.size());
    const auto colon = desc.find(':');
    desc = (colon == std::string::npos || colon > m ? std::string() : desc.substr(0, colon) + ": ") + reason;
  }
  for (char& c : desc)
    if (c == '\n' || c == '\r') c = ' ';
  return desc.empty() ? std::string() : " (HDF5: " + desc + ")";
}

// A failed HDF5 call: the file could not be read or written as asked (ErrorKind::io).
void fail(const std::string& where, const std::string& what) {
  throw Error(where + ": " + what + hdf5_detail(), ErrorKind::io);
}

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

bool valid_link_name(const std::string& name) {
  return !name.empty() && name.find('/') == std::string::npos && name != "." && name != "..";
}

// ---------------------------------------------------------------- files

Handle file_access_plist(const std::string& where) {
  Handle fapl = checked(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, where, "cannot create a file access list");
  check(H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG), where, "cannot set the file close degree");
#if H5_VERSION_GE(1, 10, 7)
  check(H5Pset_file_locking(fapl.get(), true, true), where, "cannot set file locking");
#endif
  return fapl;
}

int file_descriptor(hid_t file) noexcept {
  // Only the sec2 driver's handle is a descriptor (the MPI-IO driver's is an MPI_File).
  const hid_t fapl = H5Fget_access_plist(file);
  if (fapl < 0) {
    H5Eclear2(H5E_DEFAULT);
    return -1;
  }
  const hid_t driver = H5Pget_driver(fapl);
  H5Pclose(fapl);
  if (driver != H5FD_SEC2) {
    H5Eclear2(H5E_DEFAULT);
    return -1;
  }
  void* handle = nullptr;
  if (H5Fget_vfd_handle(file, H5P_DEFAULT, &handle) < 0 || handle == nullptr) {
    H5Eclear2(H5E_DEFAULT);
    return -1;
  }
  return *static_cast<int*>(handle);
}

void abandon_file(hid_t file) noexcept {
  const int fd = file_descriptor(file);
  if (fd >= 0) detail::divert_descriptor(fd);
}

namespace {
// Bytes the file system holding `file` can still give this process; nullopt when it does not say.
std::optional<unsigned long long> free_bytes(const fs::path& file) {
  struct statvfs fs_info {};
  const fs::path dir = file.has_parent_path() ? file.parent_path() : fs::path(".");
  if (::statvfs(dir.c_str(), &fs_info) != 0) return std::nullopt;
  const unsigned long long blocks = ::geteuid() == 0 ? fs_info.f_bfree : fs_info.f_bavail;
  return blocks * fs_info.f_frsize;
}
}  // namespace

void check_room_for_metadata(hid_t id, const fs::path& file, const std::string& where) {
  std::size_t max_size = 0, min_clean = 0, current = 0;
  int entries = 0;
  if (H5Fget_mdc_size(id, &max_size, &min_clean, &current, &entries) < 0) {
    H5Eclear2(H5E_DEFAULT);
    return;
  }
  const auto free = free_bytes(file);
  if (free && *free < current + (std::size_t(16) << 10))
    throw Error(where + ": no space left on the device for the file's last " + std::to_string(current) +
                " bytes of metadata (" + std::to_string(*free) + " bytes free)", ErrorKind::io);
}

void check_room_for_data(const fs::path& file, unsigned long long bytes, const std::string& where,
                         const std::string& what) {
  const auto free = free_bytes(file);
  if (free && *free < bytes + (std::size_t(16) << 10))
    throw Error(where + ": no space left on the device for " + what + " (" + std::to_string(bytes) +
                " bytes, " + std::to_string(*free) + " free)", ErrorKind::io);
}

void inject_write_fault(hid_t file, const fs::path& target) {
  if (!detail::write_fault_requested(target)) return;
  const int fd = file_descriptor(file);
  if (fd < 0) throw Error(target.string() + ": PISCO_TEST_FAULT: HDF5 gives no file descriptor", ErrorKind::io);
  detail::make_disk_full(fd, target);
}

namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr bool sanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool sanitized = true;
#else
constexpr bool sanitized = false;
#endif
#else
constexpr bool sanitized = false;
#endif

// The process's address space in bytes (/proc/self/statm's first field), 0 if unknown.
std::uintmax_t address_space() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  unsigned long long pages = 0;
  const int got = std::fscanf(f, "%llu", &pages);
  std::fclose(f);
  return got == 1 ? pages * static_cast<std::uintmax_t>(::sysconf(_SC_PAGESIZE)) : 0;
}

// Every object of the file and, for each dataset, its type and dataspace: the metadata the readers
// walk, so that a crash there happens in the probe.
herr_t visit_object(hid_t loc, const char* name, const H5O_info_t* info, void*) {
  if (info->type != H5O_TYPE_DATASET) return 0;
  const hid_t ds = H5Dopen2(loc, name, H5P_DEFAULT);
  if (ds < 0) return 0;
  const hid_t type = H5Dget_type(ds), space = H5Dget_space(ds);
  if (type >= 0) H5Tclose(type);
  if (space >= 0) H5Sclose(space);
  H5Dclose(ds);
  return 0;
}

}  // namespace

void run_isolated(const std::string& where, const std::function<void()>& read) {
  if (probe_child) return;
#ifdef H5_HAVE_PARALLEL
  // The MPI build's HDF5 (parallel, over Open MPI) cannot be used in a forked child of an MPI process:
  // it waits there for MPI. Inputs are read directly.
  (void)where;
  (void)read;
  return;
#endif
  double seconds = 30;
  if (const char* s = std::getenv("PISCO_HDF5_PROBE_SECONDS"); s && std::atof(s) > 0) seconds = std::atof(s);
  int message[2];
  if (::pipe2(message, O_CLOEXEC) != 0) return;  // no isolation possible: read as before
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(message[0]);
    ::close(message[1]);
    return;
  }
  if (pid == 0) {
    probe_child = true;
    ::close(message[0]);
    // Quiet: the parent speaks (the sanitizers' reports of a library crash included).
    if (const int null = ::open("/dev/null", O_WRONLY); null >= 0) {
      ::dup2(null, STDOUT_FILENO);
      ::dup2(null, STDERR_FILENO);
    }
    if (!sanitized)
      if (const std::uintmax_t now = address_space(); now > 0) {
        const rlimit limit{now + (std::uintmax_t(2) << 30), now + (std::uintmax_t(2) << 30)};
        ::setrlimit(RLIMIT_AS, &limit);
      }
    int code = 0;
    try {
      read();
    } catch (const Error& e) {
      const std::string text = e.what();
      std::size_t done = 0;
      while (done < text.size()) {
        const ssize_t n = ::write(message[1], text.data() + done, text.size() - done);
        if (n <= 0) break;
        done += std::size_t(n);
      }
      code = 3;
    } catch (...) {
      code = 4;  // the parent's own read says what it is
    }
    ::_exit(code);
  }
  ::close(message[1]);
  std::string text;
  int status = 0;
  bool ended = false;
  const auto start = std::chrono::steady_clock::now();
  char buffer[4096];
  while (!ended) {
    pollfd p{message[0], POLLIN, 0};
    if (::poll(&p, 1, 20) > 0) {
      const ssize_t n = ::read(message[0], buffer, sizeof buffer);
      if (n > 0) text.append(buffer, std::size_t(n));
    }
    pid_t got = ::waitpid(pid, &status, WNOHANG);
    if (got == pid) ended = true;
    else if (got < 0 && errno != EINTR) break;
    else if (std::chrono::steady_clock::now() - start > std::chrono::duration<double>(seconds)) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      ::close(message[0]);
      throw Error(where + ": the HDF5 library did not finish reading the file's structure in " + number_text(seconds) +
                      " s (a corrupt file can make it loop; PISCO_HDF5_PROBE_SECONDS gives it longer)",
                  ErrorKind::input);
    }
  }
  for (ssize_t n; (n = ::read(message[0], buffer, sizeof buffer)) > 0;) text.append(buffer, std::size_t(n));
  ::close(message[0]);
  if (!ended) return;  // waitpid failed: read as before
  if (WIFSIGNALED(status))
    throw Error(where + ": the HDF5 library crashed reading the file (signal " + std::to_string(WTERMSIG(status)) +
                "): the file is corrupt");
  const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (code == 3) throw Error(text, ErrorKind::input);
  if (code != 0 && code != 4)
    throw Error(where + ": the HDF5 library failed reading the file (its reading process ended with status " +
                std::to_string(code) + ", out of memory or a memory error): the file is corrupt");
}

Handle open_read_only(const fs::path& file) {
  const std::string where = file.string();
  require_regular_file(file, "an HDF5 file");
  const htri_t is_hdf5 = H5Fis_hdf5(file.c_str());
  if (is_hdf5 < 0) fail(where, "cannot read the file (expected an HDF5 file)");
  if (is_hdf5 == 0) throw Error(where + ": not an HDF5 file");
  Handle fapl = file_access_plist(where);
  // The file's structure walked in a child process first: HDF5 1.10 crashes on some corrupt files.
  // Once a version of a file (device, inode, size, modification time): readers that open it again (a
  // TOD file read detector by detector) do not fork again. Under the Session lock.
  static std::set<std::array<std::int64_t, 5>> walked;
  struct stat st {};
  const bool known = ::stat(file.c_str(), &st) == 0;
  const std::array<std::int64_t, 5> version{std::int64_t(st.st_dev), std::int64_t(st.st_ino), std::int64_t(st.st_size),
                                            std::int64_t(st.st_mtim.tv_sec), std::int64_t(st.st_mtim.tv_nsec)};
  if (!known || walked.count(version) == 0) {
    run_isolated(where, [&] {
      Handle f = checked(H5Fopen(file.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose, where,
                         "cannot open the HDF5 file for reading");
      H5Ovisit2(f.get(), H5_INDEX_NAME, H5_ITER_NATIVE, visit_object, nullptr, H5O_INFO_BASIC);
    });
    if (known) walked.insert(version);
  }
  return checked(H5Fopen(file.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose, where,
                 "cannot open the HDF5 file for reading");
}

// ---------------------------------------------------------------- links and groups

bool has_link(hid_t loc, const std::string& name, const std::string& where, const std::string& what) {
  const htri_t exists = H5Lexists(loc, name.c_str(), H5P_DEFAULT);
  if (exists < 0) fail(where, "cannot look up " + what);
  return exists > 0;
}

std::vector<std::string> list_members(hid_t loc, const std::string& group_path, const std::string& where,
                                      Members which) {
  const std::string group = group_text(group_path);
  Handle g = checked(H5Gopen2(loc, group_path.c_str(), H5P_DEFAULT), H5Gclose, where, "cannot open " + group);
  Handle gcpl = checked(H5Gget_create_plist(g.get()), H5Pclose, where,
                        group_path == "/" ? "cannot get the root group's creation properties"
                                          : "cannot get the creation properties of " + group);
  unsigned order_flags = 0;
  check(H5Pget_link_creation_order(gcpl.get(), &order_flags), where, "cannot get the link creation order");
  const H5_index_t index = (order_flags & H5P_CRT_ORDER_INDEXED) ? H5_INDEX_CRT_ORDER : H5_INDEX_NAME;
  std::vector<std::string> links;
  check(H5Literate(g.get(), index, H5_ITER_INC, nullptr, collect_link_name, &links), where, "cannot list " + group);
  if (which == Members::all) return links;
  const H5I_type_t wanted = which == Members::groups ? H5I_GROUP : H5I_DATASET;
  std::vector<std::string> out;
  for (const std::string& name : links) {
    const hid_t object = H5Oopen(g.get(), name.c_str(), H5P_DEFAULT);
    if (object < 0) {  // a dangling soft or external link
      H5Eclear2(H5E_DEFAULT);
      continue;
    }
    Handle guard(object, H5Oclose);
    if (H5Iget_type(object) == wanted) out.push_back(name);
  }
  return out;
}

Handle open_group(hid_t loc, const std::string& path, const std::string& where) {
  if (path != "/" && !has_link(loc, path, where, "group " + in_quotes(path)))
    throw Error(where + ": no group " + in_quotes(path));
  Handle object = checked(H5Oopen(loc, path.c_str(), H5P_DEFAULT), H5Oclose, where, "cannot open " + in_quotes(path));
  if (H5Iget_type(object.get()) != H5I_GROUP) throw Error(where + ": " + in_quotes(path) + " is not a group");
  return object;
}

// ---------------------------------------------------------------- datasets

std::size_t Dataset::elements() const {
  std::size_t n = 1;
  for (hsize_t d : shape) n *= static_cast<std::size_t>(d);
  return n;
}

Dataset open_dataset(hid_t loc, const std::string& name, const std::string& path, const std::string& where,
                     const std::string& expected) {
  const std::string q = in_quotes(path);
  const std::string tail = expected.empty() ? std::string() : " (expected " + expected + ")";
  if (!has_link(loc, name, where, "dataset " + q)) throw Error(where + ": no dataset " + q + tail);
  const hid_t object = H5Oopen(loc, name.c_str(), H5P_DEFAULT);
  if (object < 0) fail(where, "cannot open " + q);
  const H5I_type_t kind = H5Iget_type(object);
  H5Oclose(object);
  if (kind != H5I_DATASET) throw Error(where + ": " + q + " is not a dataset" + tail);
  Dataset out;
  out.path = path;
  out.handle = checked(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose, where, "cannot open dataset " + q);
  Handle type = checked(H5Dget_type(out.handle.get()), H5Tclose, where, "cannot get the type of " + q);
  out.type_class = H5Tget_class(type.get());
  Handle space = checked(H5Dget_space(out.handle.get()), H5Sclose, where, "cannot get the dataspace of " + q);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) fail(where, "cannot get the rank of " + q);
  out.shape.resize(static_cast<std::size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space.get(), out.shape.data(), nullptr) < 0)
    fail(where, "cannot get the size of " + q);
  // What the dataset declares against what the file holds, before a reader allocates for it: a few
  // hundred bytes must not declare gigabytes. Compression may hold data in less room than it takes
  // in memory, so the bound is generous: 64 times the file, plus 64 MiB.
  {
    double elements = 1;
    for (hsize_t d : out.shape) elements *= double(d);
    const double bytes = elements * double(std::max<std::size_t>(1, H5Tget_size(type.get())));
    hsize_t file_bytes = 0;
    const hid_t file = H5Iget_file_id(out.handle.get());
    if (file >= 0) {
      H5Fget_filesize(file, &file_bytes);
      H5Fclose(file);
    }
    if (file_bytes > 0 && bytes > 64.0 * double(file_bytes) + 64.0 * 1024 * 1024)
      throw Error(where + ": dataset " + q + " declares " + detail::count_text(elements) + " elements (" +
                  detail::bytes_text(bytes) + "), more than 64 times the file's " + std::to_string(file_bytes) +
                  " bytes: not data this file holds" + tail);
  }
  return out;
}

void require_float(const Dataset& dataset, int rank, const std::string& where, const std::string& expected) {
  const std::string q = in_quotes(dataset.path);
  if (dataset.type_class != H5T_FLOAT)
    throw Error(where + ": dataset " + q + " is not floating point (expected " + expected + ")");
  if (dataset.shape.size() != static_cast<std::size_t>(rank))
    throw Error(where + ": dataset " + q + " has " + std::to_string(dataset.shape.size()) +
                " dimensions (expected " + expected + ")");
}

std::vector<double> read_float64(const Dataset& dataset, const std::string& where) {
  std::vector<double> values(dataset.elements());
  if (!values.empty())
    check(H5Dread(dataset.handle.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), where,
          "cannot read dataset " + in_quotes(dataset.path));
  return values;
}

Float64Array read_float64_dataset(hid_t loc, const std::string& name, const std::string& path, int rank,
                                  const std::string& where, const std::string& expected) {
  const Dataset dataset = open_dataset(loc, name, path, where, expected);
  require_float(dataset, rank, where, expected);
  Float64Array out;
  out.shape.assign(dataset.shape.begin(), dataset.shape.end());
  out.values = read_float64(dataset, where);
  return out;
}

// ---------------------------------------------------------------- attributes

std::vector<std::string> attribute_names(hid_t obj, const std::string& where, const std::string& what) {
  std::vector<std::string> names;
  check(H5Aiterate2(obj, H5_INDEX_NAME, H5_ITER_INC, nullptr, collect_attribute_name, &names), where,
        "cannot list " + what);
  return names;
}

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
    if (H5Tget_strpad(type.get()) == H5T_STR_SPACEPAD) buffer.erase(buffer.find_last_not_of(' ') + 1);
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

std::optional<std::string> read_string_attribute(hid_t obj, const std::string& name,
                                                 const std::string& object_path, const std::string& where) {
  const std::string what = "attribute " + in_quotes(name) + " of " + in_quotes(object_path);
  const htri_t exists = H5Aexists(obj, name.c_str());
  if (exists < 0) fail(where, "cannot look up " + what);
  if (exists == 0) return std::nullopt;
  Handle attr = checked(H5Aopen(obj, name.c_str(), H5P_DEFAULT), H5Aclose, where, "cannot open " + what);
  Handle type = checked(H5Aget_type(attr.get()), H5Tclose, where, "cannot get the type of " + what);
  std::string value;
  if (H5Tget_class(type.get()) != H5T_STRING || !attribute_as_text(attr.get(), value, where, what))
    throw Error(where + ": " + what + " is not a string (expected one string)");
  return value;
}

void write_string_attribute(hid_t loc, const std::string& key, const std::string& value, const std::string& where) {
  const std::string what = "attribute " + in_quotes(key);
  Handle type = checked(H5Tcopy(H5T_C_S1), H5Tclose, where, "cannot create the string type for " + what);
  check(H5Tset_size(type.get(), H5T_VARIABLE), where, "cannot size the string type for " + what);
  check(H5Tset_cset(type.get(), H5T_CSET_UTF8), where, "cannot set UTF-8 for " + what);
  Handle space = checked(H5Screate(H5S_SCALAR), H5Sclose, where, "cannot create the dataspace for " + what);
  Handle attr = checked(H5Acreate2(loc, key.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
                        where, "cannot create " + what);
  const char* text = value.c_str();
  check(H5Awrite(attr.get(), type.get(), &text), where, "cannot write " + what);
  if (!attr.close()) fail(where, "cannot close " + what);
}

void write_scalar_attribute(hid_t loc, const char* key, hid_t file_type, hid_t mem_type, const void* value,
                            const std::string& where, const std::string& group) {
  const std::string what = "attribute " + in_quotes(key) + " of group " + in_quotes("/" + group);
  Handle space = checked(H5Screate(H5S_SCALAR), H5Sclose, where, "cannot create the dataspace for " + what);
  Handle attr = checked(H5Acreate2(loc, key, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose, where,
                        "cannot create " + what);
  check(H5Awrite(attr.get(), mem_type, value), where, "cannot write " + what);
  if (!attr.close()) fail(where, "cannot close " + what);
}

}  // namespace pisco::detail::hdf5
