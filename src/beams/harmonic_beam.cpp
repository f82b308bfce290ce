// Harmonic beams (docs/beams.md, "Harmonic beams"): b_lm in healpy's layout read from healpy alm FITS
// files and synthesized exactly onto a beamsor's nodes.
//
// Synthesis follows healpy's alm2map (checked against HEALPix C++'s alm2map_pol in test_beam_files):
//   T(rho, sigma)      =  sum_lm t_lm sqrt((2l+1)/4pi) d^l_{m,0}(rho) e^{i m sigma}
//   (Q + iU)(rho, sigma) = -sum_lm (e_lm + i b_lm) sqrt((2l+1)/4pi) d^l_{m,-2}(rho) e^{i m sigma}
// over -mmax <= m <= mmax (a_{l,-m} = (-1)^m conj(a_lm)), Q and U in the (rho-hat, sigma-hat) basis,
// with d^l the Wigner small-d matrices, computed by their three-term recursion in l from a closed
// form at l = max(|m|, |m'|). For each radius the Fourier coefficients in sigma are computed once, so
// a node costs O(mmax) and a radius O(lmax mmax).
#include <fitsio.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <numbers>
#include <sstream>
#include <thread>
#include <unordered_map>

#include "io/fits_table.hpp"
#include "core/text.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace {

using cd = std::complex<double>;
constexpr double pi = std::numbers::pi;

// d^l_{m1,m2}(beta) for l = 0..lmax (zero below max(|m1|, |m2|)).
//
// For any m up to lmax: the closed form at l0 is summed in logarithms (its factorials overflow a double
// beyond m of about 85, its powers of cos and sin underflow it), and the recursion carries a power of
// two apart from its values, so that a start far below the smallest double still grows into the
// values of larger l exactly. Values below the smallest double are 0.
void wigner_d(int m1, int m2, double beta, int lmax, std::vector<double>& d) {
  d.assign(static_cast<std::size_t>(lmax) + 1, 0.0);
  const int l0 = std::max(std::abs(m1), std::abs(m2));
  if (l0 > lmax) return;
  const double c = std::cos(beta / 2), s = std::sin(beta / 2);
  const double log_c = std::log(std::abs(c)), log_s = std::log(std::abs(s));
  // The closed form (a sum over k) at j = l0, in which only one or two terms survive: each term as a
  // sign and a logarithm, summed relative to the largest.
  const int j = l0, mp = m1, m = m2;
  std::vector<std::pair<double, double>> terms;  // (log |term|, sign)
  double largest = -std::numeric_limits<double>::infinity();
  for (int k = std::max(0, m - mp); k <= std::min(j + m, j - mp); ++k) {
    const int pc = 2 * j + m - mp - 2 * k, ps = mp - m + 2 * k;  // the powers of c and s, >= 0
    if ((pc > 0 && c == 0.0) || (ps > 0 && s == 0.0)) continue;  // a zero term (at beta = 0 or pi)
    const double lf = 0.5 * (std::lgamma(j + mp + 1.0) + std::lgamma(j - mp + 1.0) + std::lgamma(j + m + 1.0) +
                             std::lgamma(j - m + 1.0)) -
                      std::lgamma(j + m - k + 1.0) - std::lgamma(k + 1.0) - std::lgamma(mp - m + k + 1.0) -
                      std::lgamma(j - mp - k + 1.0) + (pc > 0 ? pc * log_c : 0.0) + (ps > 0 ? ps * log_s : 0.0);
    double sign = (mp - m + k) % 2 != 0 ? -1.0 : 1.0;
    if (pc % 2 != 0 && c < 0) sign = -sign;
    if (ps % 2 != 0 && s < 0) sign = -sign;
    terms.emplace_back(lf, sign);
    largest = std::max(largest, lf);
  }
  if (terms.empty()) return;  // d^l vanishes for every l (m1 != m2 at beta = 0, ...)
  double first = 0.0;
  for (const auto& [lf, sign] : terms) first += sign * std::exp(lf - largest);
  // The values are stored * 2^scale; the stored ones are kept between 2^-500 and 2^500.
  int scale = 0;
  {
    const double e2 = std::floor(largest / std::numbers::ln2);
    scale = static_cast<int>(std::clamp(e2, -1e6, 1e6));
    first *= std::exp(largest - scale * std::numbers::ln2);
  }
  const auto put = [&](int l, double stored) { d[static_cast<std::size_t>(l)] = std::ldexp(stored, scale); };
  put(l0, first);
  const double cb = std::cos(beta);
  const double mm = static_cast<double>(m1) * m2;
  const double a1 = static_cast<double>(m1) * m1, a2 = static_cast<double>(m2) * m2;
  double previous = 0.0, current = first;
  for (int l = l0; l < lmax; ++l) {
    const double dl = static_cast<double>(l);
    double next;
    if (l == 0) {
      next = cb;  // d^1_00
    } else {
      next = ((2 * dl + 1) * (dl * (dl + 1) * cb - mm) * current -
              (dl + 1) * std::sqrt(dl * dl - a1) * std::sqrt(dl * dl - a2) * previous) /
             (dl * std::sqrt((dl + 1) * (dl + 1) - a1) * std::sqrt((dl + 1) * (dl + 1) - a2));
    }
    previous = current;
    current = next;
    if (std::abs(current) > 0x1p500) {  // the recursion is linear: both values rescaled alike
      current = std::ldexp(current, -500);
      previous = std::ldexp(previous, -500);
      scale += 500;
    }
    put(l + 1, current);
  }
}

