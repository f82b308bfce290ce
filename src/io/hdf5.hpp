// The HDF5 layer under the library's file readers and writers (TOD and pointing files, and whatever
// else is stored in HDF5): identifiers closed by RAII, one process-wide lock, and errors that name the
// file, the object and the operation, with HDF5's own reason appended.
//
// Conventions: `where` is the file as the caller named it, and every message starts "<where>: ";
// objects are named in messages by their absolute path in quotes ('/det0/theta'); `expected`, where a
// function takes it, ends a message about a wrong object ("... (expected <expected>)"). Every function
// here calls HDF5, and must run while a Session is alive.
#pragma once

#include <hdf5.h>

#include <cstddef>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace pisco::detail::hdf5 {

// All HDF5 calls of the library go through one lock (HDF5 builds without thread safety exist), with
// HDF5's automatic error printing switched off for the duration and restored afterwards. Recursive:
// a function holding a Session may call another that takes one.
class Session {
 public:
  Session();
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

 private:
  std::lock_guard<std::recursive_mutex> lock_;
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
  bool saved_ = false;
};

// Runs `read` first in a child process (fork), so that a corrupt file on which the HDF5 library itself
// crashes, loops or asks for gigabytes (HDF5 1.10 does, on some files: the fuzzing of docs/validation.md)
// ends there and becomes one pisco::Error naming `where`: "the HDF5 library crashed reading the file
// (signal 11): the file is corrupt". A pisco::Error thrown by `read` in the child is thrown again here
// with its message. Returns when `read` succeeded in the child: the caller then reads for real. Call it
// holding a Session (no other thread is then inside HDF5 when the process forks). Inside the child it
// does nothing (one level of isolation), and so does the MPI build (its parallel HDF5 cannot run in a
// forked child of an MPI process). The child is given PISCO_HDF5_PROBE_SECONDS (default 30) and,
// outside the sanitizer builds, 2 GiB of address space beyond the parent's.
void run_isolated(const std::string& where, const std::function<void()>& read);

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

// ---- errors and text

// The most specific message on HDF5's error stack (then cleared), as " (HDF5: ...)", or "".
std::string hdf5_detail();
// Throws pisco::Error("<where>: <what> (HDF5: ...)").
[[noreturn]] void fail(const std::string& where, const std::string& what);
// id as a Handle closed by `close`; fails with `what` when id is negative (an HDF5 failure).
Handle checked(hid_t id, Handle::Closer close, const std::string& where, const std::string& what);
// Fails with `what` when status is negative.
void check(herr_t status, const std::string& where, const std::string& what);
// 's' in single quotes, as objects and names appear in messages.
std::string in_quotes(const std::string& s);
// A double as text that reads back exactly (%.17g).
std::string format_double(double v);
// A name usable as one link of an HDF5 path: non-empty, without '/', neither "." nor "..".
bool valid_link_name(const std::string& name);

// ---- files

// File access properties: strong close degree, and file locking where the file system supports it
// (without failing where it does not: NFS, some containers).
Handle file_access_plist(const std::string& where);

// The operating-system descriptor of an open file (the sec2 driver's); -1 when HDF5 gives none.
int file_descriptor(hid_t file) noexcept;

// Prepares a file that is being written and will not be completed (an error, a full disk) for its
// handles to be closed: its descriptor is diverted to an anonymous file in memory, so that HDF5's
// final flush, truncation and close succeed. (In HDF5 1.10 a close that fails leaves a freed file
// under a live identifier, and the library's exit handler then crashes on it.) The caller closes its
// handles, then removes the file by name.
void abandon_file(hid_t file) noexcept;

// Fails ("no space left on the device ...") unless the file system of `file` (open as `id`) has room
// for the metadata HDF5 still holds in memory, so that the final flush does not meet a full disk: in
// HDF5 1.10 a failed metadata flush leaves the cache unable to flush again, and the file can then be
// neither completed nor closed.
void check_room_for_metadata(hid_t id, const std::filesystem::path& file, const std::string& where);

