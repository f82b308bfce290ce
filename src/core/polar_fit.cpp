// The least-squares fit of the sky around each pole (polar_fit.hpp; docs/physics.md, "The
// quadrature").
//
// With c the coefficients of the whitened basis and s the caps' pixels, A c = s is the synthesis (per
// mode, the basis at the rings' colatitudes; per ring, the modes folded onto its bins and one inverse
// DFT). The fit is E p(A^H A) A^H s: p the polynomial of kIterations steps of a Chebyshev iteration on
// the interval [kFloor b, b] (b above A^H A's largest eigenvalue), which inverts A^H A where it is at
// least kFloor b and leaves what the pixels do not determine at zero; E the synthesis on a fine grid in
// theta. p is fixed (the same for every sky), so the fit is linear, and its transpose is
// A p(A^H A) E^H. Each mode's basis is whitened by the Cholesky factor of its Gram over the rings, so
// that A^H A is about 1 within a mode and the iteration has only the rings' aliases between modes to
// resolve: 100 steps do what 400 did without.
#include "core/polar_fit.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <memory>
#include <string>
#include <tuple>

#include <healpix_base.h>

#include "core/thread_pool.hpp"
#include "pisco/error.hpp"

namespace pisco::detail {
namespace {
using cd = std::complex<double>;
constexpr double pi = std::numbers::pi;
constexpr int F = PolarFit::kFields;
// Lagrange interpolation in theta on the fine grid: kGridPoints points, kGridStep grid points a ring.
constexpr int kGridPoints = 10;
constexpr int kGridStep = 4;
// The basis: l from the band limit down in steps of dl = kStep / theta_max (complete while
// dl theta_max < pi / 2); the band limit 3 NSIDE + 1 (a sky's 3 NSIDE - 1 and the spin of Q and U).
constexpr double kStep = 2.4;
// Power iterations for the bound b of the iteration's operator, and the margin above their estimate.
constexpr int kPowerSteps = 60;
constexpr double kBoundMargin = 1.25;

int fold(int m, int n) { return ((m % n) + n) % n; }

// The fit's inner loops on x86-64 compiled for AVX-512 and AVX2 beside the baseline, the loader picking
// what the processor has: kFields complex values are 8 doubles, one AVX-512 register.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define PISCO_FIT_CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define PISCO_FIT_CLONES
#endif
constexpr int D = 2 * F;  // doubles a value

// out[t] += sign table[j][t] c[j] over j (each of the D doubles): basis -> values at T points. Four j
// at a time, so that each out[t] is loaded and stored once for four products.
PISCO_FIT_CLONES void synthesize(const double* __restrict table, std::size_t J, std::size_t T, const double* __restrict c,
                                 double sign, double* __restrict out) {
  std::size_t j = 0;
  for (; j + 4 <= J; j += 4) {
    double cj[4][D];
    for (int q = 0; q < 4; ++q)
      for (int k = 0; k < D; ++k) cj[q][k] = sign * c[(j + std::size_t(q)) * D + std::size_t(k)];
    const double *r0 = table + j * T, *r1 = r0 + T, *r2 = r1 + T, *r3 = r2 + T;
    for (std::size_t t = 0; t < T; ++t) {
      double* o = out + t * D;
      for (int k = 0; k < D; ++k) o[k] += r0[t] * cj[0][k] + r1[t] * cj[1][k] + r2[t] * cj[2][k] + r3[t] * cj[3][k];
    }
  }
  for (; j < J; ++j) {
    double cj[D];
    for (int k = 0; k < D; ++k) cj[k] = sign * c[j * D + std::size_t(k)];
    const double* row = table + j * T;
    for (std::size_t t = 0; t < T; ++t) {
      double* o = out + t * D;
      for (int k = 0; k < D; ++k) o[k] += row[t] * cj[k];
    }
  }
}

// c[j] = sign sum_t table[j][t] in[t]: its transpose, four j at a time.
PISCO_FIT_CLONES void analyze(const double* __restrict table, std::size_t J, std::size_t T, const double* __restrict in,
                              double sign, double* __restrict c) {
  std::size_t j = 0;
  for (; j + 4 <= J; j += 4) {
    double acc[4][D] = {};
    const double *r0 = table + j * T, *r1 = r0 + T, *r2 = r1 + T, *r3 = r2 + T;
    for (std::size_t t = 0; t < T; ++t) {
      const double* x = in + t * D;
      for (int k = 0; k < D; ++k) {
        acc[0][k] += r0[t] * x[k];
        acc[1][k] += r1[t] * x[k];
        acc[2][k] += r2[t] * x[k];
        acc[3][k] += r3[t] * x[k];
      }
    }
    for (int q = 0; q < 4; ++q)
      for (int k = 0; k < D; ++k) c[(j + std::size_t(q)) * D + std::size_t(k)] = sign * acc[q][k];
  }
  for (; j < J; ++j) {
    double acc[D] = {};
    const double* row = table + j * T;
    for (std::size_t t = 0; t < T; ++t)
      for (int k = 0; k < D; ++k) acc[k] += row[t] * in[t * D + std::size_t(k)];
    for (int k = 0; k < D; ++k) c[j * D + std::size_t(k)] = sign * acc[k];
  }
}

double* doubles(cd* p) { return reinterpret_cast<double*>(p); }
// The sign of lambda_{l,-m} against lambda_{lm}: (-1)^m for m < 0.
double mode_sign(int m) { return m < 0 && (m % 2) ? -1.0 : 1.0; }
const double* doubles(const cd* p) { return reinterpret_cast<const double*>(p); }
}  // namespace

std::mutex& fftw_planner_mutex() {
  // Never destroyed: the fits kept by polar_fit_for destroy their plans at exit, after statics
  // constructed later than that cache.
  static std::mutex* m = new std::mutex;
  return *m;
}

double polar_ring_coordinate(double theta, int nside) {
  const double n = nside, z = std::cos(theta);
  return z >= 2.0 / 3.0 ? n * std::sqrt(3.0 * (1.0 - z)) : 2.0 * n - 1.5 * n * z;
}

int PolarFit::rings_for(int nside, double reach) {
  // The zone in rings: the reach's, rounded up to 16, 32 or 64 (kMaxZoneRings), so that copies of
  // nearby reaches (a split beam's parts, the whole beam) are one fit and read the same values.
  const int t = static_cast<int>(std::ceil(polar_ring_coordinate(reach, nside)));
  int zone = 16;
  while (zone < t && zone < kMaxZoneRings) zone *= 2;
  return std::min(zone, 4 * nside - 1 - kMarginRings) + kMarginRings;
}

namespace {
// lambda_lm(theta) (the normalized associated Legendre function, Y_lm = lambda_lm e^{i m phi}, without
// the Condon-Shortley sign) for l = m .. lmax at one theta; out[l - m]. In long double: the start
// sin^m theta underflows a double where the recurrence climbs out of it.
void legendre(int m, int lmax, double theta, std::vector<long double>& out) {
  out.assign(std::size_t(lmax - m + 1), 0.0L);
  const long double s = std::sin(static_cast<long double>(theta)), x = std::cos(static_cast<long double>(theta));
  long double start = 0.0L;
  if (m == 0) {
    start = std::sqrt(1.0L / (4.0L * std::numbers::pi_v<long double>));
  } else if (s > 0.0L) {
    const long double lg = 0.5L * (std::log((2.0L * m + 1.0L) / (4.0L * std::numbers::pi_v<long double>)) +
                                   std::lgamma(2.0L * m + 1.0L) - 2.0L * m * std::log(2.0L) - 2.0L * std::lgamma(m + 1.0L)) +
                           m * std::log(s);
    start = lg < -11000.0L ? 0.0L : std::exp(lg);
  }
  out[0] = start;
  if (lmax == m) return;
  out[1] = x * std::sqrt(2.0L * m + 3.0L) * start;
  for (int l = m + 2; l <= lmax; ++l) {
    const long double ll = l, mm = m;
    const long double a = std::sqrt((4.0L * ll * ll - 1.0L) / (ll * ll - mm * mm));
    const long double b = std::sqrt(((ll - 1.0L) * (ll - 1.0L) - mm * mm) / (4.0L * (ll - 1.0L) * (ll - 1.0L) - 1.0L));
    out[std::size_t(l - m)] = a * (x * out[std::size_t(l - m - 1)] - b * out[std::size_t(l - m - 2)]);
  }
}
}  // namespace

PolarFit::PolarFit(int nside, double reach, ThreadPool& pool) : nside_(nside) {
  const int T = rings_for(nside, reach);
  if (T > 4 * nside - 1) throw Error("the sky's polar fit: NSIDE " + std::to_string(nside) + " has too few rings for a reach of " + std::to_string(reach) + " rad");
  read_rings(T);
  zone_ = rings_[std::size_t(T - kMarginRings - 1)].theta;
  const double theta_max = rings_.back().theta;
  lband_ = 3 * nside + 1;
  M_ = std::min(lband_, static_cast<int>(std::ceil(lband_ * std::sin(std::min(theta_max, pi / 2)))) + 10);
  delta_ = rings_[0].theta / kGridStep;
  grid_ = static_cast<int>(std::ceil(zone_ / delta_)) + kGridPoints;
  tabulate(std::max(1, static_cast<int>(std::floor(kStep / theta_max))), pool);
  whiten_basis(pool);
  index_modes();
  plan_transforms();
  bound_spectrum(pool);
}

void PolarFit::read_rings(int T) {
  const T_Healpix_Base<int64> base(nside_, RING, SET_NSIDE);
  for (int i = 1; i <= T; ++i) {
    int64 start = 0, n = 0;
    double theta = 0.0;
    bool shifted = false;
    base.get_ring_info2(i, start, n, theta, shifted);
    Ring r;
    r.start = std::size_t(start);
    r.n = static_cast<int>(n);
    r.theta = theta;
    r.phi0 = shifted ? pi / double(n) : 0.0;
    r.offset = samples_;
    samples_ += std::size_t(n);
    rings_.push_back(r);
  }
}

// The basis at the rings and on the grid, l from the band limit down in steps of dl; functions below
// 1e-14 of the largest on every ring (deep in their evanescent region, |m| > l sin theta) left out.
void PolarFit::tabulate(int dl, ThreadPool& pool) {
  const std::size_t T = rings_.size();
  std::vector<std::vector<int>> ls(std::size_t(M_ + 1));
  modes_.resize(std::size_t(M_ + 1));
  std::vector<double> peak(std::size_t(M_ + 1), 0.0);
  pool.parallel_for(std::size_t(M_ + 1), 1, [&](std::size_t begin, std::size_t end) {
    std::vector<long double> v;
    for (std::size_t mi = begin; mi < end; ++mi) {
      const int m = static_cast<int>(mi);
      std::vector<int> l;
      for (int x = lband_; x >= m; x -= dl) l.push_back(x);
      Mode& mode = modes_[mi];
      mode.m = m;
      mode.at_rings.assign(l.size() * T, 0.0);
      for (std::size_t t = 0; t < T; ++t) {
        legendre(m, lband_, rings_[t].theta, v);
        for (std::size_t j = 0; j < l.size(); ++j) mode.at_rings[j * T + t] = double(v[std::size_t(l[j] - m)]);
      }
      for (const double x : mode.at_rings) peak[mi] = std::max(peak[mi], std::abs(x));
      ls[mi] = std::move(l);
    }
  });
  const double floor = 1e-14 * *std::max_element(peak.begin(), peak.end());
  pool.parallel_for(std::size_t(M_ + 1), 1, [&](std::size_t begin, std::size_t end) {
    std::vector<long double> v;
    for (std::size_t mi = begin; mi < end; ++mi) {
      Mode& mode = modes_[mi];
      const std::vector<int>& l = ls[mi];
      std::vector<double> kept;
      std::vector<int> keep;
      for (std::size_t j = 0; j < l.size(); ++j) {
        const auto row = mode.at_rings.begin() + std::ptrdiff_t(j * T);
        double top = 0.0;
        for (std::size_t t = 0; t < T; ++t) top = std::max(top, std::abs(row[std::ptrdiff_t(t)]));
        if (top < floor) continue;
        keep.push_back(int(j));
        kept.insert(kept.end(), row, row + std::ptrdiff_t(T));
      }
      mode.at_rings = std::move(kept);
      mode.at_grid.assign(keep.size() * std::size_t(grid_), 0.0);
      if (keep.empty()) continue;
      for (int g = 0; g < grid_; ++g) {
        legendre(mode.m, lband_, g * delta_, v);
        for (std::size_t k = 0; k < keep.size(); ++k)
          mode.at_grid[k * std::size_t(grid_) + std::size_t(g)] = double(v[std::size_t(l[std::size_t(keep[k])] - mode.m)]);
      }
    }
  });
}

// Each mode's block of A^H A (its Gram over the rings, ring t weighted by its n_t pixels), plus kWhiten
// times the largest diagonal, and its Cholesky factor L: the basis is whitened to L^-1 lambda (at the
// rings and on the grid), so that A^H A is about 1 within each mode and the iteration has the aliases
// between modes left to resolve.
void PolarFit::whiten_basis(ThreadPool& pool) {
  const std::size_t T = rings_.size();
  std::vector<std::vector<double>> grams(std::size_t(M_ + 1));
  std::vector<double> tops(std::size_t(M_ + 1), 0.0);
  pool.parallel_for(std::size_t(M_ + 1), 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t m = begin; m < end; ++m) {
      const std::vector<double>& b = modes_[m].at_rings;
      const std::size_t J = b.size() / T;
      std::vector<double>& g = grams[m];
      g.assign(J * J, 0.0);
      for (std::size_t i = 0; i < J; ++i)
        for (std::size_t k = 0; k <= i; ++k) {
          double sum = 0.0;
          for (std::size_t t = 0; t < T; ++t) sum += double(rings_[t].n) * b[i * T + t] * b[k * T + t];
          g[i * J + k] = g[k * J + i] = sum;
        }
      for (std::size_t i = 0; i < J; ++i) tops[m] = std::max(tops[m], g[i * J + i]);
    }
  });
  const double ridge = kWhiten * *std::max_element(tops.begin(), tops.end());
  pool.parallel_for(std::size_t(M_ + 1), 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t m = begin; m < end; ++m) {
      std::vector<double>& g = grams[m];
      const std::size_t J = modes_[m].at_rings.size() / T;
      for (std::size_t i = 0; i < J; ++i) g[i * J + i] += ridge;
      for (std::size_t j = 0; j < J; ++j) {  // in place: the lower triangle becomes L
        double d = g[j * J + j];
        for (std::size_t k = 0; k < j; ++k) d -= g[j * J + k] * g[j * J + k];
        g[j * J + j] = std::sqrt(d);  // d >= ridge > 0 in exact arithmetic
        for (std::size_t i = j + 1; i < J; ++i) {
          double v = g[i * J + j];
          for (std::size_t k = 0; k < j; ++k) v -= g[i * J + k] * g[j * J + k];
          g[i * J + j] = v / g[j * J + j];
        }
      }
      for (std::vector<double>* table : {&modes_[m].at_rings, &modes_[m].at_grid}) {  // L^-1 table, in place
        const std::size_t n = J ? table->size() / J : 0;
        for (std::size_t j = 0; j < J; ++j) {
          double* row = table->data() + j * n;
          for (std::size_t i = 0; i < j; ++i) {
            const double l = g[j * J + i];
            const double* done = table->data() + i * n;
            for (std::size_t x = 0; x < n; ++x) row[x] -= l * done[x];
          }
          for (std::size_t x = 0; x < n; ++x) row[x] /= g[j * J + j];
        }
      }
    }
  });
}

