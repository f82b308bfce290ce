// Output files written whole or not at all (docs/formats.md, "Errors and partial files"), and the
// temporary files a process must remove when it has to stop at once.
//
// Every writer of the library (TodWriter, write_healpix_map, Sky::write_fits, Beamsor::write_healpix_fits,
// BoresightFile::write, write_file_atomically) writes under a temporary name in the target's directory
// (file + ".tmp-<pid>"), renames it over the target when complete, and removes it on any failure: a full
// disk is a pisco::Error naming the file and the reason, never a partial file under the final name.
// While a temporary exists it is listed here, so that a program stopped by a signal can remove it.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string_view>
#include <vector>

namespace pisco {

// Writes `contents` to `file` whole: under file + ".tmp-<pid>", closed and renamed over `file`. On a
// failure (a full disk, a missing directory, no permission) the temporary is removed and
// pisco::Error names the file and the system's reason.
void write_file_atomically(const std::filesystem::path& file, std::string_view contents);

// The temporary files of the library's writers that exist now (in no particular order).
std::vector<std::filesystem::path> temporary_files();

// Removes every temporary file listed by temporary_files() and returns how many it removed. For a
// process that must stop now (pisco-vk on SIGINT, SIGTERM or SIGHUP removes them, then ends with
// _exit): safe to call from any thread while writers run, not from a signal handler. A writer still
// running afterwards fails or commits nothing that it had not renamed already.
std::size_t remove_temporary_files() noexcept;

}  // namespace pisco