// The Fourier coefficients in sigma of T and of Q + iU at one radius.
struct Ring {
  std::vector<cd> t;  // m = 0..mmax: T = Re(t_0) + 2 sum_{m>0} Re(t_m e^{i m sigma})
  std::vector<cd> p;  // m = -mmax..mmax at [m + mmax]: Q + iU = sum_m p_m e^{i m sigma}
};

class Synthesis {
 public:
  explicit Synthesis(const HarmonicBeam& beam) : beam_(beam), norm_(static_cast<std::size_t>(beam.lmax) + 1) {
    for (int l = 0; l <= beam.lmax; ++l) norm_[static_cast<std::size_t>(l)] = std::sqrt((2.0 * l + 1) / (4 * pi));
  }

  Ring ring(double rho) const {
    const int lmax = beam_.lmax, mmax = beam_.mmax;
    Ring r;
    r.t.assign(static_cast<std::size_t>(mmax) + 1, cd{});
    std::vector<double> d;
    for (int m = 0; m <= mmax; ++m) {
      wigner_d(m, 0, rho, lmax, d);
      cd sum{};
      for (int l = m; l <= lmax; ++l)
        sum += beam_.t[HarmonicBeam::index(lmax, l, m)] * (norm_[static_cast<std::size_t>(l)] * d[static_cast<std::size_t>(l)]);
      r.t[static_cast<std::size_t>(m)] = sum;
    }
    if (!beam_.polarized()) return r;
    r.p.assign(2 * static_cast<std::size_t>(mmax) + 1, cd{});
    const cd i1(0.0, 1.0);
    for (int m = -mmax; m <= mmax; ++m) {
      const int am = std::abs(m);
      wigner_d(m, -2, rho, lmax, d);
      cd sum{};
      for (int l = std::max(2, am); l <= lmax; ++l) {
        const std::size_t k = HarmonicBeam::index(lmax, l, am);
        cd e = beam_.e[k], b = beam_.b[k];
        if (m < 0) {
          const double sign = am % 2 != 0 ? -1.0 : 1.0;
          e = sign * std::conj(e);
          b = sign * std::conj(b);
        }
        sum += (e + i1 * b) * (norm_[static_cast<std::size_t>(l)] * d[static_cast<std::size_t>(l)]);
      }
      r.p[static_cast<std::size_t>(m + mmax)] = -sum;
    }
    return r;
  }

