// Input files are regular files (docs/formats.md, "What is refused"): a FIFO, a device or a socket
// named as an input would block the reader forever or feed it without end, and a directory is no file.
#pragma once

#include <sys/stat.h>

#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <string>
#include <system_error>

#include "pisco/error.hpp"

namespace pisco::detail {

// Throws pisco::Error naming `file` unless it is a regular file (a symbolic link to one is followed);
// `expected` says what the file should be ("a TICRA GRASP .grd or .cut file"). Returns its size in
// bytes, against which a reader checks the sizes the file declares before allocating.
inline std::uintmax_t require_regular_file(const std::filesystem::path& file, const std::string& expected) {
  struct stat st {};
  if (::stat(file.c_str(), &st) != 0) {
    const int e = errno;
    if (e == ENOENT) throw Error(file.string() + ": no such file (expected " + expected + ")");
    throw Error(file.string() + ": cannot be read (" + std::error_code(e, std::generic_category()).message() +
                    "; expected " + expected + ")",
                ErrorKind::io);
  }
  if (S_ISDIR(st.st_mode)) throw Error(file.string() + ": is a directory (expected " + expected + ")");
  if (!S_ISREG(st.st_mode)) {
    const char* kind = S_ISFIFO(st.st_mode) ? "a FIFO"
                       : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device"
                       : S_ISSOCK(st.st_mode) ? "a socket"
                                              : "not a regular file";
    throw Error(file.string() + ": is " + std::string(kind) + "; inputs are read from regular files only (expected " +
                expected + ")");
  }
  return static_cast<std::uintmax_t>(st.st_size);
}

}  // namespace pisco::detail