// Each signed m's coefficients' place, and the rings' phases e^{i m phi0}.
void PolarFit::index_modes() {
  const std::size_t T = rings_.size(), W = std::size_t(2 * M_ + 1);
  counts_.resize(W);
  offsets_.resize(W);
  for (std::size_t mi = 0; mi < W; ++mi) {
    counts_[mi] = static_cast<int>(modes_[std::size_t(std::abs(int(mi) - M_))].at_rings.size() / T);
    offsets_[mi] = coefficients_;
    coefficients_ += std::size_t(counts_[mi]);
  }
  phases_.resize(T * W);
  for (std::size_t t = 0; t < T; ++t)
    for (std::size_t mi = 0; mi < W; ++mi) phases_[t * W + mi] = std::polar(1.0, double(int(mi) - M_) * rings_[t].phi0);
}

// FFTW's plans for each ring length, both directions, four interleaved fields.
void PolarFit::plan_transforms() {
  std::lock_guard lock(fftw_planner_mutex());
  for (const Ring& r : rings_)
    for (const int sign : {FFTW_FORWARD, FFTW_BACKWARD}) {
      fftw_plan& plan = plans_[{r.n, sign}];
      if (plan) continue;
      std::vector<cd> a(std::size_t(r.n) * F), b(std::size_t(r.n) * F);
      int n = r.n;
      plan = fftw_plan_many_dft(1, &n, F, reinterpret_cast<fftw_complex*>(a.data()), nullptr, F, 1,
                                reinterpret_cast<fftw_complex*>(b.data()), nullptr, F, 1, sign, FFTW_ESTIMATE | FFTW_UNALIGNED);
      if (!plan) throw Error("the sky's polar fit: FFTW could not plan a transform of length " + std::to_string(r.n));
    }
}

