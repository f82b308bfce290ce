// HEALPix beamsor files, the PISCO paper's representation (docs/formats.md, "Beamsor files (HEALPix
// FITS)"; docs/physics.md, "Beamsors"): a FITS binary table of
// up to 16 full-sky HEALPix maps named B_TT, B_QT, ... (B_XY = Mueller row Y, column X), with the
// beam axis at the north pole and sigma = longitude.
//
// Reading resamples the maps onto the beamsor's orthographic grid with HEALPix's bilinear
// interpolation (get_interpol: linear in phi along the two nearest rings, then linear in theta).
// That resampling is the error this format adds, measured in test_beamsor_fits for a Gaussian of
// width s (FWHM 1.5 deg) written at NSIDE 1024 (3.4 arcmin pixels) and read back:
//  - it is largest on the beam axis, which HEALPix interpolates from the first ring of pixels at
//    theta_1 = acos(1 - 1/(3 NSIDE^2)): the axis value is low by 1 - exp(-theta_1^2 / 2 s^2),
//    about 1/(3 NSIDE^2 s^2) of the peak (2.6e-3 for the test beam);
//  - away from the axis it is smaller: 5.6e-4 of the peak at the nodes of a grid of the file's
//    pixel size, with no node on the axis;
//  - Omega~, the pixel sum of B_TT, is a midpoint rule in cos(theta) and is low by about
//    1/(18 NSIDE^2 s^2) (4.3e-4 for the test beam).
// All three fall as the square of the pixel size: a file should sample the beam's smallest feature
// (s) with NSIDE >= 1 / (s sqrt(3e-3)) for an axis error below 1e-3.

// The table goes through CFITSIO directly (io/fits_table.hpp; the same layout HEALPix C++ and
// healpy use), so that every failure is one pisco::Error naming the file; HEALPix C++ supplies the
// pixel geometry.
#include <fitsio.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <healpix_base.h>
#include <pointing.h>