 private:
  const HarmonicBeam& beam_;
  std::vector<double> norm_;
};

// T and, in the frame's Ludwig-3 basis, Q and U at beam-frame azimuth sigma.
void evaluate(const Ring& r, int mmax, double sigma, double& t, double& q, double& u) {
  t = r.t[0].real();
  for (int m = 1; m <= mmax; ++m) t += 2.0 * (r.t[static_cast<std::size_t>(m)] * std::polar(1.0, m * sigma)).real();
  q = u = 0.0;
  if (r.p.empty()) return;
  cd p{};
  for (int m = -mmax; m <= mmax; ++m) p += r.p[static_cast<std::size_t>(m + mmax)] * std::polar(1.0, m * sigma);
  // (rho-hat, sigma-hat) -> Ludwig 3: the frame's e_x lies at -sigma from rho-hat.
  p *= std::polar(1.0, 2.0 * sigma);
  q = p.real();
  u = p.imag();
}

bool harmonic_is_radial(const HarmonicBeam& beam) {
  for (int m = 1; m <= beam.mmax; ++m)
    for (int l = m; l <= beam.lmax; ++l)
      if (beam.t[HarmonicBeam::index(beam.lmax, l, m)] != cd{}) return false;
  if (!beam.polarized()) return true;
  // Q + iU proportional to e^{-2 i sigma} in (rho-hat, sigma-hat), so constant in the Ludwig-3
  // basis: e + i b zero at m = +2 (it stays at m = -2) and nothing at other m.
  for (int m = 0; m <= beam.mmax; ++m)
    for (int l = std::max(2, m); l <= beam.lmax; ++l) {
      const std::size_t k = HarmonicBeam::index(beam.lmax, l, m);
      if (m == 2) {
        if (std::abs(beam.e[k] + cd(0, 1) * beam.b[k]) > 1e-14 * (std::abs(beam.e[k]) + std::abs(beam.b[k]))) return false;
      } else if (beam.e[k] != cd{} || beam.b[k] != cd{}) {
        return false;
      }
    }
  return true;
}

// The default grid step: 0.75 / l_eff, with l_eff the largest l whose power sum_m |t_lm|^2 is at least
// 1e-12 of the largest (for a Gaussian of width s, l_eff s = 5.3 and the step is FWHM / 16.8), where the
// grid's interpolation error is of order step^3 (docs/physics.md, "Interpolation on the grid").
double default_step(const HarmonicBeam& beam) {
  std::vector<double> power(static_cast<std::size_t>(beam.lmax) + 1, 0.0);
  for (int m = 0; m <= beam.mmax; ++m)
    for (int l = m; l <= beam.lmax; ++l) power[static_cast<std::size_t>(l)] += std::norm(beam.t[HarmonicBeam::index(beam.lmax, l, m)]);
  const double peak = *std::max_element(power.begin(), power.end());
  int leff = 1;
  for (int l = 0; l <= beam.lmax; ++l)
    if (power[static_cast<std::size_t>(l)] >= 1e-12 * peak) leff = std::max(leff, l);
  return 0.75 / leff;
}

}  // namespace

std::size_t HarmonicBeam::size(int lmax, int mmax) {
  return static_cast<std::size_t>(mmax + 1) * (lmax + 1) - static_cast<std::size_t>(mmax) * (mmax + 1) / 2;
}

std::array<double, 3> HarmonicBeam::stokes_at(double rho, double sigma) const {
  check();
  const Ring r = Synthesis(*this).ring(rho);
  double t, q, u;
  evaluate(r, mmax, sigma, t, q, u);
  return {t, q, u};
}