// The bound of A^H A's spectrum by power iterations from a fixed vector (the same for every sky).
void PolarFit::bound_spectrum(ThreadPool& pool) {
  std::vector<cd> x(coefficients_ * F), y, scratch;
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = cd(std::cos(0.7 * double(i)), std::sin(1.3 * double(i)));
  double estimate = 0.0;
  for (int k = 0; k < kPowerSteps; ++k) {
    double nx = 0.0;
    for (const cd& v : x) nx += std::norm(v);
    normal(x, y, scratch, pool);
    double ny = 0.0;
    for (const cd& v : y) ny += std::norm(v);
    estimate = std::sqrt(ny / nx);
    const double s = 1.0 / std::sqrt(ny);
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = y[i] * s;
  }
  high_ = kBoundMargin * estimate;
  low_ = kFloor * high_;
}

PolarFit::~PolarFit() {
  std::lock_guard lock(fftw_planner_mutex());
  for (auto& [key, plan] : plans_) fftw_destroy_plan(plan);
}

void PolarFit::run_fft(int n, int sign, const cd* in, cd* out) const {
  fftw_execute_dft(plans_.at({n, sign}), reinterpret_cast<fftw_complex*>(const_cast<cd*>(in)), reinterpret_cast<fftw_complex*>(out));
}

