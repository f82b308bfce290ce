// Units. The library takes every angle in radians: write 1.5 * pisco::deg for 1.5 degrees.
#pragma once

#include <numbers>

namespace pisco {

inline constexpr double deg = std::numbers::pi / 180;  // one degree in radians

}  // namespace pisco