void HarmonicBeam::check() const {
  const std::string who = "harmonic beam " + (source.empty() ? std::string("(arrays)") : source) + ": ";
  if (lmax < 0) throw Error(who + "lmax = " + std::to_string(lmax) + " must be at least 0");
  if (mmax < 0 || mmax > lmax)
    throw Error(who + "mmax = " + std::to_string(mmax) + " must lie in 0..lmax = " + std::to_string(lmax));
  const std::size_t n = size(lmax, mmax);
  if (t.size() != n)
    throw Error(who + "T has " + std::to_string(t.size()) + " coefficients; lmax " + std::to_string(lmax) +
                " and mmax " + std::to_string(mmax) + " need " + std::to_string(n));
  if (e.size() != b.size() || (!e.empty() && e.size() != n))
    throw Error(who + "E and B must both be empty (an unpolarized beam) or hold " + std::to_string(n) +
                " coefficients each; got " + std::to_string(e.size()) + " and " + std::to_string(b.size()));
  const char* names[3] = {"T", "E", "B"};
  const std::vector<cd>* parts[3] = {&t, &e, &b};
  for (int c = 0; c < 3; ++c)
    for (int m = 0; m <= mmax && !parts[c]->empty(); ++m)
      for (int l = m; l <= lmax; ++l) {
        const cd v = (*parts[c])[index(lmax, l, m)];
        if (!std::isfinite(v.real()) || !std::isfinite(v.imag()))
          throw Error(who + names[c] + " coefficient l = " + std::to_string(l) + ", m = " + std::to_string(m) +
                      " is not finite");
      }
  if (!(t[0].real() > 0.0))
    throw Error(who + "T's l = 0 coefficient (the beam's integral over the sphere, sqrt(4 pi) b_00) must be "
                      "positive, got " + std::to_string(t[0].real()));
}

