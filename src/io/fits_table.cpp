#include "io/fits_table.hpp"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <vector>
#include <cstdlib>
#include <cstdio>
#include <new>
#include <utility>

#include <error_handling.h>

#include "io/input_file.hpp"
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

// ---- Headers checked before CFITSIO reads them ---------------------------------------------------

namespace {

// Whether `v` (a card's value field, after "= ") is a value of the FITS standard (section 4.2): a
// quoted string ('' inside for a quote), T or F, an integer or a real (E or D exponent), a complex
// "(re, im)", or nothing; then spaces and an optional "/ comment". CFITSIO's own parsers copy an
// unquoted word into fixed buffers and overrun them when it is long, so such a card never reaches it.
bool valid_value(const std::string& v) {
  std::size_t i = v.find_first_not_of(' ');
  if (i == std::string::npos || v[i] == '/') return true;  // no value (undefined), or a comment alone
  auto rest_is_comment = [&](std::size_t at) {
    const std::size_t j = v.find_first_not_of(' ', at);
    return j == std::string::npos || v[j] == '/';
  };
  if (v[i] == '\'') {
    for (std::size_t j = i + 1; j < v.size(); ++j)
      if (v[j] == '\'') {
        if (j + 1 < v.size() && v[j + 1] == '\'') {
          ++j;
          continue;
        }
        return rest_is_comment(j + 1);
      }
    return false;  // not closed within the card
  }
  if (v[i] == 'T' || v[i] == 'F') return rest_is_comment(i + 1);
  const auto number = [&](std::size_t& j) {
    if (j < v.size() && (v[j] == '+' || v[j] == '-')) ++j;
    std::size_t digits = 0;
    while (j < v.size() && std::isdigit(static_cast<unsigned char>(v[j]))) ++j, ++digits;
    if (j < v.size() && v[j] == '.') {
      ++j;
      while (j < v.size() && std::isdigit(static_cast<unsigned char>(v[j]))) ++j, ++digits;
    }
    if (digits == 0) return false;
    if (j < v.size() && (v[j] == 'E' || v[j] == 'D' || v[j] == 'e' || v[j] == 'd')) {
      ++j;
      if (j < v.size() && (v[j] == '+' || v[j] == '-')) ++j;
      std::size_t e = 0;
      while (j < v.size() && std::isdigit(static_cast<unsigned char>(v[j]))) ++j, ++e;
      if (e == 0) return false;
    }
    return true;
  };
  if (v[i] == '(') {
    std::size_t j = v.find_first_not_of(' ', i + 1);
    if (j == std::string::npos || !number(j)) return false;
    j = v.find_first_not_of(' ', j);
    if (j == std::string::npos || v[j] != ',') return false;
    j = v.find_first_not_of(' ', j + 1);
    if (j == std::string::npos || !number(j)) return false;
    j = v.find_first_not_of(' ', j);
    return j != std::string::npos && v[j] == ')' && rest_is_comment(j + 1);
  }
  std::size_t j = i;
  return number(j) && rest_is_comment(j);
}

// Every header of the file, card by card, before CFITSIO opens it: printable ASCII, keywords of the
// standard's characters, and values the standard allows; the data units between them skipped by
// their declared size. Stops at the end of the file (a truncated table is the readers' to refuse).
void check_headers(const fs::path& file, std::uintmax_t size, const std::string& expected) {
  std::FILE* in = std::fopen(file.c_str(), "rb");
  if (!in) return;  // CFITSIO then says why it cannot open it
  struct Closer {
    std::FILE* f;
    ~Closer() { std::fclose(f); }
  } closer{in};
  constexpr std::uintmax_t block = 2880;
  std::uintmax_t at = 0;
  for (int hdu = 1; at < size && hdu <= 1000; ++hdu) {
    double bitpix = 0, naxis = 0, pcount = 0, gcount = 1;
    std::vector<double> axes;
    bool end = false;
    for (int n = 1; !end; ++n) {
      if (at + 80 > size) {
        if (hdu == 1) fail(file, "the FITS header ends before its END card; " + expected);
        return;  // a truncated extension: CFITSIO and the readers say so
      }
      char card[80];
      if (std::fseek(in, long(at), SEEK_SET) != 0 || std::fread(card, 1, 80, in) != 80) return;
      at += 80;
      const std::string text(card, 80);
      const std::string where = "HDU " + std::to_string(hdu) + ", header card " + std::to_string(n);
      for (char c : text)
        if (c < 32 || c > 126)
          fail(file, where + " holds a byte that is not printable ASCII (a FITS header holds ASCII text only); " +
                         expected);
      const std::string key = text.substr(0, 8);
      const std::string name = key.substr(0, key.find_last_not_of(' ') + 1);
      for (char c : name)
        if (!(std::isupper(static_cast<unsigned char>(c)) || std::isdigit(static_cast<unsigned char>(c)) ||
              c == '-' || c == '_' || c == ' '))
          fail(file, where + ": the keyword '" + name + "' is not of the FITS standard's characters (A-Z, 0-9, - and _); " +
                         expected);
      if (name == "END") {
        end = true;
        break;
      }
      if (text.compare(8, 2, "= ") != 0) continue;  // commentary (COMMENT, HISTORY, blank, CONTINUE, HIERARCH)
      const std::string value = text.substr(10);
      if (!valid_value(value)) {
        std::string shown = value.substr(value.find_first_not_of(' '));
        shown = shown.substr(0, shown.find_last_not_of(' ') + 1);
        fail(file, where + " (" + name + "): the value '" + shown.substr(0, 40) + (shown.size() > 40 ? "..." : "") +
                       "' is neither a quoted string, a number, T nor F (FITS standard, section 4.2); " + expected);
      }
      const double number = std::atof(value.c_str());
      if (name == "BITPIX") bitpix = number;
      else if (name == "NAXIS") naxis = number;
      else if (name == "PCOUNT") pcount = number;
      else if (name == "GCOUNT") gcount = number;
      else if (name.rfind("NAXIS", 0) == 0 && name.size() > 5) axes.push_back(number);
    }
    at = (at + block - 1) / block * block;
    // The data unit: |BITPIX| / 8 GCOUNT (PCOUNT + NAXIS1 ... NAXISn) bytes, in whole blocks.
    double data = naxis > 0 ? 1.0 : 0.0;
    for (std::size_t k = 0; k < axes.size() && double(k) < naxis; ++k) data *= std::max(0.0, axes[k]);
    data = std::abs(bitpix) / 8 * std::max(1.0, gcount) * (std::max(0.0, pcount) + data);
    if (!(data >= 0) || data > double(size)) return;  // beyond the file: the readers say so
    at += (std::uintmax_t(data) + block - 1) / block * block;
  }
}

}  // namespace

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
  const std::uintmax_t size =
      require_regular_file(file, expected.rfind("expected ", 0) == 0 ? expected.substr(9) : expected);
  check_headers(file, size, expected);
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
