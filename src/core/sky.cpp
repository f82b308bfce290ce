// The in-memory sky: four full-sky HEALPix maps in RING ordering (DESIGN 1).
#include "pisco/sky.hpp"

#include <cmath>
#include <numbers>

#include "pisco/error.hpp"

namespace pisco {
namespace {

// Healpix_Base (32-bit pixel indices) and the engine's pixel tables stop at NSIDE 8192.
constexpr int max_nside = 8192;

bool is_power_of_two(int n) { return n > 0 && (n & (n - 1)) == 0; }

constexpr const char* stokes_names[4] = {"I", "Q", "U", "V"};

}  // namespace

Sky::Sky(int nside, std::string units) : nside_(nside), units_(std::move(units)) {
  if (!is_power_of_two(nside) || nside > max_nside)
    throw Error("sky: NSIDE = " + std::to_string(nside) +
                " is not a power of two in [1, " + std::to_string(max_nside) + "]");
  const std::size_t npix = 12 * static_cast<std::size_t>(nside) * static_cast<std::size_t>(nside);
  for (auto& map : maps_) map.assign(npix, 0.0);
}

double Sky::pixel_area() const noexcept {
  return 4.0 * std::numbers::pi / static_cast<double>(npix());
}

void Sky::check_finite(const std::string& origin) const {
  for (int s = 0; s < 4; ++s) {
    const auto& map = maps_[s];
    for (std::size_t p = 0; p < map.size(); ++p) {
      if (std::isfinite(map[p])) continue;
      throw Error(origin + ": Stokes " + stokes_names[s] + " map has the non-finite value " +
                  (std::isnan(map[p]) ? std::string("NaN") : std::string(map[p] > 0 ? "+inf" : "-inf")) +
                  " at pixel " + std::to_string(p) + " (RING); every pixel must be a finite number");
    }
  }
}

}  // namespace pisco