namespace {
using namespace detail;

// One alm table of the file: its rows and its header's MAX-LPOL and MAX-MPOL (-1 where absent).
struct AlmTable {
  int hdu;
  std::vector<double> index, re, im;
  long long lmax_key = -1, mmax_key = -1;
};

// l and m of a healpy INDEX - 1, that is l^2 + l + m.
std::pair<long long, long long> alm_lm(long long i) {
  auto l = static_cast<long long>(std::sqrt(static_cast<double>(i)));
  while (l * l > i) --l;
  while ((l + 1) * (l + 1) <= i) ++l;
  return {l, i - l * l - l};
}

// The alm table of HDU h (the file positioned there); `expected` says what the file should be.
AlmTable read_alm_table(FitsFile& f, const std::filesystem::path& file, int h, const std::string& expected) {
  const std::string where = "HDU " + std::to_string(h) + ": ";
  require_complete_hdu(f);
  const TableSize size = table_size(f);
  int col_index = 0, col_re = 0, col_im = 0;
  for (int c = 1; c <= size.columns; ++c) {
    const std::string n = trim_upper(column_name(f, c, std::string()));
    if (n == "INDEX") col_index = c;
    if (n == "REAL") col_re = c;
    if (n == "IMAG") col_im = c;
  }
  if (!col_index || !col_re || !col_im) fail(file, where + "has no INDEX, REAL and IMAG columns; " + expected);
  AlmTable p;
  p.hdu = h;
  const auto n = static_cast<std::size_t>(size.rows);
  p.index.resize(n);
  p.re.resize(n);
  p.im.resize(n);
  const auto repeat = [&](int col, const char* label) {
    const ColumnType t = column_type(f, col, label);
    if (t.repeat != 1) fail(file, where + "column " + label + " holds " + std::to_string(t.repeat) + " values a row; expected 1");
    if (!is_fixed_numeric(t.type)) fail(file, where + "column " + label + " is not numeric");
    return t.repeat;
  };
  read_column(f, col_index, repeat(col_index, "INDEX"), p.index, "INDEX");
  read_column(f, col_re, repeat(col_re, "REAL"), p.re, "REAL");
  read_column(f, col_im, repeat(col_im, "IMAG"), p.im, "IMAG");
  long value = 0;
  int s2 = 0;
  if (fits_read_key(f.get(), TLONG, "MAX-LPOL", &value, nullptr, &s2) == 0) p.lmax_key = value;
  s2 = 0;
  if (fits_read_key(f.get(), TLONG, "MAX-MPOL", &value, nullptr, &s2) == 0) p.mmax_key = value;
  fits_clear_errmsg();
  return p;
}

// A table's header keys and rows checked, and the beam's lmax and mmax raised to them: the header's
// MAX-LPOL and MAX-MPOL where given, else the largest l and m present.
void check_alm_table(const AlmTable& p, const std::filesystem::path& file, HarmonicBeam& beam) {
  const std::string where = "HDU " + std::to_string(p.hdu) + ": ";
  if (p.lmax_key >= 0 && p.mmax_key > p.lmax_key)
    fail(file, where + "MAX-MPOL = " + std::to_string(p.mmax_key) + " is above MAX-LPOL = " + std::to_string(p.lmax_key) +
                   "; expected mmax <= lmax");
  if (p.lmax_key > 100000) fail(file, where + "MAX-LPOL = " + std::to_string(p.lmax_key) + " is above 100000");
  beam.lmax = std::max<long long>(beam.lmax, p.lmax_key);
  beam.mmax = std::max<long long>(beam.mmax, p.mmax_key);
  for (std::size_t r = 0; r < p.index.size(); ++r) {
    const double x = p.index[r];
    if (!(x >= 1 && x <= 1e10 && x == std::floor(x)))
      fail(file, where + "row " + std::to_string(r + 1) + ": INDEX " + std::to_string(x) + " is not l^2 + l + m + 1 of any l, m >= 0");
    const auto i = static_cast<long long>(x) - 1;
    const auto [l, m] = alm_lm(i);
    if (m < 0) fail(file, where + "row " + std::to_string(r + 1) + ": INDEX " + std::to_string(i + 1) + " is l = " + std::to_string(l) + ", m = " + std::to_string(m) + "; expected m >= 0");
    if (p.lmax_key >= 0 && l > p.lmax_key)
      fail(file, where + "row " + std::to_string(r + 1) + ": l = " + std::to_string(l) + " is above MAX-LPOL = " + std::to_string(p.lmax_key));
    if (p.mmax_key >= 0 && m > p.mmax_key)
      fail(file, where + "row " + std::to_string(r + 1) + ": m = " + std::to_string(m) + " is above MAX-MPOL = " + std::to_string(p.mmax_key));
    if (p.lmax_key < 0) beam.lmax = std::max<long long>(beam.lmax, l);
    if (p.mmax_key < 0) beam.mmax = std::max<long long>(beam.mmax, m);
    if (!std::isfinite(p.re[r]) || !std::isfinite(p.im[r]))
      fail(file, where + "row " + std::to_string(r + 1) + " (l = " + std::to_string(l) + ", m = " + std::to_string(m) + ") is not finite");
  }
}

}  // namespace

