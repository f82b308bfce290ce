// Scalar arguments and errors of the Python API (docs/python.md, "Errors"): integers that are unsigned
// in C++ are taken as Python ints and checked here, so that a negative value is a ValueError naming
// the argument (nanobind's own conversion would refuse it with a generic TypeError); memory that runs
// out in the library becomes a MemoryError that says what was too large.
#pragma once

#include <cstdio>
#include <limits>
#include <string>

#include <nanobind/nanobind.h>

namespace pisco::python {

namespace nb = nanobind;

// `value` as the unsigned type T, or ValueError naming `name`: negative, or beyond T.
template <class T>
T unsigned_arg(long long value, const char* name) {
  if (value < 0)
    throw nb::value_error((std::string(name) + " = " + std::to_string(value) +
                           " is negative; expected a non-negative integer").c_str());
  if (static_cast<unsigned long long>(value) > std::numeric_limits<T>::max())
    throw nb::value_error((std::string(name) + " = " + std::to_string(value) + " is beyond " +
                           std::to_string(std::numeric_limits<T>::max())).c_str());
  return static_cast<T>(value);
}

// A byte count as "2.58e+10 bytes".
inline std::string bytes_text(double bytes) {
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%.3g bytes", bytes);
  return buffer;
}

// Raises MemoryError(message) (with the GIL held).
[[noreturn]] inline void raise_memory_error(const std::string& message) {
  PyErr_SetString(PyExc_MemoryError, message.c_str());
  throw nb::python_error();
}

}  // namespace pisco::python
