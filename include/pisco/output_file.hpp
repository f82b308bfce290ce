// Output files written whole or not at all (docs/formats.md, "Errors and partial files"), the
// temporary files a process must remove when it has to stop at once, and the lock of an output
// directory.
//
// Every writer of the library (TodWriter, write_healpix_map, Sky::write_fits, Beamsor::write_healpix_fits,
// BoresightFile::write, write_file_atomically) writes under a temporary name in the target's directory
// (file + temporary_suffix()), renames it over the target when complete, and removes it on any failure:
// a full disk is a pisco::Error naming the file and the reason, never a partial file under the final
// name. While a temporary exists it is listed here, so that a program stopped by a signal can remove it.
#pragma once

#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace pisco {

// The suffix of this process's temporary files: ".tmp-pisco-<pid>-<16 random hex digits>", the same
// for the whole process. A name no user's file has: the lock of an output directory records it, and
// the next run there removes exactly the files that end with it if this process is killed.
const std::string& temporary_suffix();

// Writes `contents` to `file` whole: under file + temporary_suffix(), closed and renamed over `file`. On a
// failure (a full disk, a missing directory, no permission) the temporary is removed and
// pisco::Error names the file and the system's reason.
void write_file_atomically(const std::filesystem::path& file, std::string_view contents);

// The temporary files of the library's writers that exist now (in no particular order).
std::vector<std::filesystem::path> temporary_files();

// Removes every temporary file listed by temporary_files() and returns how many it removed. For a
// process that must stop now (pisco-vk on SIGINT, SIGTERM or SIGHUP removes them, then ends with
// _exit): safe to call from any thread while writers run, not from a signal handler. A writer still
// running afterwards fails or commits nothing that it had not renamed already.
// Also releases every OutputLock this process holds (their lock files are removed), so that the
// output directories are left as a finished run leaves them.
std::size_t remove_temporary_files() noexcept;

// The lock of an output directory: one run writes into a directory at a time (docs/formats.md,
// "Errors and partial files"). pisco::Simulation::run takes it (so pisco-vk run and Python's
// pisco.Simulation take the same one); a program that writes into the directory outside the run (pisco-vk
// and its plots) takes it itself first and tells the run so (SimulationOptions::lock_output).
//
// The lock is an flock on DIR/.pisco-vk.lock, which the kernel releases whatever ends the process. The
// file records the holder's process id and temporary_suffix(). Taking the lock:
// - never follows a link and never truncates or removes a file that is not a lock file of this
//   program: a `.pisco-vk.lock` that is a symbolic link, has other hard links, is not a regular file
//   or holds anything else is refused, named, and left alone;
// - removes the temporary files of a run that was killed (the lock file it left records their
//   suffix; only files ending with exactly that suffix are removed, each told to `say`);
// - throws pisco::Error naming the directory and the holder's process id when another process holds
//   it, or when this process holds it already.
// Released by the destructor: the lock file is removed, then unlocked.
class OutputLock {
 public:
  explicit OutputLock(const std::filesystem::path& dir, const std::function<void(const std::string&)>& say = {});
  ~OutputLock();
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;

  // Whether this process holds the lock of `dir` (the same directory by device and inode).
  static bool held(const std::filesystem::path& dir);

  // The lock file's name in a directory.
  static constexpr const char* file_name = ".pisco-vk.lock";

 private:
  int slot_ = -1;
};

}  // namespace pisco
