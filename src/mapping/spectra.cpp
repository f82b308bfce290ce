#include "pisco/spectra.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <alm_powspec_tools.h>
#include <arr.h>
#include <error_handling.h>
#include <healpix_data_io.h>
#include <healpix_map.h>
#include <planck_rng.h>
#include <powspec.h>
#include <xcomplex.h>

#include "io/input_file.hpp"
#include "core/sky_alm.hpp"
#include "core/text.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco {
namespace {

constexpr double two_pi = 2.0 * std::numbers::pi;

using AlmD = Alm<xcomplex<double>>;
using MapD = Healpix_Map<double>;

void check_lmax(const char* fn, int lmax) {
  if (lmax < 0) throw Error(std::string(fn) + ": lmax = " + std::to_string(lmax) + " is negative");
}

Spectra zero_spectra(int lmax) {
  const std::size_t n = std::size_t(lmax) + 1;
  Spectra s;
  for (auto* v : {&s.TT, &s.EE, &s.BB, &s.TE, &s.EB, &s.TB}) v->assign(n, 0.0);
  return s;
}

// ---- C_l table ------------------------------------------------------------------------------

[[noreturn]] void table_error(const std::filesystem::path& file, std::size_t line,
                              const std::string& what) {
  throw Error(file.string() + ":" + std::to_string(line) + ": " + what);
}

// One row: l TT EE BB TE (D_l, uK^2). Further columns, as some CAMB outputs carry, are ignored.
void parse_row(const std::filesystem::path& file, std::size_t line_no, const std::string& line,
               long& l, double d[4]) {
  std::istringstream in(line);
  double l_value = 0.0;
  if (!(in >> l_value) || !std::isfinite(l_value) || l_value < 0.0 ||
      l_value != std::floor(l_value))
    table_error(file, line_no, "expected a non-negative integer multipole l in the first column");
  // Beyond any lmax asked for (at most 4 x 8192): read as that, never converted out of a long's range.
  l = static_cast<long>(std::min(l_value, 1e9));
  static const char* names[4] = {"TT", "EE", "BB", "TE"};
  for (int k = 0; k < 4; ++k)
    if (!(in >> d[k]) || !std::isfinite(d[k]))
      table_error(file, line_no,
                  std::string("expected a finite number for ") + names[k] + " in column " +
                      std::to_string(k + 2) + " (columns: l TT EE BB TE)");
}

bool blank_or_comment(const std::string& line) {
  const auto first = line.find_first_not_of(" \t\r");
  return first == std::string::npos || line[first] == '#';
}

// ---- Harmonic transforms ----------------------------------------------------------------------

// planck_rng takes four 32-bit words. splitmix64 spreads the 64-bit seed over all of them, so that
// nearby seeds (0, 1, 2...) start far apart and no seed hits the generator's zero-word defaults
// by accident (a zero word is replaced by a fixed constant, which would alias seeds).
planck_rng seeded_rng(std::uint64_t seed) {
  auto next = [&seed]() {
    std::uint64_t z = (seed += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  };
  const std::uint64_t a = next(), b = next();
  return planck_rng(unsigned(a & 0xFFFFFFFFu), unsigned(a >> 32), unsigned(b & 0xFFFFFFFFu),
                    unsigned(b >> 32));
}

arr<double> to_arr(const std::vector<double>& v, int lmax) {
  arr<double> a(std::size_t(lmax) + 1);
  for (int l = 0; l <= lmax; ++l) a[l] = v[l];
  return a;
}


// A RING Healpix_Map of the values, UNSEEN as zero (anafast's treatment of masked pixels);
// NaN and infinities are errors rather than silently poisoning every a_lm.
MapD to_map(std::span<const double> values, int nside, const char* stokes) {
  MapD map(nside, RING, SET_NSIDE);
  if (values.size() != std::size_t(map.Npix()))
    throw Error(std::string("anafast: the ") + stokes + " map has " +
                std::to_string(values.size()) + " pixels; NSIDE " + std::to_string(nside) +
                " needs " + std::to_string(map.Npix()));
  for (std::size_t p = 0; p < values.size(); ++p) {
    const double x = values[p];
    if (!std::isfinite(x))
      throw Error(std::string("anafast: the ") + stokes + " map has a non-finite value at pixel " +
                  std::to_string(p));
    map[int(p)] = is_unseen(x) ? 0.0 : x;
  }
  return map;
}

// C_l^{XY} = Re sum_m a_lm b_lm^* / (2l + 1) over m = -l..l, healpy's alm2cl. Written out rather
// than through extract_crosspowspec, which stores the cross spectrum as a "TT" PowSpec and prints
// a warning on stderr whenever it has negative values, as cross spectra do.
std::vector<double> cross_spectrum(const AlmD& a, const AlmD& b) {
  const int lmax = a.Lmax();
  std::vector<double> cl(std::size_t(lmax) + 1, 0.0);
  for (int l = 0; l <= lmax; ++l) {
    // m < 0 mirrors m > 0 for real fields, hence the factor 2.
    double sum = a(l, 0).real() * b(l, 0).real() + a(l, 0).imag() * b(l, 0).imag();
    for (int m = 1; m <= std::min(l, a.Mmax()); ++m)
      sum += 2.0 * (a(l, m).real() * b(l, m).real() + a(l, m).imag() * b(l, m).imag());
    cl[l] = sum / (2.0 * l + 1.0);
  }
  return cl;
}

// ---- Windows --------------------------------------------------------------------------------

std::filesystem::path pixel_window_file(int nside) {
  char name[64];
  std::snprintf(name, sizeof name, "pixel_window_n%04d.fits", nside);
  return detail::healpy_data_dir() / name;
}

void check_window(const char* which, std::span<const double> w, std::size_t n) {
  if (!w.empty() && w.size() < n)
    throw Error(std::string("deconvolve_windows: the ") + which + " window has " +
                std::to_string(w.size()) + " entries; the spectra need " + std::to_string(n) +
                " (l = 0.." + std::to_string(n - 1) + ")");
}

double window_at(std::span<const double> w, std::size_t l) { return w.empty() ? 1.0 : w[l]; }

// Divides cl by wa(l) wb(l). A zero window (the polarization pixel window at l = 0, 1, where
// spin-2 fields have no modes) leaves that multipole at zero instead of 0/0.
std::vector<double> divide(const std::vector<double>& cl, const std::vector<double>& wa,
                           const std::vector<double>& wb) {
  std::vector<double> out(cl.size(), 0.0);
  for (std::size_t l = 0; l < cl.size(); ++l) {
    const double w = wa[l] * wb[l];
    out[l] = w == 0.0 ? 0.0 : cl[l] / w;
  }
  return out;
}

}  // namespace

std::filesystem::path default_cl_file() {
  return detail::healpy_data_dir() / "totcls.dat";
}

Spectra read_cl_table(const std::filesystem::path& file, int lmax, bool bb_zero) {
  check_lmax("read_cl_table", lmax);
  detail::require_regular_file(file, "a C_l table");
  std::ifstream in(file);
  if (!in) throw Error(file.string() + ": cannot open the C_l table");
  Spectra s = zero_spectra(lmax);
  std::string line;
  std::size_t line_no = 0, rows = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (blank_or_comment(line)) continue;
    long l = 0;
    double d[4];
    parse_row(file, line_no, line, l, d);
    ++rows;
    // C_0 and C_1 stay zero: D_l = l(l+1) C_l / 2pi carries no information there.
    if (l > lmax || l < 2) continue;
    const double to_cl = two_pi / (double(l) * double(l + 1));
    s.TT[l] = d[0] * to_cl;
    s.EE[l] = d[1] * to_cl;
    s.BB[l] = bb_zero ? 0.0 : d[2] * to_cl;
    s.TE[l] = d[3] * to_cl;
  }
  if (in.bad()) throw Error(file.string() + ": read error");
  if (rows == 0) throw Error(file.string() + ": no rows (expected columns l TT EE BB TE)");
  return s;
}