void PolarFit::forward(const std::vector<cd>& c, std::vector<cd>& samples, ThreadPool& pool) const {
  const std::size_t T = rings_.size(), W = std::size_t(2 * M_ + 1);
  const std::vector<cd> modes = synthesize_modes(c, &Mode::at_rings, T, pool);
  samples.assign(samples_ * F, cd(0.0));
  pool.parallel_for(T, 1, [&](std::size_t begin, std::size_t end) {
    std::vector<cd> bins;
    for (std::size_t t = begin; t < end; ++t) {
      const Ring& r = rings_[t];
      bins.assign(std::size_t(r.n) * F, cd(0.0));
      for (std::size_t mi = 0; mi < W; ++mi) {
        const cd ph = phases_[t * W + mi];
        const cd* in = modes.data() + (mi * T + t) * F;
        cd* b = bins.data() + std::size_t(fold(int(mi) - M_, r.n)) * F;
        for (int f = 0; f < F; ++f) b[f] += ph * in[f];
      }
      run_fft(r.n, FFTW_BACKWARD, bins.data(), samples.data() + r.offset * F);
    }
  });
}

void PolarFit::adjoint(const std::vector<cd>& samples, std::vector<cd>& c, ThreadPool& pool) const {
  const std::size_t T = rings_.size(), W = std::size_t(2 * M_ + 1);
  std::vector<cd> modes(W * T * F, cd(0.0));
  pool.parallel_for(T, 1, [&](std::size_t begin, std::size_t end) {
    std::vector<cd> bins;
    for (std::size_t t = begin; t < end; ++t) {
      const Ring& r = rings_[t];
      bins.assign(std::size_t(r.n) * F, cd(0.0));
      run_fft(r.n, FFTW_FORWARD, samples.data() + r.offset * F, bins.data());
      for (std::size_t mi = 0; mi < W; ++mi) {
        const cd ph = std::conj(phases_[t * W + mi]);
        const cd* b = bins.data() + std::size_t(fold(int(mi) - M_, r.n)) * F;
        cd* out = modes.data() + (mi * T + t) * F;
        for (int f = 0; f < F; ++f) out[f] = ph * b[f];
      }
    }
  });
  c = analyze_modes(modes, &Mode::at_rings, T, pool);
}