// Fails ("no space left on the device for <what> (N bytes, M free)") unless the file system of `file`
// has room for `bytes` more (and a margin for metadata): checked before raw data is written, so that
// a full disk is met here rather than inside HDF5, whose failed writes leak their buffers.
void check_room_for_data(const std::filesystem::path& file, unsigned long long bytes, const std::string& where,
                         const std::string& what);

// Test hook (PISCO_TEST_FAULT=write-fail:NAME, io/output_file.hpp): when `target` is the file to
// fail, the descriptor of `file`, just created, is made to refer to /dev/full.
void inject_write_fault(hid_t file, const std::filesystem::path& target);

// Opens an existing HDF5 file read-only. Errors name the file: "no such file (expected an HDF5 file)",
// "is a directory (expected an HDF5 file)", "not an HDF5 file", or HDF5's reason for failing to open.
Handle open_read_only(const std::filesystem::path& file);

// ---- links and groups

// Whether group `loc` has a link `name` (the object may still be missing: a dangling soft link).
// `what` names the object in the error of a failed lookup ("dataset '/det0/theta'").
bool has_link(hid_t loc, const std::string& name, const std::string& where, const std::string& what);

enum class Members { all, groups, datasets };

// The members of the group at `group_path` (absolute, or relative to loc), in creation order where
// the group tracks and indexes it, else in name order. With `groups` or `datasets`, only the members
// of that kind; dangling soft and external links are then skipped.
std::vector<std::string> list_members(hid_t loc, const std::string& group_path, const std::string& where,
                                      Members which = Members::all);

// Opens the group at `path` (absolute, or relative to loc). Errors: "no group '<path>'", "'<path>' is
// not a group".
Handle open_group(hid_t loc, const std::string& path, const std::string& where);

// ---- datasets

struct Dataset {
  Handle handle;
  std::string path;                  // absolute, as messages name it
  H5T_class_t type_class = H5T_NO_CLASS;
  std::vector<hsize_t> shape;        // empty for a scalar dataset
  std::size_t elements() const;      // the product of shape
};

// Opens dataset `name` of group `loc`, whose absolute path is `path`, with its type class and shape.
// Errors name the file and the dataset: "no dataset '<path>'", "'<path>' is not a dataset".
Dataset open_dataset(hid_t loc, const std::string& name, const std::string& path, const std::string& where,
                     const std::string& expected);

// Fails unless the dataset is floating point ("dataset '<path>' is not floating point") and has `rank`
// dimensions ("dataset '<path>' has N dimensions"), each message ending "(expected <expected>)".
void require_float(const Dataset& dataset, int rank, const std::string& where, const std::string& expected);

// The whole dataset converted to float64, row-major.
std::vector<double> read_float64(const Dataset& dataset, const std::string& where);

// A floating-point dataset of `rank` dimensions (1 or 2: a column, or rows x columns) read whole as
// float64, with its shape.
struct Float64Array {
  std::vector<double> values;        // row-major
  std::vector<std::size_t> shape;    // rank entries
};
Float64Array read_float64_dataset(hid_t loc, const std::string& name, const std::string& path, int rank,
                                  const std::string& where, const std::string& expected);

// ---- attributes

// The names of the attributes of object `obj`, in name order; `what` names them in the error.
std::vector<std::string> attribute_names(hid_t obj, const std::string& where, const std::string& what);

// The value of a scalar (one-element) string or numeric attribute as text (numbers as %.17g or
// integers); false for other shapes and types. `what` names the attribute in errors.
bool attribute_as_text(hid_t attr, std::string& out, const std::string& where, const std::string& what);

// The string attribute `name` of the object at `object_path` (open as obj): nullopt when absent;
// an error naming the attribute and the object when it is not a scalar string.
std::optional<std::string> read_string_attribute(hid_t obj, const std::string& name,
                                                 const std::string& object_path, const std::string& where);

// A variable-length UTF-8 string attribute.
void write_string_attribute(hid_t loc, const std::string& key, const std::string& value, const std::string& where);

// A scalar attribute of the group `group` (a name at the root, for messages).
void write_scalar_attribute(hid_t loc, const char* key, hid_t file_type, hid_t mem_type, const void* value,
                            const std::string& where, const std::string& group);

}  // namespace pisco::detail::hdf5
