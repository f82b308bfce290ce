// Formatting shared by the error messages of the core sources.
#pragma once

#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "pisco/units.hpp"

namespace pisco::detail {

// An angle given in radians, as "1.5 deg" (six significant digits).
inline std::string degrees_text(double radians) {
  std::ostringstream s;
  s << radians / deg << " deg";
  return s.str();
}

// A number in six significant digits ("1e+200", "0.0153"), or as many as asked for.
inline std::string number_text(double value, int digits = 6) {
  std::ostringstream s;
  s.precision(digits);
  s << value;
  return s.str();
}

// A count in three significant digits ("1e+08", "2.56e+03", "512").
inline std::string count_text(double value) { return number_text(value, 3); }

// A size in bytes for a person: "3.2 GB", "512 kB", "96 bytes" (decimal units, two or three digits).
inline std::string bytes_text(double bytes) {
  const char* units[] = {"bytes", "kB", "MB", "GB", "TB", "PB"};
  int u = 0;
  while (bytes >= 1000.0 && u < 5) bytes /= 1000.0, ++u;
  return number_text(bytes, u == 0 ? 6 : 3) + " " + units[u];
}

// Items as a series: "a", "a and b", "a, b and c" (with `conjunction` "and"; "or" likewise).
inline std::string series_text(const std::vector<std::string>& items, const char* conjunction) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i)
    out += (i == 0 ? "" : i + 1 == items.size() ? std::string(" ") + conjunction + " " : std::string(", ")) + items[i];
  return out;
}

// printf into a string.
template <typename... Args>
std::string printf_text(const char* fmt, Args... args) {
  const int n = std::snprintf(nullptr, 0, fmt, args...);
  if (n <= 0) return {};
  std::string s(static_cast<std::size_t>(n) + 1, '\0');
  std::snprintf(s.data(), s.size(), fmt, args...);
  s.resize(static_cast<std::size_t>(n));
  return s;
}

}  // namespace pisco::detail