void PolarFit::normal(const std::vector<cd>& c, std::vector<cd>& out, std::vector<cd>& scratch, ThreadPool& pool) const {
  forward(c, scratch, pool);
  adjoint(scratch, out, pool);
}


std::vector<cd> PolarFit::solve(const std::vector<cd>& rhs, ThreadPool& pool) const {
  const double d = 0.5 * (high_ + low_), h = 0.5 * (high_ - low_);
  std::vector<cd> x(rhs.size(), cd(0.0)), r = rhs, p(rhs.size()), np, scratch;
  double alpha = 0.0;
  for (int k = 0; k < kIterations; ++k) {
    if (k == 0) {
      p = r;
      alpha = 1.0 / d;
    } else {
      const double beta = k == 1 ? 0.5 * (h * alpha) * (h * alpha) : 0.25 * (h * alpha) * (h * alpha);
      alpha = 1.0 / (d - beta / alpha);
      for (std::size_t i = 0; i < p.size(); ++i) p[i] = r[i] + beta * p[i];
    }
    normal(p, np, scratch, pool);
    for (std::size_t i = 0; i < x.size(); ++i) {
      x[i] += alpha * p[i];
      r[i] -= alpha * np[i];
    }
  }
  return x;
}

// Each signed m's values at n points (the rings or the grid) from its coefficients, lambda_{l,-m} being
// (-1)^m lambda_{lm}; and the transpose.
std::vector<cd> PolarFit::synthesize_modes(const std::vector<cd>& c, std::vector<double> Mode::*table, std::size_t n,
                                           ThreadPool& pool) const {
  const std::size_t W = std::size_t(2 * M_ + 1);
  std::vector<cd> out(W * n * F, cd(0.0));
  pool.parallel_for(W, 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t mi = begin; mi < end; ++mi) {
      const int m = int(mi) - M_;
      synthesize((modes_[std::size_t(std::abs(m))].*table).data(), std::size_t(counts_[mi]), n,
                 doubles(c.data() + offsets_[mi] * F), mode_sign(m), doubles(out.data() + mi * n * F));
    }
  });
  return out;
}