#include "io/fits_table.hpp"
#include "core/text.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco {
namespace {

namespace fs = std::filesystem;

using namespace detail;  // io/fits_table.hpp

constexpr double pi = std::numbers::pi;
constexpr const char* stokes_letters = "TQUV";

// B_XY names row Y, column X (X leaks into Y); elements are stored at [row * 4 + col].
std::string element_name(int e) {
  return std::string("B_") + stokes_letters[e % 4] + stokes_letters[e / 4];
}

std::optional<int> element_of(const std::string& column_name) {
  const std::string n = trim_upper(column_name);
  if (n.size() != 4 || n.compare(0, 2, "B_") != 0) return std::nullopt;
  const char* x = std::strchr(stokes_letters, n[2]);
  const char* y = std::strchr(stokes_letters, n[3]);
  if (!x || !y || !*x || !*y) return std::nullopt;
  return static_cast<int>(y - stokes_letters) * 4 + static_cast<int>(x - stokes_letters);
}

// ---- reading ------------------------------------------------------------------------------------

constexpr const char* expected_file = "expected a HEALPix beamsor file";

struct BeamTable {
  int nside = 0;
  bool nested = false;
  long long rows = 0;
  std::array<int, 16> column{};           // FITS column number per element; 0 = absent
  std::array<long long, 16> repeat{};     // values per row
};

void read_geometry(const FitsFile& f, BeamTable& t) {
  t.nside = detail::read_nside(f, std::string("has no NSIDE key; ") + expected_file);
  const auto ordering = string_key(f, "ORDERING");
  const std::string o = ordering ? trim_upper(*ordering) : "";
  if (o != "RING" && o != "NESTED" && o != "NEST")
    fail(f.path(), "ORDERING = '" + ordering.value_or("") + "'; expected 'RING' or 'NESTED'");
  t.nested = o != "RING";
  const auto scheme = string_key(f, "INDXSCHM");
  if (scheme && trim_upper(*scheme) == "EXPLICIT")
    fail(f.path(), "is a cut-sky (partial) map; beamsor files must be full-sky maps");
}

// Maps the B_XY columns to elements; other columns are ignored. Each must hold 12 NSIDE^2 numbers.
void find_columns(const FitsFile& f, BeamTable& t) {
  const auto [ncols, rows] = detail::table_size(f);
  t.rows = rows;
  std::string found;
  const long long npix = 12LL * t.nside * t.nside;
  for (int c = 1; c <= ncols; ++c) {
    const std::string name = detail::column_name(f, c);
    found += (found.empty() ? "" : ", ") + name;
    const auto e = element_of(name);
    if (!e) continue;
    if (t.column[*e]) fail(f.path(), "has two columns named " + element_name(*e));
    const auto [type, repeat] = detail::column_type(f, c, name);
    if (!detail::is_fixed_numeric(type))
      fail(f.path(), "column " + name + " is not a numeric column of fixed width");
    if (repeat * t.rows != npix)
      fail(f.path(), "column " + name + " holds " + std::to_string(repeat * t.rows) +
                         " values; NSIDE = " + std::to_string(t.nside) + " needs 12 NSIDE^2 = " +
                         std::to_string(npix));
    t.column[*e] = c;
    t.repeat[*e] = repeat;
  }
  if (!t.column[0])
    fail(f.path(), "has no B_TT column (columns: " + (found.empty() ? "none" : found) +
                       "); expected HEALPix maps named B_TT, B_QT, B_UT, ... with at least B_TT");
}

// Number of RING pixels in the rings with colatitude <= theta, plus `extra` further rings.
long long ring_prefix(const Healpix_Base& base, double theta, int extra) {
  const int rings = 4 * base.Nside() - 1;
  int ring = 1;
  for (; ring <= rings; ++ring) {
    int start = 0, count = 0;
    double ring_theta = 0.0;
    bool shifted = false;
    base.get_ring_info2(ring, start, count, ring_theta, shifted);
    if (ring_theta > theta) break;
  }
  const int end_ring = std::min(rings, ring - 1 + extra);
  if (end_ring < 1) return 0;
  int start = 0, count = 0;
  bool shifted = false;
  base.get_ring_info_small(end_ring, start, count, shifted);
  return static_cast<long long>(start) + count;
}

// Reads the first `count` RING pixels of one element. CFITSIO converts to float64 and reads vector
// columns across rows; NESTED files are read whole and reordered first.
std::vector<double> read_element(const FitsFile& f, const BeamTable& t, int e, long long count) {
  const long long npix = 12LL * t.nside * t.nside;
  std::vector<double> values(static_cast<std::size_t>(t.nested ? npix : count));
  detail::read_column(f, t.column[e], t.repeat[e], values, element_name(e));
  if (!t.nested) return values;
  const Healpix_Base nest(t.nside, NEST, SET_NSIDE);
  std::vector<double> ring(static_cast<std::size_t>(count));
  for (int p = 0; p < nest.Npix(); ++p) {
    const int r = nest.nest2ring(p);
    if (r < count) ring[r] = values[p];
  }
  return ring;
}

// NaN and infinity are errors anywhere read; HEALPix's UNSEEN marker is an error inside the cap
// (the beam would be undefined there) and zero outside it, where masked files often use it.
void clean_element(const fs::path& file, int e, std::vector<double>& v, long long cap_pixels) {
  for (std::size_t p = 0; p < v.size(); ++p) {
    if (!std::isfinite(v[p]))
      fail(file, "column " + element_name(e) + " has a non-finite value at pixel " +
                     std::to_string(p) + " (RING); beam values must be finite");
    if (!is_unseen(v[p])) continue;
    if (static_cast<long long>(p) < cap_pixels)
      fail(file, "column " + element_name(e) + " is UNSEEN at pixel " + std::to_string(p) +
                     " (RING), inside rho_max; the beam must be defined over the whole cap");
    v[p] = 0.0;
  }
}

void check_read_arguments(const fs::path& file, double rho_max, double grid_step) {
  check_file_beam_options({.rho_max = rho_max, .grid_step = grid_step}, file.string());
}

// The polar cap of a beamsor file, in RING order: the pixels the grid can reach.
struct BeamMaps {
  int nside = 0;
  long long cap_pixels = 0;                     // pixels with theta <= rho_max
  std::array<std::vector<double>, 16> values;   // per element; empty if absent
};

// Reads the cap out to `reach`, plus the rings interpolation there touches.
BeamMaps load_maps(const fs::path& file, double rho_max, double reach) {
  std::error_code ec;
  if (!fs::exists(file, ec)) fail(file, std::string("no such file; ") + expected_file);
  const FitsFile f =
      FitsFile::open(file, "expected a HEALPix beamsor file (binary table with columns B_TT, ...)");
  detail::goto_first_binary_table(f, expected_file);
  detail::require_complete_hdu(f);
  BeamTable t;
  read_geometry(f, t);
  find_columns(f, t);
  const Healpix_Base base(t.nside, RING, SET_NSIDE);
  const long long needed = ring_prefix(base, reach, 2);
  BeamMaps m;
  m.nside = t.nside;
  m.cap_pixels = ring_prefix(base, rho_max, 0);
  for (int e = 0; e < 16; ++e) {
    if (!t.column[e]) continue;
    m.values[e] = read_element(f, t, e, needed);
    clean_element(file, e, m.values[e], m.cap_pixels);
  }
  return m;
}

// Omega~ = sum of B_TT over the pixels within rho_max times the pixel area.
double pixel_sum_omega(const fs::path& file, const BeamMaps& m, double rho_max) {
  double sum = 0.0;
  for (long long p = 0; p < m.cap_pixels; ++p) sum += m.values[0][static_cast<std::size_t>(p)];
  const double omega = sum * 4 * pi / (12.0 * m.nside * m.nside);
  if (!(omega > 0.0))
    fail(file, "the sum of B_TT over the pixels within rho_max = " + degrees_text(rho_max) + " is " +
                   std::to_string(omega) + " sr; expected a positive beam solid angle");
  return omega;
}

int grid_nodes(const fs::path& file, double half_width, double step, double rho_max) {
  const double nodes = std::ceil(2.0 * half_width / step) + 1.0;
  if (nodes > Beamsor::max_grid_nodes)
    fail(file, "grid_step = " + degrees_text(step) + " needs " + std::to_string(nodes) +
                   " nodes per axis for rho_max = " + degrees_text(rho_max) + "; at most " +
                   std::to_string(Beamsor::max_grid_nodes) + " are allowed: choose a larger grid_step");
  return std::max(3, static_cast<int>(nodes));
}

// HEALPix bilinear interpolation of every present element at (rho, sigma).
Beamsor::Field interpolating_field(const BeamMaps& m) {
  return [&m, base = Healpix_Base(m.nside, RING, SET_NSIDE)](double rho, double sigma) {
    Mueller out{};
    fix_arr<int, 4> pix;
    fix_arr<double, 4> wgt;
    base.get_interpol(pointing(rho, sigma < 0 ? sigma + 2 * pi : sigma), pix, wgt);
    for (int e = 0; e < 16; ++e) {
      const auto& v = m.values[e];
      if (v.empty()) continue;
      double sum = 0.0;
      for (int k = 0; k < 4; ++k)
        if (static_cast<std::size_t>(pix[k]) < v.size()) sum += wgt[k] * v[pix[k]];
      out[e / 4][e % 4] = sum;
    }
    return out;
  };
}

}  // namespace

