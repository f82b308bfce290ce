// Errors: every bad input is reported by throwing pisco::Error with a message that names the file,
// key, value or sample and what was expected (docs/formats.md, "Errors and partial files"), and a
// kind that a caller can act on without reading the message (docs/library.md, "Errors").
#pragma once

#include <stdexcept>
#include <string>
#include <utility>

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

// key(): the setting, keyword or field the error concerns, where the code that found it knows it and
// its message does not name it; the caller that knows where it came from (a simulation file's table,
// a Python keyword, a command-line flag) names it with its own prefix (Error::named) instead of
// checking the value again. Empty where the message says it all.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what, ErrorKind kind = ErrorKind::input, std::string key = {})
      : std::runtime_error(what), kind_(kind), key_(std::move(key)) {}
  explicit Error(const char* what, ErrorKind kind = ErrorKind::input) : std::runtime_error(what), kind_(kind) {}
  ErrorKind kind() const noexcept { return kind_; }
  const std::string& key() const noexcept { return key_; }
  // The message with the key named as `prefix` + key + ": " (the message alone when there is no key).
  std::string named(const std::string& prefix = {}) const {
    return key_.empty() ? std::string(what()) : prefix + key_ + ": " + what();
  }

 private:
  ErrorKind kind_;
  std::string key_;
};

}  // namespace pisco