HarmonicBeam HarmonicBeam::read_fits(const std::filesystem::path& file) {
  using namespace detail;
  const std::string expected = "expected a healpy alm FITS file (healpy.write_alm: tables of INDEX, REAL, IMAG)";
  FitsFile f = FitsFile::open(file, expected);
  int hdus = 0, status = 0;
  fits_get_num_hdus(f.get(), &hdus, &status);
  detail::check(status, file, "counting its HDUs");
  std::vector<AlmTable> parts;
  for (int h = 2; h <= hdus; ++h) {
    int type = 0;
    fits_movabs_hdu(f.get(), h, &type, &status);
    detail::check(status, file, "moving to HDU " + std::to_string(h));
    if (type != BINARY_TBL && type != ASCII_TBL) continue;
    parts.push_back(read_alm_table(f, file, h, expected));
  }
  if (parts.size() != 1 && parts.size() != 3)
    fail(file, "has " + std::to_string(parts.size()) + " alm tables; expected 1 (T) or 3 (T, E, B), as healpy.write_alm writes them");
  HarmonicBeam beam;
  beam.source = file.string();
  for (const AlmTable& p : parts) check_alm_table(p, file, beam);
  if (beam.lmax < 0) fail(file, "its alm tables are empty");
  if (beam.mmax > beam.lmax)
    fail(file, "mmax = " + std::to_string(beam.mmax) + " is above lmax = " + std::to_string(beam.lmax));
  // The dense tables (16 bytes a coefficient, a table a component) against the rows the file holds:
  // healpy writes every coefficient up to lmax and mmax, a sparse writer the non-zero ones. A table
  // filled to less than a quarter (beyond a million coefficients) is refused before it is allocated:
  // a small file must not declare gigabytes, nor hours of synthesis (O(lmax mmax) a radius).
  const std::size_t n = size(beam.lmax, beam.mmax);
  std::size_t rows = 0;
  for (const AlmTable& p : parts) rows = std::max(rows, p.index.size());
  if (static_cast<double>(n) > 4.0 * static_cast<double>(rows) + 1e6)
    fail(file, "lmax = " + std::to_string(beam.lmax) + ", mmax = " + std::to_string(beam.mmax) + " (" +
                   (parts[0].lmax_key >= 0 ? "MAX-LPOL and MAX-MPOL" : "the largest l and m of its rows") + ") make " +
                   detail::count_text(static_cast<double>(n)) + " coefficients a component (" +
                   detail::bytes_text(16.0 * static_cast<double>(n) * static_cast<double>(parts.size())) +
                   "), but its tables hold " + std::to_string(rows) +
                   " rows; expected the coefficients up to lmax and mmax, as healpy.write_alm writes them");
  std::vector<cd>* out[3] = {&beam.t, &beam.e, &beam.b};
  for (std::size_t c = 0; c < parts.size(); ++c) {
    try {
      out[c]->assign(n, cd{});
    } catch (const std::bad_alloc&) {
      fail(file, detail::bytes_text(16.0 * static_cast<double>(n)) + " for the " + std::string(c == 0 ? "T" : c == 1 ? "E" : "B") +
                     " coefficients (lmax " + std::to_string(beam.lmax) + ", mmax " + std::to_string(beam.mmax) +
                     ") could not be allocated");
    }
    const AlmTable& p = parts[c];
    for (std::size_t r = 0; r < p.index.size(); ++r) {
      const auto [l, m] = alm_lm(static_cast<long long>(p.index[r]) - 1);
      (*out[c])[index(beam.lmax, static_cast<int>(l), static_cast<int>(m))] = cd(p.re[r], m == 0 ? 0.0 : p.im[r]);
    }
  }
  try {
    beam.check();
  } catch (const Error& e) {
    throw Error(std::string(e.what()), e.kind());
  }
  return beam;
}