std::vector<cd> PolarFit::analyze_modes(const std::vector<cd>& in, std::vector<double> Mode::*table, std::size_t n,
                                        ThreadPool& pool) const {
  const std::size_t W = std::size_t(2 * M_ + 1);
  std::vector<cd> c(coefficients_ * F, cd(0.0));
  pool.parallel_for(W, 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t mi = begin; mi < end; ++mi) {
      const int m = int(mi) - M_;
      analyze((modes_[std::size_t(std::abs(m))].*table).data(), std::size_t(counts_[mi]), n,
              doubles(in.data() + mi * n * F), mode_sign(m), doubles(c.data() + offsets_[mi] * F));
    }
  });
  return c;
}

PolarFit::Modes PolarFit::to_grid(const std::vector<cd>& c, ThreadPool& pool) const {
  return synthesize_modes(c, &Mode::at_grid, std::size_t(grid_), pool);
}

std::vector<cd> PolarFit::from_grid(const Modes& in, ThreadPool& pool) const {
  return analyze_modes(in, &Mode::at_grid, std::size_t(grid_), pool);
}

PolarFit::Modes PolarFit::fit(const std::vector<cd>& samples, ThreadPool& pool) const {
  if (samples.size() != samples_ * F) throw std::logic_error("PolarFit::fit: samples of the wrong size");
  std::vector<cd> rhs;
  adjoint(samples, rhs, pool);
  return to_grid(solve(rhs, pool), pool);
}

