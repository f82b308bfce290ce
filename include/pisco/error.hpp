// Errors: every bad input is reported by throwing pisco::Error with a message that names the file,
// key, value or sample and what was expected (docs/formats.md, "Errors and partial files"), and a
// kind that a caller can act on without reading the message (docs/library.md, "Errors").
#pragma once

#include <stdexcept>
#include <string>

namespace pisco {

// What went wrong, for a caller that handles some failures itself (e.g. falls back on another
// backend when one is unavailable).
enum class ErrorKind {
  input,        // a bad argument, file content or configuration: fix the input
  unavailable,  // a backend, device, driver or library that is not present on this machine
  device,       // a device failed while working: out of its memory, lost, or a driver error
  io,           // a file could not be opened, read, written or renamed (disk, permissions)
  internal,     // a broken invariant of the library itself: a bug to report
};

// "input", "unavailable", "device", "io" or "internal".
const char* error_kind_name(ErrorKind kind) noexcept;

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what, ErrorKind kind = ErrorKind::input) : std::runtime_error(what), kind_(kind) {}
  explicit Error(const char* what, ErrorKind kind = ErrorKind::input) : std::runtime_error(what), kind_(kind) {}
  ErrorKind kind() const noexcept { return kind_; }

 private:
  ErrorKind kind_;
};

}  // namespace pisco
