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

Sky::Sky(const SkyView& view) : nside_(view.nside()), units_(view.units()) {
  for (int s = 0; s < 4; ++s) {
    const auto map = view.stokes(static_cast<StokesIndex>(s));
    maps_[s].assign(map.begin(), map.end());
  }
}

double Sky::pixel_area() const noexcept {
  return 4.0 * std::numbers::pi / static_cast<double>(npix());
}

void Sky::check_finite(const std::string& origin) const { SkyView(*this).check_finite(origin); }

std::vector<std::size_t> Sky::unseen_pixels() const { return SkyView(*this).unseen_pixels(); }

void Sky::check_unseen(const std::string& origin) const { SkyView(*this).check_unseen(origin); }

SkyView::SkyView(int nside, std::span<const double> I, std::span<const double> Q, std::span<const double> U,
                 std::span<const double> V, std::string units)
    : nside_(nside), units_(std::move(units)) {
  check_nside(nside, "sky view");
  const std::size_t npix = 12 * static_cast<std::size_t>(nside) * static_cast<std::size_t>(nside);
  if (V.empty()) {
    zeros_ = std::make_shared<const std::vector<double>>(npix, 0.0);
    V = *zeros_;
  }
  maps_ = {I, Q, U, V};
  for (int s = 0; s < 4; ++s)
    if (maps_[s].size() != npix)
      throw Error("sky view: the Stokes " + std::string(stokes_names[s]) + " map has " +
                  std::to_string(maps_[s].size()) + " values; NSIDE " + std::to_string(nside) + " has " +
                  std::to_string(npix) + " pixels");
}

SkyView::SkyView(const Sky& sky)
    : nside_(sky.nside()), maps_{sky.I(), sky.Q(), sky.U(), sky.V()}, units_(sky.units()) {}

double SkyView::pixel_area() const noexcept {
  return 4.0 * std::numbers::pi / static_cast<double>(npix());
}

void SkyView::check_finite(const std::string& origin) const {
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

std::vector<std::size_t> SkyView::unseen_pixels() const {
  std::vector<std::size_t> out;
  for (std::size_t p = 0; p < npix(); ++p)
    if (is_unseen(maps_[0][p]) || is_unseen(maps_[1][p]) || is_unseen(maps_[2][p]) || is_unseen(maps_[3][p]))
      out.push_back(p);
  return out;
}

std::size_t Sky::zero_unseen() {
  std::size_t changed = 0;
  for (std::size_t p = 0; p < npix(); ++p) {
    bool any = false;
    for (auto& map : maps_)
      if (is_unseen(map[p])) {
        map[p] = 0.0;
        any = true;
      }
    changed += any;
  }
  return changed;
}

void SkyView::check_unseen(const std::string& origin) const {
  for (int s = 0; s < 4; ++s) {
    const auto& map = maps_[s];
    std::size_t count = 0, first = 0;
    for (std::size_t p = 0; p < map.size(); ++p)
      if (is_unseen(map[p]) && count++ == 0) first = p;
    if (count == 0) continue;
    throw Error(origin + ": the Stokes " + stokes_names[s] + " map has " + std::to_string(count) +
                " UNSEEN pixel" + (count == 1 ? "" : "s") + " (-1.6375e30, HEALPix's marker of a pixel without data), " +
                "the first at pixel " + std::to_string(first) +
                " (RING); expected a value at every pixel, or a policy for masked skies (zero or flag)");
  }
}

}  // namespace pisco
