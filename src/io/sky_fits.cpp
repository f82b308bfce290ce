// HEALPix FITS maps in and out of a Sky (docs/formats.md, "Sky maps and output maps (HEALPix FITS)").
//
// The files follow the layout HEALPix C++ and healpy write and read: an empty primary HDU, then a
// binary table with one column per Stokes map and the keys NSIDE, ORDERING, POLCCONV, ... Pixel
// geometry (NESTED to RING) comes from HEALPix C++. The table itself goes through CFITSIO directly
// (io/fits_table.hpp), so that every failure becomes one pisco::Error naming the file.
#include <fitsio.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <healpix_base.h>

#include "io/fits_table.hpp"
#include "core/text.hpp"
#include "pisco/sky.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco {
namespace {

namespace fs = std::filesystem;

using namespace detail;  // io/fits_table.hpp

constexpr const char* expected_layout =
    "expected a full-sky HEALPix map: a FITS binary table with 1 (I), 3 (I Q U) or 4 (I Q U V) "
    "columns and the keys NSIDE and ORDERING";

// ---- reading ------------------------------------------------------------------------------------

bool read_is_nested(const FitsFile& f) {
  const auto ordering = string_key(f, "ORDERING");
  if (!ordering) fail(f.path(), "has no ORDERING key; expected ORDERING = 'RING' or 'NESTED'");
  const std::string o = trim_upper(*ordering);
  if (o == "RING") return false;
  if (o == "NESTED" || o == "NEST") return true;
  fail(f.path(), "ORDERING = '" + *ordering + "'; expected 'RING' or 'NESTED'");
}

// Cut-sky files list pixel indices explicitly; only implicit full-sky tables are supported.
void reject_partial_sky(const FitsFile& f) {
  const auto scheme = string_key(f, "INDXSCHM");
  const auto object = string_key(f, "OBJECT");
  if ((scheme && trim_upper(*scheme) == "EXPLICIT") || (object && trim_upper(*object) == "PARTIAL"))
    fail(f.path(), std::string("is a cut-sky (partial) map; ") + expected_layout);
}

bool read_is_iau(const FitsFile& f) {
  const auto conv = string_key(f, "POLCCONV");
  if (!conv) return false;  // absent: HEALPix's default, COSMO
  const std::string c = trim_upper(*conv);
  if (c == "COSMO") return false;
  if (c == "IAU") return true;
  fail(f.path(), "POLCCONV = '" + *conv + "'; expected 'COSMO' or 'IAU'");
}

std::string read_units(const FitsFile& f) {
  const auto unit = string_key(f, "TUNIT1");
  if (!unit) return "K_CMB";
  std::string u = *unit;
  u.erase(u.find_last_not_of(' ') + 1);
  return u.empty() ? "K_CMB" : u;
}

struct Column {
  int number;           // 1-based FITS column number
  long long repeat;     // values per row (1024 for healpy's vector columns)
  long long elements;   // repeat * rows
};

// The column's name, or "column N" where it has none.
std::string name_or_number(const FitsFile& f, int col) {
  return detail::column_name(f, col, "column " + std::to_string(col));
}

// The Stokes columns: 1, 3 or 4 numeric columns that each hold exactly 12 NSIDE^2 values.
std::vector<Column> map_columns(const FitsFile& f, int nside) {
  const auto [ncols, rows] = detail::table_size(f);
  if (ncols != 1 && ncols != 3 && ncols != 4) {
    std::string names;
    for (int c = 1; c <= ncols; ++c) names += (c > 1 ? ", " : "") + name_or_number(f, c);
    fail(f.path(), "has " + std::to_string(ncols) + " columns (" + names +
                       "); expected 1 (I), 3 (I Q U) or 4 (I Q U V)");
  }
  const long long npix = 12LL * nside * nside;
  std::vector<Column> columns;
  for (int c = 1; c <= ncols; ++c) {
    const auto [type, repeat] = detail::column_type(f, c, std::to_string(c));
    if (!detail::is_fixed_numeric(type))
      fail(f.path(), "column " + std::to_string(c) + " (" + name_or_number(f, c) +
                         ") is not a numeric column of fixed width");
    columns.push_back({c, repeat, repeat * rows});
  }
  for (const Column& c : columns)
    if (c.elements != columns[0].elements)
      fail(f.path(), "columns have different lengths: column 1 holds " +
                         std::to_string(columns[0].elements) + " values, column " +
                         std::to_string(c.number) + " holds " + std::to_string(c.elements));
  if (columns[0].elements != npix)
    fail(f.path(), "the columns hold " + std::to_string(columns[0].elements) +
                       " values; NSIDE = " + std::to_string(nside) + " needs 12 NSIDE^2 = " +
                       std::to_string(npix));
  return columns;
}

// NESTED to RING with HEALPix's index conversion. Healpix_Map::swap_scheme would do it in place,
// but it is an OpenMP loop in a header, and libpisco is not built with OpenMP.
void nested_to_ring(std::span<double> map, int nside) {
  const Healpix_Base base(nside, NEST, SET_NSIDE);
  const std::vector<double> nested(map.begin(), map.end());
  for (int p = 0; p < base.Npix(); ++p) map[base.nest2ring(p)] = nested[p];
}

// The error of a map column with UNSEEN pixels (UnseenPolicy::error).
void reject_unseen(const FitsFile& f, const Column& c, std::span<const double> map) {
  std::size_t count = 0, first = 0;
  for (std::size_t p = 0; p < map.size(); ++p)
    if (is_unseen(map[p]) && count++ == 0) first = p;
  if (count == 0) return;
  fail(f.path(), "column " + std::to_string(c.number) + " (" + name_or_number(f, c.number) + ") has " +
                     std::to_string(count) + " UNSEEN pixel" + (count == 1 ? "" : "s") +
                     " (-1.6375e30, HEALPix's marker of a pixel without data), the first at pixel " +
                     std::to_string(first) + " (RING); expected a value at every pixel, or a policy for " +
                     "masked skies (zero: taken as 0; flag: taken as 0 and the samples whose disc holds one flagged)");
}

Sky read_sky(const fs::path& file, UnseenPolicy unseen) {
  std::error_code ec;
  if (!fs::exists(file, ec)) fail(file, std::string("no such file; ") + expected_layout);
  if (fs::is_directory(file, ec)) fail(file, std::string("is a directory; ") + expected_layout);
  const FitsFile f = FitsFile::open(file, expected_layout);
  detail::goto_first_binary_table(f, expected_layout);
  detail::require_complete_hdu(f);
  const int nside =
      detail::read_nside(f, std::string("has no NSIDE key in its binary table; ") + expected_layout);
  const bool nested = read_is_nested(f);
  reject_partial_sky(f);
  const bool iau = read_is_iau(f);
  const std::vector<Column> columns = map_columns(f, nside);

  Sky sky(nside, read_units(f));
  for (std::size_t k = 0; k < columns.size(); ++k) {
    const auto map = sky.stokes(static_cast<StokesIndex>(k));
    // Null checking is off, so a NaN in the file stays NaN and is reported later with its pixel.
    detail::read_column(f, columns[k].number, columns[k].repeat, map,
                        std::to_string(columns[k].number));
    if (nested) nested_to_ring(map, nside);
    if (unseen == UnseenPolicy::error) reject_unseen(f, columns[k], map);
  }
  if (unseen == UnseenPolicy::zero) sky.zero_unseen();
  if (iau && columns.size() >= 3) {
    for (double& u : sky.U()) u = -u;
    std::clog << "pisco: " << file.string()
              << ": POLCCONV = 'IAU', U negated to the COSMO convention\n";
  }
  sky.check_finite(file.string());
  return sky;
}

// ---- writing ------------------------------------------------------------------------------------

void write_string_key(const FitsFile& f, const char* key, const std::string& value,
                      const char* comment) {
  int status = 0;
  fits_update_key(f.get(), TSTRING, key, const_cast<char*>(value.c_str()), comment, &status);
  check(status, f.path(), std::string("writing the key ") + key);
}

void write_long_key(const FitsFile& f, const char* key, long long value, const char* comment) {
  int status = 0;
  fits_update_key(f.get(), TLONGLONG, key, &value, comment, &status);
  check(status, f.path(), std::string("writing the key ") + key);
}

void write_healpix_keys(const FitsFile& f, int nside) {
  const long long npix = 12LL * nside * nside;
  int status = 0;
  write_string_key(f, "PIXTYPE", "HEALPIX", "HEALPIX pixelisation");
  write_string_key(f, "ORDERING", "RING", "Pixel ordering scheme, either RING or NESTED");
  write_long_key(f, "NSIDE", nside, "Resolution parameter of HEALPIX");
  write_long_key(f, "FIRSTPIX", 0, "First pixel # (0 based)");
  write_long_key(f, "LASTPIX", npix - 1, "Last pixel # (0 based)");
  write_string_key(f, "INDXSCHM", "IMPLICIT", "Indexing: IMPLICIT or EXPLICIT");
  write_string_key(f, "OBJECT", "FULLSKY", "Sky coverage, either FULLSKY or PARTIAL");
  int polar = 1;
  fits_update_key(f.get(), TLOGICAL, "POLAR", &polar, "Polarisation included (True/False)",
                  &status);
  check(status, f.path(), "writing the key POLAR");
  write_string_key(f, "POLCCONV", "COSMO", "Coord. convention for polarisation (COSMO/IAU)");
}

void write_map_table(const FitsFile& f, int nside, const std::vector<MapColumn>& columns,
                     const std::string& units) {
  const long long npix = 12LL * nside * nside;
  const long long repeat = detail::values_per_row(npix);
  const std::string form = std::to_string(repeat) + "D";
  const int n = static_cast<int>(columns.size());
  std::vector<char*> ttype(n), tform(n), tunit(n);
  for (int k = 0; k < n; ++k) {
    ttype[k] = const_cast<char*>(columns[k].name.c_str());
    tform[k] = const_cast<char*>(form.c_str());
    tunit[k] = const_cast<char*>(units.c_str());
  }
  int status = 0;
  fits_create_img(f.get(), BYTE_IMG, 0, nullptr, &status);
  check(status, f.path(), "writing the primary HDU");
  fits_create_tbl(f.get(), BINARY_TBL, npix / repeat, n, ttype.data(), tform.data(), tunit.data(), "xtension",
                  &status);
  check(status, f.path(), "creating the binary table");
  write_healpix_keys(f, nside);
  detail::write_columns(f, n, npix, repeat,
                        [&columns](int k, long long first, long long) { return columns[k].values.data() + first; });
}

}  // namespace