Beamsor Beamsor::from_harmonic(const HarmonicBeam& beam, const FileBeamOptions& options) {
  beam.check();
  check_file_beam_options(options, "harmonic beam " + beam.source);
  const double step = options.grid_step > 0 ? options.grid_step : default_step(beam);
  const Synthesis synthesis(beam);
  // Rings by radius, computed once: the nodes' radii repeat eightfold, the quadrature's per panel node.
  auto cache = std::make_shared<std::map<double, Ring>>();
  auto mutex = std::make_shared<std::mutex>();
  // The main grid's node radii, laid out as Beamsor::from_field lays them out, synthesized ahead on
  // all hardware threads (a radius the layout misses is synthesized when first asked for).
  {
    const bool radial = harmonic_is_radial(beam);
    const double rho_grid = options.split.rho_main > 0 ? options.split.rho_main : options.rho_max;
    const double a = std::sin(rho_grid);
    std::vector<double> keys;
    // rho_max, the split and grid_step are checked above (check_file_beam_options); a degenerate step
    // synthesizes nothing ahead, and from_field says why.
    const bool valid = rho_grid > 0 && rho_grid < std::numbers::pi / 2 && std::isfinite(step) && step > 0;
    if (valid && radial) {
      const double h = step / radial_oversampling;
      const int n = radial_nodes(rho_grid, step, "harmonic beam " + beam.source);
      for (int i = 0; i < n; ++i) keys.push_back(std::asin(std::min(1.0, i * h)));
    } else if (valid && std::ceil(2.0 * a / step) + 1.0 <= max_grid_nodes) {
      const int n = std::max(3, static_cast<int>(std::ceil(2.0 * a / step) + 1.0));
      const double h = 2.0 * a / (n - 1);
      // One octant: the grid is symmetric about the axis, and mirrored nodes' radii round to one key.
      for (int j = 0; j <= (n - 1) / 2 + 1 && j < n; ++j)
        for (int i = 0; i <= j; ++i) {
          const double x = -a + i * h, y = -a + j * h;
          keys.push_back(std::asin(std::min(1.0, std::sqrt(x * x + y * y))));
        }
    }
    for (double& k : keys) k = std::round(k * 1e12) / 1e12;
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    std::vector<Ring> rings(keys.size());
    std::atomic<std::size_t> next{0}, done{0};
    const auto work = [&] {
      for (std::size_t k; (k = next.fetch_add(1)) < keys.size();) {
        rings[k] = synthesis.ring(keys[k]);
        done.fetch_add(1);
      }
    };
    const unsigned threads = std::max(1u, std::min(std::thread::hardware_concurrency(), 64u));
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < threads; ++t) pool.emplace_back(work);
    // Progress: the synthesis costs about 3 lmax mmax multiply-adds a radius (at 1e9 a second a
    // thread, lmax = mmax = 3000 and a thousand radii take about a minute on two threads).
    const double cost = 3.0 * (beam.lmax + 1.0) * (beam.mmax + 1.0) * double(keys.size()) / (1e9 * threads);
    if (options.progress && cost > 2.0) {
      options.progress("synthesizing " + std::to_string(keys.size()) + " radii of the b_lm beam (lmax " +
                       std::to_string(beam.lmax) + ", mmax " + std::to_string(beam.mmax) + ", about " +
                       detail::number_text(std::ceil(cost), 3) + " s)");
      auto last = std::chrono::steady_clock::now();
      while (done.load() < keys.size()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
        if (std::chrono::steady_clock::now() - last < std::chrono::seconds(5)) continue;
        last = std::chrono::steady_clock::now();
        options.progress("synthesized " + std::to_string(done.load()) + " of " + std::to_string(keys.size()) + " radii");
      }
    }
    for (auto& t : pool) t.join();
    for (std::size_t k = 0; k < keys.size(); ++k) cache->emplace(keys[k], std::move(rings[k]));
  }
  const int mmax = beam.mmax;
  const double angle = options.angle;
  const Field field = [=, &synthesis](double rho, double sigma) {
    const double key = std::round(rho * 1e12) / 1e12;
    const Ring* r;
    {
      std::lock_guard lock(*mutex);
      auto it = cache->find(key);
      if (it == cache->end()) it = cache->emplace(key, synthesis.ring(key)).first;
      r = &it->second;
    }
    double t, q, u;
    evaluate(*r, mmax, sigma - angle, t, q, u);
    return stokes_mueller(t, q, u, 0.0);
  };
  std::ostringstream d;
  d << "harmonic beam " << beam.source << " (lmax " << beam.lmax << ", mmax " << beam.mmax
    << (beam.polarized() ? ", T E B" : ", T only") << ")";
  if (angle != 0.0) d << " turned by " << angle / deg << " deg";
  d << ", rho_max " << options.rho_max / deg << " deg, grid step " << step / deg * 60 << " arcmin";
  return from_field(field, options.rho_max, step, d.str(), 0.0, harmonic_is_radial(beam), options.split);
}

}  // namespace pisco
