#include "io/input_file.hpp"
#include "io/fits_table.hpp"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <new>
#include <utility>

#include <error_handling.h>

#include "io/output_file.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco::detail {

namespace fs = std::filesystem;

void fail(const fs::path& file, const std::string& what, ErrorKind kind) {
  throw Error(file.string() + ": " + what, kind);
}

std::string cfitsio_text(int status) {
  char text[FLEN_STATUS] = {};
  fits_get_errstatus(status, text);
  fits_clear_errmsg();
  return text;
}

void check(int status, const fs::path& file, const std::string& doing) {
  if (status == 0) return;
  // CFITSIO's text for a failed write or close does not say why: the system's reason does (a full disk).
  const int error = errno;
  std::string why = cfitsio_text(status);
  if ((status == WRITE_ERROR || status == FILE_NOT_CLOSED) && error != 0) why += ": " + std::string(std::strerror(error));
  fail(file, doing + " failed (CFITSIO: " + why + ")", ErrorKind::io);
}

void rethrow_naming(const fs::path& file) {
  try {
    throw;
  } catch (const Error&) {
    throw;
  } catch (const PlanckError& e) {
    fail(file, std::string("HEALPix: ") + e.what());
  } catch (const fs::filesystem_error& e) {
    fail(file, e.code().message(), ErrorKind::io);
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

// ---- FitsFile -----------------------------------------------------------------------------------

FitsFile::FitsFile(fs::path file) : file_(std::move(file)) {}

FitsFile::FitsFile(FitsFile&& o) noexcept : ptr_(o.ptr_), file_(std::move(o.file_)) {
  o.ptr_ = nullptr;
}

FitsFile::~FitsFile() {
  int status = 0;
  if (ptr_) fits_close_file(ptr_, &status);
  if (status) fits_clear_errmsg();
}

FitsFile FitsFile::open(const fs::path& file, const std::string& expected) {
  require_regular_file(file, expected.rfind("expected ", 0) == 0 ? expected.substr(9) : expected);
  FitsFile f(file);
  int status = 0;
  fits_open_diskfile(&f.ptr_, file.c_str(), READONLY, &status);
  if (status) {
    f.ptr_ = nullptr;
    fail(file, "cannot be read as a FITS file (CFITSIO: " + cfitsio_text(status) + "); " + expected);
  }
  return f;
}

FitsFile FitsFile::create(const fs::path& temporary, const fs::path& target) {
  FitsFile f(target);
  int status = 0;
  fits_create_diskfile(&f.ptr_, temporary.c_str(), &status);
  if (status) {
    f.ptr_ = nullptr;
    fail(target, "cannot be created as " + temporary.filename().string() + " (CFITSIO: " +
                     cfitsio_text(status) + ")", ErrorKind::io);
  }
  if (write_fault_requested(target)) {
    const int fd = descriptor_of(temporary);
    if (fd < 0) fail(target, "PISCO_TEST_FAULT: the temporary file's descriptor was not found", ErrorKind::io);
    make_disk_full(fd, target);
  }
  return f;
}

void FitsFile::close() {
  int status = 0;
  fits_close_file(ptr_, &status);
  ptr_ = nullptr;
  check(status, file_, "closing the file");
}

// ---- reading ------------------------------------------------------------------------------------

void goto_first_binary_table(const FitsFile& f, const std::string& expected) {
  int status = 0, hdus = 0;
  fits_get_num_hdus(f.get(), &hdus, &status);
  check(status, f.path(), "counting the HDUs");
  for (int h = 2; h <= hdus; ++h) {
    int type = 0;
    fits_movabs_hdu(f.get(), h, &type, &status);
    check(status, f.path(), "moving to HDU " + std::to_string(h));
    if (type == BINARY_TBL) return;
  }
  fail(f.path(), "has no binary-table extension; " + expected);
}

void require_complete_hdu(const FitsFile& f) {
  long long head = 0, data = 0, end = 0;
  int status = 0;
  fits_get_hduaddrll(f.get(), &head, &data, &end, &status);
  check(status, f.path(), "reading the table's extent");
  std::error_code ec;
  const auto size = fs::file_size(f.path(), ec);
  if (!ec && static_cast<long long>(size) < end)
    fail(f.path(), "is truncated: " + std::to_string(size) + " bytes, but its table ends at byte " + std::to_string(end));
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

int read_nside(const FitsFile& f, const std::string& if_missing) {
  long long nside = 0;
  int status = 0;
  fits_read_key(f.get(), TLONGLONG, "NSIDE", &nside, nullptr, &status);
  if (status == KEY_NO_EXIST) {
    fits_clear_errmsg();
    fail(f.path(), if_missing);
  }
  check(status, f.path(), "reading NSIDE (expected an integer)");
  pisco::check_nside(nside, f.path().string());
  return static_cast<int>(nside);
}

std::string column_name(const FitsFile& f, int col, const std::optional<std::string>& if_unreadable) {
  char key[FLEN_KEYWORD], value[FLEN_VALUE] = {};
  int status = 0;
  fits_make_keyn("TTYPE", col, key, &status);
  fits_read_key(f.get(), TSTRING, key, value, nullptr, &status);
  if (status) {
    fits_clear_errmsg();
    if (if_unreadable) return *if_unreadable;
  }
  return value;
}

TableSize table_size(const FitsFile& f) {
  TableSize size;
  int status = 0;
  fits_get_num_cols(f.get(), &size.columns, &status);
  fits_get_num_rowsll(f.get(), &size.rows, &status);
  check(status, f.path(), "reading the table size");
  return size;
}

ColumnType column_type(const FitsFile& f, int col, const std::string& label) {
  ColumnType c;
  long long width = 0;
  int status = 0;
  fits_get_coltypell(f.get(), col, &c.type, &c.repeat, &width, &status);
  check(status, f.path(), "reading the type of column " + label);
  return c;
}

bool is_fixed_numeric(int type) {
  return !(type <= 0 || type == TSTRING || type == TLOGICAL || type == TBIT || type == TCOMPLEX ||
           type == TDBLCOMPLEX);
}

void read_column(const FitsFile& f, int col, long long repeat, std::span<double> out,
                 const std::string& label) {
  long rows_per_chunk = 0;
  int status = 0;
  fits_get_rowsize(f.get(), &rows_per_chunk, &status);
  const long long chunk = std::max<long long>(1, rows_per_chunk) * repeat;
  const long long total = static_cast<long long>(out.size());
  for (long long first = 0; first < total && status == 0; first += chunk) {
    int anynul = 0;
    fits_read_col(f.get(), TDOUBLE, col, first / repeat + 1, first % repeat + 1,
                  std::min(chunk, total - first), nullptr, out.data() + first, &anynul, &status);
  }
  check(status, f.path(), "reading column " + label);
}

// ---- writing ------------------------------------------------------------------------------------

long long values_per_row(long long npix) { return npix % 1024 == 0 ? 1024 : 1; }

void write_columns(const FitsFile& f, int columns, long long total, long long repeat,
                   const ColumnValues& values) {
  int status = 0;
  long rows_per_chunk = 0;
  fits_get_rowsize(f.get(), &rows_per_chunk, &status);
  const long long chunk = std::max<long long>(1, rows_per_chunk) * repeat;
  for (long long first = 0; first < total && status == 0; first += chunk) {
    const long long n = std::min(chunk, total - first);
    for (int k = 0; k < columns && status == 0; ++k)
      fits_write_col(f.get(), TDOUBLE, k + 1, first / repeat + 1, first % repeat + 1, n,
                     const_cast<double*>(values(k, first, n)), &status);
  }
  check(status, f.path(), "writing the maps");
}

void write_atomically(const fs::path& file,
                      const std::function<void(const fs::path& temporary)>& write) {
  const TemporaryListing listed(temporary_name(file));
  const fs::path& temporary = listed.path();
  std::error_code ec;
  fs::remove(temporary, ec);  // a leftover of a crashed process with the same pid
  try {
    write(temporary);
    fs::rename(temporary, file);
  } catch (...) {
    fs::remove(temporary, ec);
    rethrow_naming(file);
  }
}

}  // namespace pisco::detail