// Written under a temporary name in the same directory and renamed over `file`, so readers never
// see a half-written map and a failure leaves nothing behind.
void write_healpix_map(const std::filesystem::path& file, int nside, const std::vector<MapColumn>& columns,
                       const std::string& units) {
  check_nside(nside, file.string());
  if (units.size() > 68) fail(file, "units '" + units + "' exceed 68 characters");
  if (columns.empty()) fail(file, "no map columns to write");
  for (const auto& c : columns)
    if (c.values.size() != static_cast<std::size_t>(12LL * nside * nside))
      fail(file, "column " + c.name + " has " + std::to_string(c.values.size()) + " values; expected 12 NSIDE^2 = " +
                     std::to_string(12LL * nside * nside));
  // Every value finite (UNSEEN, -1.6375e30, is), checked before anything is written.
  for (const auto& c : columns)
    for (std::size_t p = 0; p < c.values.size(); ++p)
      if (!std::isfinite(c.values[p]))
        fail(file, "column " + c.name + ": pixel " + std::to_string(p) + " is " + detail::number_text(c.values[p]) +
                       "; a map holds finite values (UNSEEN, " + detail::number_text(unseen) +
                       ", marks a pixel without data)");
  detail::write_atomically(file, [&](const fs::path& temporary) {
    FitsFile f = FitsFile::create(temporary, file);
    write_map_table(f, nside, columns, units);
    f.close();
  });
}

Sky Sky::read_fits(const std::filesystem::path& file, UnseenPolicy unseen) {
  try {
    return read_sky(file, unseen);
  } catch (...) {
    rethrow_naming(file);
  }
}

void Sky::write_fits(const std::filesystem::path& file) const {
  write_healpix_map(file, nside_,
                    {{"I_STOKES", I()}, {"Q_STOKES", Q()}, {"U_STOKES", U()}, {"V_STOKES", V()}}, units_);
}

}  // namespace pisco