Beamsor Beamsor::read_healpix_fits(const std::filesystem::path& file, double rho_max,
                                   double grid_step) {
  check_read_arguments(file, rho_max, grid_step);
  try {
    Beamsor b;
    b.rho_max_ = rho_max;
    b.a_ = std::sin(rho_max);
    // The grid's corner nodes lie at sin(rho) = sqrt(2) a; sample() evaluates them too.
    const BeamMaps maps = load_maps(file, rho_max, std::asin(std::min(1.0, std::sqrt(2.0) * b.a_)));
    const double pixel_size = std::sqrt(4 * pi / (12.0 * maps.nside * maps.nside));
    // By default 1.25 pixels: the grid's interpolation is of order step^3 (docs/physics.md,
    // "Interpolation on the grid"), finer than the map's own resampling.
    b.n_ = grid_nodes(file, b.a_, grid_step > 0 ? grid_step : 1.25 * pixel_size, rho_max);
    b.step_ = 2.0 * b.a_ / (b.n_ - 1);
    b.omega_ = pixel_sum_omega(file, maps, rho_max);
    b.description_ = "HEALPix beamsor file " + file.filename().string() + " (NSIDE " +
                     std::to_string(maps.nside) + ")";
    b.sample(interpolating_field(maps));
    if (!b.has_element(0, 0)) fail(file, "B_TT is zero everywhere on the beam grid");
    return b;
  } catch (...) {
    rethrow_naming(file);
  }
}

// ---- writing ------------------------------------------------------------------------------------