std::vector<cd> PolarFit::fit_transpose(const Modes& modes, ThreadPool& pool) const {
  std::vector<cd> samples;
  forward(solve(from_grid(modes, pool), pool), samples, pool);
  return samples;
}

namespace {
// Lagrange weights at grid coordinate u on the kGridPoints nodes g0 .. g0 + kGridPoints - 1.
int grid_weights(double u, std::array<double, kGridPoints>& w) {
  const int g0 = static_cast<int>(std::floor(u)) - (kGridPoints / 2 - 1);
  for (int k = 0; k < kGridPoints; ++k) {
    double num = 1.0, den = 1.0;
    for (int j = 0; j < kGridPoints; ++j)
      if (j != k) {
        num *= u - double(g0 + j);
        den *= double(k - j);
      }
    w[std::size_t(k)] = num / den;
  }
  return g0;
}
}  // namespace

PolarFit::Values PolarFit::value(const Modes& modes, double theta, double phi) const {
  std::array<double, kGridPoints> w{};
  const int g0 = grid_weights(theta / delta_, w);
  const std::size_t G = std::size_t(grid_);
  Values out{};
  const cd step = std::polar(1.0, phi);
  cd e = std::polar(1.0, -double(M_) * phi);
  for (int mi = 0; mi <= 2 * M_; ++mi, e *= step) {
    const int m = mi - M_;
    const cd* o = modes.data() + std::size_t(mi) * G * F;
    Values h{};
    for (int k = 0; k < kGridPoints; ++k) {
      const int g = g0 + k;
      // Beyond the pole: lambda_lm(-theta) = (-1)^m lambda_lm(theta).
      const double wk = g < 0 && (m % 2) ? -w[std::size_t(k)] : w[std::size_t(k)];
      const cd* v = o + std::size_t(std::abs(g)) * F;
      for (int f = 0; f < F; ++f) h[std::size_t(f)] += wk * v[f];
    }
    for (int f = 0; f < F; ++f) out[std::size_t(f)] += e * h[std::size_t(f)];
  }
  return out;
}

void PolarFit::add_value_transpose(Modes& bar, double theta, double phi, const Values& v) const {
  std::array<double, kGridPoints> w{};
  const int g0 = grid_weights(theta / delta_, w);
  const std::size_t G = std::size_t(grid_);
  const cd step = std::polar(1.0, -phi);
  cd e = std::polar(1.0, double(M_) * phi);
  for (int mi = 0; mi <= 2 * M_; ++mi, e *= step) {
    const int m = mi - M_;
    cd* o = bar.data() + std::size_t(mi) * G * F;
    Values h{};
    for (int f = 0; f < F; ++f) h[std::size_t(f)] = e * v[std::size_t(f)];
    for (int k = 0; k < kGridPoints; ++k) {
      const int g = g0 + k;
      const double wk = g < 0 && (m % 2) ? -w[std::size_t(k)] : w[std::size_t(k)];
      cd* x = o + std::size_t(std::abs(g)) * F;
      for (int f = 0; f < F; ++f) x[f] += wk * h[std::size_t(f)];
    }
  }
}

std::shared_ptr<const PolarFit> polar_fit_for(int nside, double reach, ThreadPool& pool) {
  // The fits last made, by NSIDE and reach (their tables cost more than a fit): a few, so that an
  // engine's sky and a split beam's coarse sky, forward and adjoint, do not make theirs again.
  static std::mutex mutex;
  static std::vector<std::tuple<int, double, std::shared_ptr<const PolarFit>>> cache;
  constexpr std::size_t kKept = 4;
  {
    std::lock_guard lock(mutex);
    for (std::size_t i = 0; i < cache.size(); ++i)
      if (std::get<0>(cache[i]) == nside && std::get<1>(cache[i]) == reach) {
        auto hit = cache[i];
        cache.erase(cache.begin() + std::ptrdiff_t(i));
        cache.insert(cache.begin(), hit);
        return std::get<2>(hit);
      }
  }
  auto fit = std::make_shared<const PolarFit>(nside, reach, pool);
  std::lock_guard lock(mutex);
  cache.insert(cache.begin(), {nside, reach, fit});
  if (cache.size() > kKept) cache.pop_back();
  return fit;
}

}  // namespace pisco::detail