Sky synthesize_sky(const Spectra& cls, int nside, std::uint64_t seed) {
  check_nside(nside, "synthesize_sky");
  if (cls.TT.empty()) throw Error("synthesize_sky: the TT spectrum is empty");
  if (cls.EE.size() != cls.TT.size() || cls.BB.size() != cls.TT.size() ||
      cls.TE.size() != cls.TT.size())
    throw Error("synthesize_sky: TT, EE, BB and TE must have the same length");
  const int lmax = std::min(cls.lmax(), 3 * nside - 1);
  for (int l = 0; l <= lmax; ++l)
    if (!(cls.TT[l] >= 0.0 && cls.EE[l] >= 0.0 && cls.BB[l] >= 0.0) ||
        cls.TE[l] * cls.TE[l] > cls.TT[l] * cls.EE[l] * (1.0 + 1e-12))
      throw Error("synthesize_sky: C_l at l = " + std::to_string(l) +
                  " is not a valid covariance (need TT, EE, BB >= 0 and TE^2 <= TT EE)");

  // HEALPix names the polarization spectra by the a_lm they belong to: G (gradient) is E and
  // C (curl) is B. EB and TB are not synthesized (zero), as in synfast's default.
  arr<double> tt = to_arr(cls.TT, lmax), gg = to_arr(cls.EE, lmax), cc = to_arr(cls.BB, lmax),
              tg = to_arr(cls.TE, lmax);
  PowSpec ps(4, lmax);
  ps.Set(tt, gg, cc, tg);

  AlmD almT(lmax, lmax), almG(lmax, lmax), almC(lmax, lmax);
  planck_rng rng = seeded_rng(seed);
  MapD mapT(nside, RING, SET_NSIDE), mapQ(nside, RING, SET_NSIDE), mapU(nside, RING, SET_NSIDE);
  try {
    create_alm_pol(ps, almT, almG, almC, rng);
    alm2map_pol(almT, almG, almC, mapT, mapQ, mapU);
  } catch (const PlanckError& e) {
    throw Error(std::string("synthesize_sky: HEALPix: ") + e.what());
  }

  Sky sky(nside, "uK_CMB");
  std::copy(mapT.Map().begin(), mapT.Map().end(), sky.I().begin());
  std::copy(mapQ.Map().begin(), mapQ.Map().end(), sky.Q().begin());
  std::copy(mapU.Map().begin(), mapU.Map().end(), sky.U().begin());
  return sky;
}

