// CFITSIO plumbing shared by the HEALPix FITS readers and writers (sky maps, beamsor files).
//
// The tables go through CFITSIO directly rather than HEALPix's fitshandle, because fitshandle
// prints CFITSIO's error stack to stderr and throws a bare "FITS error"; here every failure becomes
// one pisco::Error naming the file the caller asked for.
#pragma once

#include <fitsio.h>

#include <filesystem>
#include <functional>
#include <optional>
#include <span>

#include <string>

#include "pisco/error.hpp"

namespace pisco::detail {

// Throws pisco::Error("<file>: <what>").
[[noreturn]] void fail(const std::filesystem::path& file, const std::string& what, ErrorKind kind = ErrorKind::input);

// CFITSIO's own explanation of a status code; its message stack is cleared so that stale messages
// never leak into a later, unrelated error.
std::string cfitsio_text(int status);

// Fails with "<doing> failed (CFITSIO: ...)" unless status is 0.
void check(int status, const std::filesystem::path& file, const std::string& doing);

// Inside a catch block: rethrows the current exception as one pisco::Error naming the file
// (HEALPix C++ throws PlanckError, the filesystem library filesystem_error).
[[noreturn]] void rethrow_naming(const std::filesystem::path& file);

// Leading and trailing white space removed, upper case: the form header values are compared in.
std::string trim_upper(std::string s);

// An open FITS file, closed on every path out of the reader or writer. Errors name path(), the
// file the caller asked for.
class FitsFile {
 public:
  FitsFile(const FitsFile&) = delete;
  FitsFile& operator=(const FitsFile&) = delete;
  FitsFile(FitsFile&& o) noexcept;
  ~FitsFile();

  // The *_diskfile variants take the name literally: no CFITSIO extended syntax, so names with
  // brackets or a leading '!' mean what they say. `expected` ends the error of a file CFITSIO
  // cannot open ("expected ...").
  static FitsFile open(const std::filesystem::path& file, const std::string& expected);
  // Creates `temporary`; errors name `target`.
  static FitsFile create(const std::filesystem::path& temporary,
                         const std::filesystem::path& target);

  // Closing flushes CFITSIO's buffers, so a writer must close explicitly to see write errors.
  void close();

  fitsfile* get() const { return ptr_; }
  const std::filesystem::path& path() const { return file_; }

 private:
  explicit FitsFile(std::filesystem::path file);
  fitsfile* ptr_ = nullptr;
  std::filesystem::path file_;
};

// ---- reading ------------------------------------------------------------------------------------

// Moves to the first binary-table HDU (the primary HDU of a HEALPix file is empty); fails with
// "has no binary-table extension; <expected>" when there is none.
void goto_first_binary_table(const FitsFile& f, const std::string& expected);

// Fails ("is truncated: ...") when the file ends before the data of the current HDU does: a reader
// that takes only part of a table (a beamsor's cap) would not notice on its own.
void require_complete_hdu(const FitsFile& f);

// A string key of the current HDU; nullopt when it is absent.
std::optional<std::string> string_key(const FitsFile& f, const char* key);

// The NSIDE key, checked with pisco::check_nside (healpix_map.hpp); fails with `if_missing` when the
// key is absent.
int read_nside(const FitsFile& f, const std::string& if_missing);

// The name (TTYPEn) of column `col`. When it cannot be read, CFITSIO's message stack is cleared and
// `if_unreadable` is returned or, without one, what CFITSIO left of the value (empty if absent).
std::string column_name(const FitsFile& f, int col,
                        const std::optional<std::string>& if_unreadable = std::nullopt);

struct TableSize {
  int columns = 0;
  long long rows = 0;
};
TableSize table_size(const FitsFile& f);

struct ColumnType {
  int type = 0;          // CFITSIO's type code
  long long repeat = 0;  // values per row (1024 for healpy's vector columns)
};
// Errors name the column "column <label>".
ColumnType column_type(const FitsFile& f, int col, const std::string& label);

// A numeric column of fixed width, which CFITSIO can convert to float64.
bool is_fixed_numeric(int type);

// Reads the first out.size() values of column `col` (`repeat` values per row) as float64: CFITSIO
// converts other numeric types, applies TSCAL/TZERO and reads vector columns straight across row
// boundaries. Null checking is off, so a NaN in the file stays NaN. Errors name "column <label>".
void read_column(const FitsFile& f, int col, long long repeat, std::span<double> out,
                 const std::string& label);

// ---- writing ------------------------------------------------------------------------------------

// Full-sky tables use healpy's layout of 1024 values per row where NSIDE allows it: each column's
// values then lie in contiguous 8 KiB runs, which CFITSIO writes far faster than one value per row.
long long values_per_row(long long npix);

// The n values of column k (0-based) from value `first`.
using ColumnValues = std::function<const double*(int k, long long first, long long n)>;

// Writes `columns` float64 columns of `total` values each, `repeat` values per row, as row blocks
// across all columns in file order, so CFITSIO streams the table once.
void write_columns(const FitsFile& f, int columns, long long total, long long repeat,
                   const ColumnValues& values);

// Calls write(temporary) with a temporary name in the same directory as `file`, then renames it
// over `file`, so readers never see a half-written file and a failure leaves nothing behind. Every
// error is rethrown naming `file`.
void write_atomically(const std::filesystem::path& file,
                      const std::function<void(const std::filesystem::path& temporary)>& write);

}  // namespace pisco::detail
