// A polarized sky: HEALPix I, Q, U, V maps in RING ordering, COSMO polarization convention.
#pragma once

#include <array>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace pisco {

enum class StokesIndex : int { I = 0, Q = 1, U = 2, V = 3 };

// What the library does with the UNSEEN pixels (pisco::unseen, healpix_map.hpp: HEALPix's marker of a
// pixel without data, as every masked map has them) of a sky it is given.
enum class UnseenPolicy {
  error,  // an error naming the map, the number of UNSEEN pixels and the first one (the default)
  zero,   // taken as 0
  flag,   // taken as 0, and the samples whose disc holds one are flagged (Engine::flag_samples)
};

class SkyView;

class Sky {
 public:
  // A sky of zeros. Throws pisco::Error unless nside is a power of two in [1, 8192].
  explicit Sky(int nside, std::string units = "K_CMB");
  // A copy of a view's maps.
  explicit Sky(const SkyView& view);

  int nside() const noexcept { return nside_; }
  std::size_t npix() const noexcept { return maps_[0].size(); }
  double pixel_area() const noexcept;  // 4 pi / npix, steradians

  std::span<double> I() noexcept { return maps_[0]; }
  std::span<double> Q() noexcept { return maps_[1]; }
  std::span<double> U() noexcept { return maps_[2]; }
  std::span<double> V() noexcept { return maps_[3]; }
  std::span<const double> I() const noexcept { return maps_[0]; }
  std::span<const double> Q() const noexcept { return maps_[1]; }
  std::span<const double> U() const noexcept { return maps_[2]; }
  std::span<const double> V() const noexcept { return maps_[3]; }
  std::span<double> stokes(StokesIndex s) noexcept { return maps_[static_cast<int>(s)]; }
  std::span<const double> stokes(StokesIndex s) const noexcept { return maps_[static_cast<int>(s)]; }

  const std::string& units() const noexcept { return units_; }
  void set_units(std::string units) { units_ = std::move(units); }

  // Throws pisco::Error naming `origin`, the Stokes map and the first pixel that is NaN or infinite.
  void check_finite(const std::string& origin) const;

  // UNSEEN pixels (pisco::is_unseen): the RING indices of the pixels UNSEEN in any Stokes map,
  // ascending; zero_unseen() sets those values to 0 and returns how many pixels it changed;
  // check_unseen() throws pisco::Error "<origin>: the Stokes Q map has 12 UNSEEN pixels (...), the
  // first at pixel 345 (RING); expected ..." for the first map that has any.
  std::vector<std::size_t> unseen_pixels() const;
  std::size_t zero_unseen();
  void check_unseen(const std::string& origin) const;

  // Reads a HEALPix FITS map (1, 3 or 4 columns: I, or I Q U, or I Q U V; the first binary table).
  // NESTED maps are converted to RING; POLCCONV = 'IAU' maps have U negated (to COSMO).
  // Throws pisco::Error naming the file on any problem (missing, not HEALPix, bad NSIDE, NaN). UNSEEN
  // pixels (a masked map): with UnseenPolicy::error an error naming the file, the column, their
  // number and the first; with zero they are set to 0; with flag they are kept as UNSEEN, for an
  // Engine made with EngineOptions::unseen = UnseenPolicy::flag.
  static Sky read_fits(const std::filesystem::path& file, UnseenPolicy unseen = UnseenPolicy::error);

  // Writes I, Q, U, V (TTYPE I_STOKES ... V_STOKES), RING, POLCCONV = 'COSMO', TUNIT = units.
  // The file is written to a temporary name and renamed, so it is never left half-written.
  void write_fits(const std::filesystem::path& file) const;

 private:
  int nside_;
  std::array<std::vector<double>, 4> maps_;
  std::string units_;
};

// A sky whose maps the caller holds (a framework's own arrays): I, Q, U and V as spans, without a
// copy. Accepted wherever the library takes a sky to read (Engine, the simulation's parts); a Sky
// converts to one. The arrays must stay valid and unchanged while the call that takes the view runs;
// an Engine copies what it needs while it is made, so they may change or go afterwards.
class SkyView {
 public:
  // I, Q, U (and V; empty: zero) of 12 nside^2 values each, RING ordering, COSMO convention. Throws
  // pisco::Error unless nside is a power of two in [1, 8192] and every map has 12 nside^2 values.
  SkyView(int nside, std::span<const double> I, std::span<const double> Q, std::span<const double> U,
          std::span<const double> V = {}, std::string units = "K_CMB");
  SkyView(const Sky& sky);  // NOLINT(google-explicit-constructor): a Sky is read through its view

  int nside() const noexcept { return nside_; }
  std::size_t npix() const noexcept { return maps_[0].size(); }
  double pixel_area() const noexcept;  // 4 pi / npix, steradians
  std::span<const double> I() const noexcept { return maps_[0]; }
  std::span<const double> Q() const noexcept { return maps_[1]; }
  std::span<const double> U() const noexcept { return maps_[2]; }
  std::span<const double> V() const noexcept { return maps_[3]; }
  std::span<const double> stokes(StokesIndex s) const noexcept { return maps_[static_cast<int>(s)]; }
  const std::string& units() const noexcept { return units_; }
  // As Sky's (the same checks and messages).
  void check_finite(const std::string& origin) const;
  std::vector<std::size_t> unseen_pixels() const;
  void check_unseen(const std::string& origin) const;

 private:
  int nside_;
  std::array<std::span<const double>, 4> maps_;
  std::shared_ptr<const std::vector<double>> zeros_;  // V when none is given
  std::string units_;
};

}  // namespace pisco