Spectra anafast(std::span<const double> I, std::span<const double> Q, std::span<const double> U,
                int nside, int lmax, int iterations) {
  check_nside(nside, "anafast");
  check_lmax("anafast", lmax);
  if (iterations < 0)
    throw Error("anafast: iterations = " + std::to_string(iterations) + " is negative");
  const MapD mapT = to_map(I, nside, "I"), mapQ = to_map(Q, nside, "Q"), mapU = to_map(U, nside, "U");

  AlmD almT(lmax, lmax), almE(lmax, lmax), almB(lmax, lmax);
  try {
    // Unit ring weights, as healpy.anafast's default (use_weights=False).
    map2alm_pol_iter(mapT, mapQ, mapU, almT, almE, almB, iterations);
  } catch (const PlanckError& e) {
    throw Error(std::string("anafast: HEALPix: ") + e.what());
  }
  // healpy's order and signs: TE = <T E*>, EB = <E B*>, TB = <T B*>, with HEALPix's E = G and
  // B = C, the same a_lm healpy computes.
  Spectra s;
  s.TT = cross_spectrum(almT, almT);
  s.EE = cross_spectrum(almE, almE);
  s.BB = cross_spectrum(almB, almB);
  s.TE = cross_spectrum(almT, almE);
  s.EB = cross_spectrum(almE, almB);
  s.TB = cross_spectrum(almT, almB);
  return s;
}

std::vector<double> radial_beam_window(const std::function<double(double)>& profile, double theta_max, int lmax,
                                       int steps) {
  check_lmax("radial_beam_window", lmax);
  if (!(theta_max > 0.0 && theta_max <= std::numbers::pi))
    throw Error("radial_beam_window: theta_max = " + std::to_string(theta_max) + " rad must be in (0, pi]");
  if (steps < 2 || steps % 2) throw Error("radial_beam_window: steps = " + std::to_string(steps) + " must be even and >= 2");
  std::vector<double> sum(std::size_t(lmax) + 1, 0.0);
  const double h = theta_max / steps;
  for (int i = 0; i <= steps; ++i) {
    const double theta = i * h, b = profile(theta);
    if (!std::isfinite(b))
      throw Error("radial_beam_window: the profile is not finite at theta = " + std::to_string(theta) + " rad");
    const double w = (i == 0 || i == steps ? 1.0 : (i % 2 ? 4.0 : 2.0)) * b * std::sin(theta);
    if (w == 0.0) continue;
    // P_l(x) by the three-term recurrence.
    const double x = std::cos(theta);
    double p0 = 1.0, p1 = x;
    sum[0] += w;
    if (lmax >= 1) sum[1] += w * x;
    for (int l = 2; l <= lmax; ++l) {
      const double p2 = ((2.0 * l - 1.0) * x * p1 - (l - 1.0) * p0) / l;
      sum[l] += w * p2;
      p0 = p1;
      p1 = p2;
    }
  }
  if (!(sum[0] > 0.0)) throw Error("radial_beam_window: the profile's integral is not positive");
  std::vector<double> bl(sum.size());
  for (std::size_t l = 0; l < sum.size(); ++l) bl[l] = sum[l] / sum[0];
  return bl;
}

double elliptical_gaussian_radial_profile(double fwhm_x, double fwhm_y, double theta) {
  const double to_sigma = 1.0 / std::sqrt(8.0 * std::log(2.0));
  const double a = 0.5 / std::pow(fwhm_x * to_sigma, 2), b = 0.5 / std::pow(fwhm_y * to_sigma, 2);
  const double t2 = theta * theta;
  // exp(-t2 (a+b)/2) I0(t2 |a-b|/2), written with the exponentially scaled I0 to stay finite.
  const double z = 0.5 * t2 * std::abs(a - b);
  return std::exp(-t2 * (a + b) / 2 + z) * (z < 700 ? std::cyl_bessel_i(0.0, z) * std::exp(-z) : 1.0 / std::sqrt(2 * std::numbers::pi * z));
}

