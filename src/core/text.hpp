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

}  // namespace pisco::detail
