// HEALPix FITS maps in and out of a Sky (DESIGN 9, 12).
//
// The files follow the layout HEALPix C++ and healpy write and read: an empty primary HDU, then a
// binary table with one column per Stokes map and the keys NSIDE, ORDERING, POLCCONV, ... Pixel
// geometry (NESTED to RING) comes from HEALPix C++. The table itself goes through CFITSIO directly
// rather than HEALPix's fitshandle, because fitshandle prints CFITSIO's error stack to stderr and
// throws a bare "FITS error"; here every failure becomes one pisco::Error naming the file.
#include <fitsio.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <new>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <error_handling.h>
#include <healpix_base.h>

#include "pisco/error.hpp"
#include "pisco/sky.hpp"

namespace pisco {
namespace {

namespace fs = std::filesystem;

constexpr int max_nside = 8192;
constexpr const char* expected_layout =
    "expected a full-sky HEALPix map: a FITS binary table with 1 (I), 3 (I Q U) or 4 (I Q U V) "
    "columns and the keys NSIDE and ORDERING";

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw Error(file.string() + ": " + what);
}

// CFITSIO's own explanation of a status code; its message stack is cleared so that stale messages
// never leak into a later, unrelated error.
std::string cfitsio_text(int status) {
  char text[FLEN_STATUS] = {};
  fits_get_errstatus(status, text);
  fits_clear_errmsg();
  return text;
}

void check(int status, const fs::path& file, const std::string& doing) {
  if (status != 0) fail(file, doing + " failed (CFITSIO: " + cfitsio_text(status) + ")");
}

// Inside a catch block: rethrows the current exception as one pisco::Error naming the file
// (HEALPix C++ throws PlanckError, the filesystem library filesystem_error).
[[noreturn]] void rethrow_naming(const fs::path& file) {
  try {
    throw;
  } catch (const Error&) {
    throw;
  } catch (const PlanckError& e) {
    fail(file, std::string("HEALPix: ") + e.what());
  } catch (const fs::filesystem_error& e) {
    fail(file, e.code().message());
  } catch (const std::bad_alloc&) {
    fail(file, "out of memory for the maps");
  } catch (const std::exception& e) {
    fail(file, e.what());
  }
}

std::string trim_upper(std::string s) {
  const auto not_space = [](unsigned char c) { return !std::isspace(c); };
  s.erase(s.begin(), std::find_if(s.begin(), s.end(), not_space));
  s.erase(std::find_if(s.rbegin(), s.rend(), not_space).base(), s.end());
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

// An open FITS file, closed on every path out of the reader or writer.
class FitsFile {
 public:
  FitsFile(const FitsFile&) = delete;
  FitsFile& operator=(const FitsFile&) = delete;
  ~FitsFile() {
    int status = 0;
    if (ptr_) fits_close_file(ptr_, &status);
    if (status) fits_clear_errmsg();
  }

  // The *_diskfile variants take the name literally: no CFITSIO extended syntax, so names with
  // brackets or a leading '!' mean what they say.
  static FitsFile open(const fs::path& file) {
    FitsFile f(file);
    int status = 0;
    fits_open_diskfile(&f.ptr_, file.c_str(), READONLY, &status);
    if (status) {
      f.ptr_ = nullptr;
      fail(file, "cannot be read as a FITS file (CFITSIO: " + cfitsio_text(status) + "); " +
                     expected_layout);
    }
    return f;
  }
  // Creates `temporary`; errors name `target`, the file the caller asked for.
  static FitsFile create(const fs::path& temporary, const fs::path& target) {
    FitsFile f(target);
    int status = 0;
    fits_create_diskfile(&f.ptr_, temporary.c_str(), &status);
    if (status) {
      f.ptr_ = nullptr;
      fail(target, "cannot be created as " + temporary.filename().string() + " (CFITSIO: " +
                       cfitsio_text(status) + ")");
    }
    return f;
  }
  FitsFile(FitsFile&& o) noexcept : ptr_(o.ptr_), file_(std::move(o.file_)) { o.ptr_ = nullptr; }

  // Closing flushes the buffers, so a writer must close explicitly to see write errors.
  void close() {
    int status = 0;
    fits_close_file(ptr_, &status);
    ptr_ = nullptr;
    check(status, file_, "closing the file");
  }

  fitsfile* get() const { return ptr_; }
  const fs::path& path() const { return file_; }

 private:
  explicit FitsFile(fs::path file) : file_(std::move(file)) {}
  fitsfile* ptr_ = nullptr;
  fs::path file_;
};

// ---- reading ------------------------------------------------------------------------------------

// Moves to the first binary-table HDU; the primary HDU of a HEALPix file is empty.
void goto_first_binary_table(const FitsFile& f) {
  int status = 0, hdus = 0;
  fits_get_num_hdus(f.get(), &hdus, &status);
  check(status, f.path(), "counting the HDUs");
  for (int h = 2; h <= hdus; ++h) {
    int type = 0;
    fits_movabs_hdu(f.get(), h, &type, &status);
    check(status, f.path(), "moving to HDU " + std::to_string(h));
    if (type == BINARY_TBL) return;
  }
  fail(f.path(), std::string("has no binary-table extension; ") + expected_layout);
}

std::optional<std::string> string_key(const FitsFile& f, const char* key) {
  char value[FLEN_VALUE] = {};
  int status = 0;
  fits_read_key(f.get(), TSTRING, key, value, nullptr, &status);
  if (status == KEY_NO_EXIST) {
    fits_clear_errmsg();
    return std::nullopt;
  }
  check(status, f.path(), std::string("reading the key ") + key);
  return std::string(value);
}

int read_nside(const FitsFile& f) {
  long long nside = 0;
  int status = 0;
  fits_read_key(f.get(), TLONGLONG, "NSIDE", &nside, nullptr, &status);
  if (status == KEY_NO_EXIST) {
    fits_clear_errmsg();
    fail(f.path(), std::string("has no NSIDE key in its binary table; ") + expected_layout);
  }
  check(status, f.path(), "reading NSIDE (expected an integer)");
  if (nside < 1 || nside > max_nside || (nside & (nside - 1)) != 0)
    fail(f.path(), "NSIDE = " + std::to_string(nside) + " is not a power of two in [1, " +
                       std::to_string(max_nside) + "]");
  return static_cast<int>(nside);
}

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

std::string column_name(const FitsFile& f, int col) {
  char key[FLEN_KEYWORD], value[FLEN_VALUE] = {};
  int status = 0;
  fits_make_keyn("TTYPE", col, key, &status);
  fits_read_key(f.get(), TSTRING, key, value, nullptr, &status);
  if (status) {
    fits_clear_errmsg();
    return "column " + std::to_string(col);
  }
  return value;
}

// The Stokes columns: 1, 3 or 4 numeric columns that each hold exactly 12 NSIDE^2 values.
std::vector<Column> map_columns(const FitsFile& f, int nside) {
  int status = 0, ncols = 0;
  long long rows = 0;
  fits_get_num_cols(f.get(), &ncols, &status);
  fits_get_num_rowsll(f.get(), &rows, &status);
  check(status, f.path(), "reading the table size");
  if (ncols != 1 && ncols != 3 && ncols != 4) {
    std::string names;
    for (int c = 1; c <= ncols; ++c) names += (c > 1 ? ", " : "") + column_name(f, c);
    fail(f.path(), "has " + std::to_string(ncols) + " columns (" + names +
                       "); expected 1 (I), 3 (I Q U) or 4 (I Q U V)");
  }
  const long long npix = 12LL * nside * nside;
  std::vector<Column> columns;
  for (int c = 1; c <= ncols; ++c) {
    int type = 0;
    long long repeat = 0, width = 0;
    fits_get_coltypell(f.get(), c, &type, &repeat, &width, &status);
    check(status, f.path(), "reading the type of column " + std::to_string(c));
    if (type <= 0 || type == TSTRING || type == TLOGICAL || type == TBIT || type == TCOMPLEX ||
        type == TDBLCOMPLEX)
      fail(f.path(), "column " + std::to_string(c) + " (" + column_name(f, c) +
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

// Reads a whole column as float64 (CFITSIO converts other numeric types and applies TSCAL/TZERO).
// Vector-valued columns are read straight across row boundaries. Null checking is off, so a NaN in
// the file stays NaN and is reported later with its pixel.
void read_column(const FitsFile& f, const Column& c, std::span<double> out) {
  long rows_per_chunk = 0;
  int status = 0;
  fits_get_rowsize(f.get(), &rows_per_chunk, &status);
  const long long chunk = std::max<long long>(1, rows_per_chunk) * c.repeat;
  for (long long first = 0; first < static_cast<long long>(out.size()) && status == 0;
       first += chunk) {
    const long long n = std::min<long long>(chunk, static_cast<long long>(out.size()) - first);
    int anynul = 0;
    fits_read_col(f.get(), TDOUBLE, c.number, first / c.repeat + 1, first % c.repeat + 1, n,
                  nullptr, out.data() + first, &anynul, &status);
  }
  check(status, f.path(), "reading column " + std::to_string(c.number));
}

// NESTED to RING with HEALPix's index conversion. Healpix_Map::swap_scheme would do it in place,
// but it is an OpenMP loop in a header, and libpisco is not built with OpenMP.
void nested_to_ring(std::span<double> map, int nside) {
  const Healpix_Base base(nside, NEST, SET_NSIDE);
  const std::vector<double> nested(map.begin(), map.end());
  for (int p = 0; p < base.Npix(); ++p) map[base.nest2ring(p)] = nested[p];
}

Sky read_sky(const fs::path& file) {
  std::error_code ec;
  if (!fs::exists(file, ec)) fail(file, std::string("no such file; ") + expected_layout);
  if (fs::is_directory(file, ec)) fail(file, std::string("is a directory; ") + expected_layout);
  const FitsFile f = FitsFile::open(file);
  goto_first_binary_table(f);
  const int nside = read_nside(f);
  const bool nested = read_is_nested(f);
  reject_partial_sky(f);
  const bool iau = read_is_iau(f);
  const std::vector<Column> columns = map_columns(f, nside);

  Sky sky(nside, read_units(f));
  for (std::size_t k = 0; k < columns.size(); ++k) {
    const auto map = sky.stokes(static_cast<StokesIndex>(k));
    read_column(f, columns[k], map);
    if (nested) nested_to_ring(map, nside);
  }
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

// Full-sky tables use healpy's layout of 1024 values per row where NSIDE allows it: each column's
// values then lie in contiguous 8 KiB runs, which CFITSIO writes far faster than one value per row.
long long values_per_row(long long npix) { return npix % 1024 == 0 ? 1024 : 1; }

void write_sky_table(const FitsFile& f, const Sky& sky) {
  static constexpr const char* names[4] = {"I_STOKES", "Q_STOKES", "U_STOKES", "V_STOKES"};
  const long long npix = static_cast<long long>(sky.npix());
  const long long repeat = values_per_row(npix);
  const std::string form = std::to_string(repeat) + "D";
  char* ttype[4];
  char* tform[4];
  char* tunit[4];
  for (int k = 0; k < 4; ++k) {
    ttype[k] = const_cast<char*>(names[k]);
    tform[k] = const_cast<char*>(form.c_str());
    tunit[k] = const_cast<char*>(sky.units().c_str());
  }
  int status = 0;
  fits_create_img(f.get(), BYTE_IMG, 0, nullptr, &status);
  check(status, f.path(), "writing the primary HDU");
  fits_create_tbl(f.get(), BINARY_TBL, npix / repeat, 4, ttype, tform, tunit, "xtension", &status);
  check(status, f.path(), "creating the binary table");
  write_healpix_keys(f, sky.nside());

  // Row blocks across all four columns, in file order, so CFITSIO streams the table once.
  long rows_per_chunk = 0;
  fits_get_rowsize(f.get(), &rows_per_chunk, &status);
  const long long chunk = std::max<long long>(1, rows_per_chunk) * repeat;
  for (long long first = 0; first < npix && status == 0; first += chunk) {
    const long long n = std::min(chunk, npix - first);
    for (int k = 0; k < 4 && status == 0; ++k) {
      const auto map = sky.stokes(static_cast<StokesIndex>(k));
      fits_write_col(f.get(), TDOUBLE, k + 1, first / repeat + 1, first % repeat + 1, n,
                     const_cast<double*>(map.data() + first), &status);
    }
  }
  check(status, f.path(), "writing the maps");
}

// Written under a temporary name in the same directory and renamed over `file`, so readers never
// see a half-written map and a failure leaves nothing behind.
void write_atomically(const fs::path& file, const Sky& sky) {
  if (sky.units().size() > 68) fail(file, "units '" + sky.units() + "' exceed 68 characters");
  fs::path temporary = file;
  temporary += ".tmp-" + std::to_string(::getpid());
  std::error_code ec;
  fs::remove(temporary, ec);  // a leftover of a crashed process with the same pid
  try {
    FitsFile f = FitsFile::create(temporary, file);
    write_sky_table(f, sky);
    f.close();
    fs::rename(temporary, file);
  } catch (...) {
    fs::remove(temporary, ec);
    rethrow_naming(file);
  }
}

}  // namespace

Sky Sky::read_fits(const std::filesystem::path& file) {
  try {
    return read_sky(file);
  } catch (...) {
    rethrow_naming(file);
  }
}

void Sky::write_fits(const std::filesystem::path& file) const { write_atomically(file, *this); }

}  // namespace pisco