std::vector<double> gaussian_beam_window(double fwhm, int lmax, bool polarization) {
  if (!std::isfinite(fwhm) || fwhm < 0.0)
    throw Error("gaussian_beam_window: fwhm = " + std::to_string(fwhm) +
                " rad must be finite and non-negative");
  check_lmax("gaussian_beam_window", lmax);
  const double sigma2 = fwhm * fwhm / (8.0 * std::log(2.0));
  // Spin-s harmonics see a Gaussian beam as exp(-(l(l+1) - s^2) sigma^2 / 2) (Ng & Liu 1999;
  // Challinor et al. 2000): the spin-2 fields Q +- iU pick up s^2 = 4. healpy.gauss_beam(pol=True)
  // gives this as its E and B columns, exp(2 sigma^2) times the temperature window.
  const double shift = polarization ? 4.0 : 0.0;
  std::vector<double> w(std::size_t(lmax) + 1);
  for (int l = 0; l <= lmax; ++l) w[l] = std::exp(-0.5 * (double(l) * (l + 1) - shift) * sigma2);
  return w;
}

std::vector<double> pixel_window(int nside, int lmax, bool polarization) {
  check_nside(nside, "pixel_window");
  check_lmax("pixel_window", lmax);
  const std::filesystem::path file = pixel_window_file(nside);
  if (!std::filesystem::exists(file))
    throw Error(file.string() + ": pixel window file not found (Debian package healpy-data)");
  arr<double> temp, pol;
  try {
    read_pixwin(file.string(), temp, pol);
  } catch (const PlanckError& e) {
    throw Error(file.string() + ": cannot read the pixel window: " + e.what());
  }
  const arr<double>& w = polarization ? pol : temp;
  if (std::size_t(lmax) >= w.size())
    throw Error(file.string() + ": the pixel window goes to l = " + std::to_string(w.size() - 1) +
                ", below the requested lmax = " + std::to_string(lmax));
  return std::vector<double>(w.begin(), w.begin() + lmax + 1);
}

Spectra deconvolve_windows(const Spectra& spectra, std::span<const double> beam_t,
                           std::span<const double> beam_p, std::span<const double> pix_t,
                           std::span<const double> pix_p) {
  std::size_t n = 0;
  for (const auto* v : {&spectra.TT, &spectra.EE, &spectra.BB, &spectra.TE, &spectra.EB,
                        &spectra.TB})
    n = std::max(n, v->size());
  check_window("temperature beam", beam_t, n);
  check_window("polarization beam", beam_p, n);
  check_window("temperature pixel", pix_t, n);
  check_window("polarization pixel", pix_p, n);

  std::vector<double> wt(n), wp(n);
  for (std::size_t l = 0; l < n; ++l) {
    wt[l] = window_at(beam_t, l) * window_at(pix_t, l);
    wp[l] = window_at(beam_p, l) * window_at(pix_p, l);
  }
  Spectra out;
  out.TT = divide(spectra.TT, wt, wt);
  out.EE = divide(spectra.EE, wp, wp);
  out.BB = divide(spectra.BB, wp, wp);
  out.TE = divide(spectra.TE, wt, wp);
  out.EB = divide(spectra.EB, wp, wp);
  out.TB = divide(spectra.TB, wt, wp);
  return out;
}

std::vector<double> to_dl(std::span<const double> cl) {
  std::vector<double> dl(cl.size());
  for (std::size_t l = 0; l < cl.size(); ++l) dl[l] = double(l) * double(l + 1) * cl[l] / two_pi;
  return dl;
}

void check_finite(const Spectra& spectra, const std::string& where, int lmin, int lmax) {
  const std::pair<const char*, const std::vector<double>*> all[6] = {
      {"TT", &spectra.TT}, {"EE", &spectra.EE}, {"BB", &spectra.BB},
      {"TE", &spectra.TE}, {"EB", &spectra.EB}, {"TB", &spectra.TB}};
  for (const auto& [name, values] : all) {
    const long long last = lmax < 0 ? static_cast<long long>(values->size()) - 1
                                    : std::min<long long>(lmax, static_cast<long long>(values->size()) - 1);
    for (long long l = std::max(lmin, 0); l <= last; ++l)
      if (!std::isfinite((*values)[static_cast<std::size_t>(l)]))
        throw Error(where + ": " + name + " at l = " + std::to_string(l) + " is " +
                    detail::number_text((*values)[static_cast<std::size_t>(l)]) +
                    "; spectra are written finite (the maps they come from, or a beam or pixel window divided "
                    "out near zero, are not)");
  }
}

}  // namespace pisco
