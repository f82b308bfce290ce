// The plumbing under include/pisco/output_file.hpp, shared by the library's writers: the list of
// temporary files in progress, the descriptor tricks that let a writer abandon a file on a full disk,
// and the test hook that makes a disk look full.
#pragma once

#include <filesystem>

namespace pisco::detail {

// A temporary file listed by pisco::temporary_files() from construction to destruction. Listed
// before the file is created, so that no temporary exists unlisted.
class TemporaryListing {
 public:
  explicit TemporaryListing(std::filesystem::path temporary);
  ~TemporaryListing();
  TemporaryListing(const TemporaryListing&) = delete;
  TemporaryListing& operator=(const TemporaryListing&) = delete;
  const std::filesystem::path& path() const noexcept { return path_; }

 private:
  std::filesystem::path path_;
};

// file + pisco::temporary_suffix(): the temporary name of every writer.
std::filesystem::path temporary_name(const std::filesystem::path& file);

// Releases every pisco::OutputLock of this process (remove_temporary_files). Safe from any thread.
void release_output_locks() noexcept;

// Test hook: whether PISCO_TEST_FAULT=write-fail:NAME names `file` (its file name), that is whether
// the writer of `file` must find the disk full. Unset (always, outside tests): false.
bool write_fault_requested(const std::filesystem::path& file);

// Makes descriptor `fd` refer to /dev/full, where every write fails with ENOSPC as on a full disk
// (the test hook's effect). Throws pisco::Error naming `file` if it cannot.
void make_disk_full(int fd, const std::filesystem::path& file);

// The descriptor of this process open on `path` (from /proc/self/fd), or -1: for libraries that do
// not expose theirs (CFITSIO).
int descriptor_of(const std::filesystem::path& path);

// Makes descriptor `fd` refer to an anonymous file in memory, so that a library closing a file it
// could not finish writing (HDF5 flushes, truncates and closes; on a full disk each would fail and
// leave the library's state broken) succeeds: used only to abandon a temporary file, which is then
// removed by name. Returns false when no such file can be made (the descriptor is left as it was).
bool divert_descriptor(int fd) noexcept;

}  // namespace pisco::detail