namespace {

void write_keys(const FitsFile& f, int nside, double rho_max, double grid_step,
                const std::string& description) {
  int status = 0;
  const auto str = [&](const char* key, const char* value, const char* comment) {
    fits_update_key(f.get(), TSTRING, key, const_cast<char*>(value), comment, &status);
  };
  long long nside_value = nside, first = 0, last = 12LL * nside * nside - 1;
  str("PIXTYPE", "HEALPIX", "HEALPIX pixelisation");
  str("ORDERING", "RING", "Pixel ordering scheme, either RING or NESTED");
  fits_update_key(f.get(), TLONGLONG, "NSIDE", &nside_value, "Resolution parameter of HEALPIX",
                  &status);
  fits_update_key(f.get(), TLONGLONG, "FIRSTPIX", &first, "First pixel # (0 based)", &status);
  fits_update_key(f.get(), TLONGLONG, "LASTPIX", &last, "Last pixel # (0 based)", &status);
  str("INDXSCHM", "IMPLICIT", "Indexing: IMPLICIT or EXPLICIT");
  str("OBJECT", "FULLSKY", "Sky coverage, either FULLSKY or PARTIAL");
  fits_update_key(f.get(), TDOUBLE, "RHOMAX", &rho_max, "[rad] beam extent; zero beyond", &status);
  fits_update_key(f.get(), TDOUBLE, "GRIDSTEP", &grid_step, "[rad] node step of the source grid",
                  &status);
  // COMMENT cards hold 70 characters; CFITSIO would split longer text mid-word.
  for (const char* line : {"PISCO beamsor: a field of Mueller matrices B over beam directions.",
                           "Column B_XY is row Y, column X (T, Q, U, V); absent columns are zero.",
                           "Beam axis at the north pole, sigma = longitude."})
    fits_write_comment(f.get(), line, &status);
  fits_write_comment(f.get(), ("Source: " + description).c_str(), &status);
  check(status, f.path(), "writing the header keys");
}

// Values of the present elements at the RING pixels within rho_max (a prefix of the RING order).
std::vector<std::vector<double>> cap_values(const Beamsor& b, const Healpix_Base& base,
                                            const std::vector<int>& present) {
  const long long cap = ring_prefix(base, b.rho_max(), 0);
  std::vector<std::vector<double>> values(present.size(),
                                          std::vector<double>(static_cast<std::size_t>(cap)));
  for (long long p = 0; p < cap; ++p) {
    const pointing ptg = base.pix2ang(static_cast<int>(p));
    const double s = std::sin(ptg.theta);
    const Mueller m = b.at(s * std::cos(ptg.phi), s * std::sin(ptg.phi));
    for (std::size_t k = 0; k < present.size(); ++k)
      values[k][static_cast<std::size_t>(p)] = m[present[k] / 4][present[k] % 4];
  }
  return values;
}

void write_beam_file(const fs::path& temporary, const fs::path& file, const Beamsor& b, int nside,
                     const std::vector<int>& present) {
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const long long npix = base.Npix();
  const auto values = cap_values(b, base, present);
  // healpy's layout of 1024 values per row where NSIDE allows it, as for sky maps.
  const long long repeat = detail::values_per_row(npix);
  const std::string form = std::to_string(repeat) + "D";
  std::vector<std::string> names;
  for (int e : present) names.push_back(element_name(e));
  std::vector<char*> ttype, tform, tunit;
  char empty[] = "";
  for (auto& n : names) {
    ttype.push_back(n.data());
    tform.push_back(const_cast<char*>(form.c_str()));
    tunit.push_back(empty);
  }
  FitsFile f = FitsFile::create(temporary, file);
  int status = 0;
  fits_create_img(f.get(), BYTE_IMG, 0, nullptr, &status);
  fits_create_tbl(f.get(), BINARY_TBL, npix / repeat, static_cast<int>(names.size()), ttype.data(),
                  tform.data(), tunit.data(), "BEAMSOR", &status);
  check(status, file, "creating the binary table");
  write_keys(f, nside, b.rho_max(), b.grid_step(), b.description());
  // Pixel p of element k is values[k][p] within the cap, zero beyond.
  std::vector<double> buffer;
  detail::write_columns(f, static_cast<int>(values.size()), npix, repeat,
                        [&](int k, long long first, long long n) {
                          const auto& v = values[static_cast<std::size_t>(k)];
                          const long long cap = static_cast<long long>(v.size());
                          buffer.assign(static_cast<std::size_t>(n), 0.0);
                          if (first < cap)
                            std::copy(v.begin() + first, v.begin() + std::min(cap, first + n),
                                      buffer.begin());
                          return static_cast<const double*>(buffer.data());
                        });
  f.close();
}

}  // namespace

void Beamsor::write_healpix_fits(const std::filesystem::path& file, int nside) const {
  check_nside(nside, file.string());
  std::vector<int> present;
  for (int e = 0; e < 16; ++e)
    if (!elements_[e].empty()) present.push_back(e);
  if (present.empty()) fail(file, "the beamsor has no non-zero element; nothing to write");
  // A temporary name in the same directory, renamed over `file`: never a half-written file.
  detail::write_atomically(file, [&](const fs::path& temporary) {
    write_beam_file(temporary, file, *this, nside, present);
  });
}

}  // namespace pisco
