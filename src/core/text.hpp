// Formatting shared by the error messages of the core sources.
#pragma once

#include <sstream>
#include <string>

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

}  // namespace pisco::detail
