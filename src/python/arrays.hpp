// Checked, zero-copy views of the numpy arrays the Python API takes (docs/python.md, "Arrays").
// nanobind's own cast failure reports only "incompatible function arguments"; these checks name the
// argument and say what is wrong with it, as TypeError (not an array, wrong dtype) or ValueError
// (shape, layout, read-only output, non-finite values). No array is ever copied or converted.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

namespace pisco::python {

namespace nb = nanobind;

using Vector = nb::ndarray<double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using ConstVector = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using ConstMatrix = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

// str(obj).
inline std::string to_string(nb::handle obj) {
  nb::object s = nb::steal(PyObject_Str(obj.ptr()));
  if (!s.is_valid()) throw nb::python_error();
  return nb::cast<std::string>(s);
}

// "list", "int64 array of shape (3, 4)", ...
inline std::string describe(nb::handle obj) {
  if (obj.is_none()) return "None";
  if (nb::hasattr(obj, "dtype") && nb::hasattr(obj, "shape"))
    return to_string(obj.attr("dtype")) + " array of shape " + to_string(obj.attr("shape"));
  return Py_TYPE(obj.ptr())->tp_name;
}

// Checks that `obj` is a float64 numpy array with `ndim` dimensions (the last of length `columns`
// unless columns is 0), C-contiguous, and writable when `writable`; throws naming `name` otherwise.
inline void check_array(nb::handle obj, const char* name, std::size_t ndim, std::size_t columns, bool writable) {
  const std::string n(name);
  if (!nb::hasattr(obj, "dtype") || !nb::hasattr(obj, "shape") || !nb::hasattr(obj, "flags"))
    throw nb::type_error((n + ": expected a numpy array of float64, got " + describe(obj)).c_str());
  const std::string dtype = to_string(obj.attr("dtype"));
  if (dtype != "float64")
    throw nb::type_error((n + ": expected float64 values, got a " + describe(obj) +
                          " (no conversion is made: numpy.asarray(x, dtype=numpy.float64))").c_str());
  const nb::tuple shape = nb::cast<nb::tuple>(obj.attr("shape"));
  const std::string expected = ndim == 1 ? "(n,)" : columns ? "(n, " + std::to_string(columns) + ")" : "2-D";
  if (shape.size() != ndim || (columns && nb::cast<std::size_t>(shape[ndim - 1]) != columns))
    throw nb::value_error((n + ": expected shape " + expected + ", got " + describe(obj)).c_str());
  nb::handle flags = obj.attr("flags");
  if (!nb::cast<bool>(flags.attr("c_contiguous")))
    throw nb::value_error((n + ": the array is not C-contiguous (a strided view); pass "
                           "numpy.ascontiguousarray(" + n + ")").c_str());
  if (writable && !nb::cast<bool>(flags.attr("writeable")))
    throw nb::value_error((n + ": the array is read-only; the output must be writable").c_str());
}

template <class Array>
Array view_as(nb::handle obj, const char* name, std::size_t ndim, std::size_t columns, bool writable) {
  check_array(obj, name, ndim, columns, writable);
  Array out;
  if (!nb::try_cast<Array>(obj, out, /*convert=*/false))
    throw nb::type_error((std::string(name) + ": cannot be viewed as a float64 array on the CPU (" +
                          describe(obj) + ")").c_str());
  return out;
}

inline ConstVector const_vector(nb::handle obj, const char* name) {
  return view_as<ConstVector>(obj, name, 1, 0, false);
}
inline Vector vector(nb::handle obj, const char* name) { return view_as<Vector>(obj, name, 1, 0, true); }
inline ConstMatrix const_matrix(nb::handle obj, const char* name, std::size_t columns) {
  return view_as<ConstMatrix>(obj, name, 2, columns, false);
}

// Index of the first non-finite value of data[0..n), or n.
inline std::size_t first_non_finite(const double* data, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(data[i])) return i;
  return n;
}

inline std::string format_double(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

}  // namespace pisco::python
