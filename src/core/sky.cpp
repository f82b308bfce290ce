// The in-memory sky: four full-sky HEALPix maps in RING ordering (docs/physics.md, "The sky").
#include "pisco/sky.hpp"

#include <cmath>
#include <numbers>

#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco {
namespace {

constexpr const char* stokes_names[4] = {"I", "Q", "U", "V"};

}  // namespace

// Declared in healpix_map.hpp: the one NSIDE check of the library.
void check_nside(long long nside, const std::string& where) {
  if (!valid_nside(nside))
    throw Error(where + ": NSIDE = " + std::to_string(nside) + " is not a power of two in [1, " +
                std::to_string(max_nside) + "]");
}

Sky::Sky(int nside, std::string units) : nside_(nside), units_(std::move(units)) {
  check_nside(nside, "sky");
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
