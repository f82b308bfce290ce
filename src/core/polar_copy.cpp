// The polar copy made around each pole (polar_copy.hpp; docs/physics.md, "The quadrature").
//
// Within the fit's zone a copy pixel is the least-squares fit's value at its place (polar_fit.hpp);
// beyond it (reaches of more than 64 rings), the rings' interpolation, blended with the fit over the
// zone's last rings. Per pole, the interpolation is linear in the sky and made in five steps, each
// with its transpose below:
// 1. each ring's samples, Q and U turned into the frame transported from the pole, and their DFT;
// 2. each ring's spectrum at 4x its length: the modes it resolves, and for the innermost rings the
//    modes it cannot resolve, predicted from the rings beyond (outermost first) and taken out of the
//    bins they alias onto;
// 3. the upsampled ring values (the inverse transform);
// 4. the value at the pole, filled in from the rings' means by a filter for band-limited data;
// 5. each copy pixel from its stencil: Lagrange interpolation in the ring index t along the great
//    circle through the pole (the pole a node like the rings), Lagrange interpolation in phi between
//    the upsampled points of each ring, and the turn into the copy's frame.
#include "core/polar_copy.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <map>
#include <mutex>
#include <numbers>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <fftw3.h>
#include <healpix_base.h>

#include "core/polar_fit.hpp"
#include "core/poles.hpp"
#include "core/thread_pool.hpp"
#include "pisco/error.hpp"

namespace pisco::detail {
namespace {
using cd = std::complex<double>;
using Base = T_Healpix_Base<int64>;
constexpr double pi = std::numbers::pi;

// Each ring upsampled kUpsample times by FFT and read by kPhiPoints-point Lagrange interpolation.
constexpr int kUpsample = 4;
constexpr int kPhiPoints = 6;
// Across rings: Lagrange interpolation on the 2 kHalfWidth nodes in t around the point, the pole a
// node like the rings (docs/physics.md, "The quadrature", has the choices measured).
constexpr int kHalfWidth = 12;
// The pole's value is designed for data band-limited to kBand of the ring spacing's Nyquist frequency
// (a sky with power up to 3 NSIDE reaches 0.78 of it around the poles, 2 NSIDE 0.52).
constexpr double kBand = 0.8;
// The value at the pole from the means of the first kPoleRings rings, for the same band.
constexpr int kPoleRings = 32;
// The innermost kDealiasRings rings: ring t has 4t pixels and cannot hold |m| >= 2t. Mode m is
// predicted from the first kPredictPoints rings that resolve it, as sin^|m| theta times a polynomial
// in cos theta (the form of every band-limited field around a pole).
constexpr int kDealiasRings = 16;
constexpr int kPredictPoints = 8;
constexpr int kStencil = 2 * kHalfWidth * kPhiPoints;

fftw_complex* fftw(cd* p) { return reinterpret_cast<fftw_complex*>(p); }

// Plans by length and direction for arrays of any alignment, made before any thread runs them.
class Plans {
 public:
  Plans() = default;
  Plans(const Plans&) = delete;
  Plans& operator=(const Plans&) = delete;
  ~Plans() {
    std::lock_guard lock(fftw_planner_mutex());
    for (auto& [key, plan] : plans_) fftw_destroy_plan(plan);
  }
  void make(int n) {
    std::lock_guard lock(fftw_planner_mutex());
    for (const int sign : {FFTW_FORWARD, FFTW_BACKWARD}) {
      fftw_plan& plan = plans_[{n, sign}];
      if (plan) continue;
      std::vector<cd> a(static_cast<std::size_t>(n)), b(static_cast<std::size_t>(n));
      plan = fftw_plan_dft_1d(n, fftw(a.data()), fftw(b.data()), sign, FFTW_ESTIMATE | FFTW_UNALIGNED);
      if (!plan) throw Error("the sky's polar copy: FFTW could not plan a transform of length " + std::to_string(n));
    }
  }
  // Unnormalized: forward sum_j x_j e^{-2 pi i jk/n}, backward with e^{+}.
  void run(int n, int sign, const cd* in, cd* out) const {
    fftw_execute_dft(plans_.at({n, sign}), fftw(const_cast<cd*>(in)), fftw(out));
  }

 private:
  std::map<std::pair<int, int>, fftw_plan> plans_;
};

// Lagrange weights at x of the n nodes xs.
template <std::size_t N>
void lagrange(const std::array<double, N>& xs, int n, double x, std::array<double, N>& w) {
  for (int k = 0; k < n; ++k) {
    double num = 1.0, den = 1.0;
    for (int j = 0; j < n; ++j)
      if (j != k) {
        num *= x - xs[j];
        den *= xs[k] - xs[j];
      }
    w[k] = num / den;
  }
}

std::vector<double> solve(std::vector<double> A, std::vector<double> b) {
  const int n = static_cast<int>(b.size());
  for (int c = 0; c < n; ++c) {
    int piv = c;
    for (int r = c + 1; r < n; ++r)
      if (std::abs(A[r * n + c]) > std::abs(A[piv * n + c])) piv = r;
    for (int k = 0; k < n; ++k) std::swap(A[c * n + k], A[piv * n + k]);
    std::swap(b[c], b[piv]);
    for (int r = c + 1; r < n; ++r) {
      const double f = A[r * n + c] / A[c * n + c];
      for (int k = c; k < n; ++k) A[r * n + k] -= f * A[c * n + k];
      b[r] -= f * b[c];
    }
  }
  std::vector<double> x(b.size());
  for (int c = n - 1; c >= 0; --c) {
    double v = b[c];
    for (int k = c + 1; k < n; ++k) v -= A[c * n + k] * x[k];
    x[c] = v / A[c * n + c];
  }
  return x;
}

// int_{-Omega}^{Omega} cos(omega d) d omega.
double band_integral(double d) {
  const double om = kBand * pi;
  return std::abs(d) < 1e-14 ? 2.0 * om : 2.0 * std::sin(om * d) / d;
}
constexpr double kRidge = 1e-9;  // keeps the design's normal equations well posed

// The pole's value from the rings' means g(t), t = 1 .. kPoleRings, of an even function of t:
// g(0) = sum_t c_t g(t) with c minimizing the mean square error over |omega| <= kBand pi of
// 1 - sum_t c_t cos(omega t) (a ridge added), scaled to sum to 1.
const std::vector<double>& pole_weights() {
  static const std::vector<double> c = [] {
    constexpr int n = kPoleRings;
    // Over [0, Omega] of cos(omega a) cos(omega b) = (I(a - b) + I(a + b)) / 4 with I over [-Omega, Omega].
    std::vector<double> A(static_cast<std::size_t>(n * n), 0.0), b(static_cast<std::size_t>(n), 0.0);
    for (int a = 0; a < n; ++a) {
      b[a] = band_integral(a + 1) / 2;
      for (int k = 0; k < n; ++k) A[a * n + k] = (band_integral(a - k) + band_integral(a + k + 2)) / 4 + (a == k ? kRidge : 0.0);
    }
    std::vector<double> w = solve(A, b);
    double sum = 0.0;
    for (const double v : w) sum += v;
    for (double& v : w) v /= sum;
    return w;
  }();
  return c;
}

struct Ring {
  int64 start = 0;  // its first pixel
  int n = 0;        // its pixels
  double theta = 0.0;  // its colatitude from the cap's pole
  double cos_theta = 1.0, sin_theta = 0.0;
  double phi0 = 0.0;       // its first pixel's longitude
  std::size_t offset = 0;  // its upsampled values' place in the cap's buffers
  int size() const { return kUpsample * n; }
};

// One pole's rings, counted from the pole (ring t has 4t pixels in the polar cap), and their values:
// field 0 is I + i V, field 1 Q_c + i U_c (Q, U in the frame parallel-transported from the pole).
struct Cap {
  int sign = 1;  // +1 north, -1 south
  int nside = 0;
  std::vector<Ring> rings;
  std::array<std::vector<cd>, 2> values;  // the rings' upsampled values, then the pole's value
  std::size_t pole = 0;
};

// The frame transported from the pole, as a turn of the local (e_theta, e_phi) frame by alpha
// (counted from e_theta towards e_phi): alpha = -phi around the north pole, +phi around the south one.
// Stokes parameters in a frame turned by alpha are e^{-2 i alpha} (Q + i U) (COSMO convention).
cd to_pole_frame(int sign, double phi) { return std::polar(1.0, 2.0 * sign * phi); }

// The rings that a copy of the given reach reads: up to the one kHalfWidth + 1 beyond reach, and at
// least kPoleRings + kPredictPoints. 0 when the sky has too few.
int rings_needed(int nside, double reach) {
  const int t = static_cast<int>(std::ceil(polar_ring_coordinate(reach, nside)));
  const int need = std::max({t + kHalfWidth + 1, kPoleRings + kPredictPoints, PolarFit::rings_for(nside, reach)});
  return need <= 4 * nside - 1 ? need : 0;
}

Cap make_cap(const Base& base, int sign, double reach) {
  const int nside = static_cast<int>(base.Nside());
  Cap cap;
  cap.sign = sign;
  cap.nside = nside;
  const int K = rings_needed(nside, reach);
  std::size_t offset = 0;
  for (int i = 1; i <= K; ++i) {
    int64 start = 0, n = 0;
    double theta = 0.0;
    bool shifted = false;
    base.get_ring_info2(sign > 0 ? i : 4 * nside - i, start, n, theta, shifted);
    Ring r;
    r.start = start;
    r.n = static_cast<int>(n);
    r.theta = sign > 0 ? theta : pi - theta;
    r.cos_theta = std::cos(r.theta);
    r.sin_theta = std::sin(r.theta);
    r.phi0 = shifted ? pi / double(n) : 0.0;
    r.offset = offset;
    offset += static_cast<std::size_t>(r.size());
    cap.rings.push_back(r);
  }
  cap.pole = offset;
  for (auto& v : cap.values) v.assign(offset + 1, cd(0.0));
  return cap;
}

int bin(int m, int size) { return ((m % size) + size) % size; }

// Step 2. The prediction of mode m of ring r (h_m, its phase e^{i m phi0} included) is
// sum_q kappa_q z_q[bin(m)] over the first kPredictPoints rings q beyond r that resolve m (z_q = n_q h
// at the bins of its upsampled length).
struct Prediction {
  int count = 0;
  std::array<std::size_t, kPredictPoints> index{};  // into the cap's buffer
  std::array<cd, kPredictPoints> kappa{};
};

Prediction prediction(const Cap& cap, std::size_t r, int m) {
  const std::size_t K = cap.rings.size();
  const int am = std::abs(m);
  std::size_t first = r + 1;
  while (first < K && cap.rings[first].n / 2 <= am) ++first;
  Prediction p;
  if (first + kPredictPoints > K) return p;
  std::array<double, kPredictPoints> xs{}, w{};
  for (int q = 0; q < kPredictPoints; ++q) xs[q] = cap.rings[first + q].cos_theta;
  const Ring& at = cap.rings[r];
  lagrange(xs, kPredictPoints, at.cos_theta, w);
  p.count = kPredictPoints;
  for (int q = 0; q < kPredictPoints; ++q) {
    const Ring& s = cap.rings[first + q];
    p.index[q] = s.offset + static_cast<std::size_t>(bin(m, s.size()));
    p.kappa[q] = w[q] * std::pow(at.sin_theta / s.sin_theta, am) / double(s.n) * std::polar(1.0, m * (at.phi0 - s.phi0));
  }
  return p;
}

// The modes of ring r that are predicted: none beyond the innermost rings; |m| from n/2 to the
// upsampled length's limit.
bool dealiased(std::size_t r) { return static_cast<int>(r) < kDealiasRings; }

// Ring r's upsampled spectrum z (n h_m at bin m mod 4n) from its DFT c: resolved modes from c, the
// unresolved ones predicted (the rings beyond r made first) and taken out of the bins they alias onto;
// the Nyquist bin's remainder split evenly between +n/2 and -n/2. The ring's values at its pixels
// stay its samples.
void ring_spectrum(const Cap& cap, std::size_t r, const std::vector<cd>& c, std::vector<cd>& z) {
  const Ring& ring = cap.rings[r];
  const int n = ring.n, size = ring.size(), top = size / 2 - 1;
  cd* out = z.data() + ring.offset;
  std::fill(out, out + size, cd(0.0));
  std::vector<cd> pred(static_cast<std::size_t>(size), cd(0.0));
  if (dealiased(r))
    for (int m = -top; m <= top; ++m)
      if (std::abs(m) >= n / 2) {
        const Prediction p = prediction(cap, r, m);
        cd v(0.0);
        for (int q = 0; q < p.count; ++q) v += p.kappa[q] * z[p.index[q]];
        pred[bin(m, size)] = v;
      }
  const auto aliases = [&](int k) {  // the predicted modes that fall on ring bin k, k included
    cd sum(0.0);
    for (int m = k - n * ((k + top) / n); m <= top; m += n)
      if (std::abs(m) >= n / 2) sum += pred[bin(m, size)];
    return sum;
  };
  for (int k = -(n / 2 - 1); k < n / 2; ++k) out[bin(k, size)] = c[bin(k, n)] - double(n) * aliases(k);
  const cd rest = c[n / 2] - double(n) * aliases(n / 2);
  out[bin(n / 2, size)] = double(n) * pred[bin(n / 2, size)] + 0.5 * rest;
  out[bin(-n / 2, size)] = double(n) * pred[bin(-n / 2, size)] + 0.5 * rest;
  for (int m = n / 2 + 1; m <= top; ++m) {
    out[bin(m, size)] = double(n) * pred[bin(m, size)];
    out[bin(-m, size)] = double(n) * pred[bin(-m, size)];
  }
}

// Its transpose: from zbar (ring r's bins) into cbar (its DFT's adjoint) and the adjoints of the
// rings beyond r (zbar at their bins), which are taken after r.
void ring_spectrum_transpose(const Cap& cap, std::size_t r, std::vector<cd>& zbar, std::vector<cd>& cbar) {
  const Ring& ring = cap.rings[r];
  const int n = ring.n, size = ring.size(), top = size / 2 - 1;
  const cd* in = zbar.data() + ring.offset;
  cbar.assign(static_cast<std::size_t>(n), cd(0.0));
  std::vector<cd> pbar(static_cast<std::size_t>(size), cd(0.0));
  const auto aliases = [&](int k, cd v) {
    for (int m = k - n * ((k + top) / n); m <= top; m += n)
      if (std::abs(m) >= n / 2) pbar[bin(m, size)] += v;
  };
  for (int k = -(n / 2 - 1); k < n / 2; ++k) {
    const cd o = in[bin(k, size)];
    cbar[bin(k, n)] += o;
    aliases(k, -double(n) * o);
  }
  const cd rest = 0.5 * (in[bin(n / 2, size)] + in[bin(-n / 2, size)]);
  cbar[n / 2] += rest;
  aliases(n / 2, -double(n) * rest);
  pbar[bin(n / 2, size)] += double(n) * in[bin(n / 2, size)];
  pbar[bin(-n / 2, size)] += double(n) * in[bin(-n / 2, size)];
  for (int m = n / 2 + 1; m <= top; ++m) {
    pbar[bin(m, size)] += double(n) * in[bin(m, size)];
    pbar[bin(-m, size)] += double(n) * in[bin(-m, size)];
  }
  if (!dealiased(r)) return;
  for (int m = -top; m <= top; ++m)
    if (std::abs(m) >= n / 2) {
      const cd v = pbar[bin(m, size)];
      if (v == cd(0.0)) continue;
      const Prediction p = prediction(cap, r, m);
      for (int q = 0; q < p.count; ++q) zbar[p.index[q]] += std::conj(p.kappa[q]) * v;
    }
}

// A copy pixel: the turn into the copy's frame and its stencil over the cap's values.
struct Stencil {
  cd rotation;  // Q' + i U' = rotation (Q_c + i U_c)
  int count = 0;
  std::array<std::size_t, kStencil> index{};
  std::array<double, kStencil> weight{};
};

// A copy pixel around a cap's pole: its colatitude t from the pole, its longitude, and the turn of
// Q + iU from the frame transported from the pole into the copy's frame.
struct CopyPoint {
  double t = 0.0, phi = 0.0;
  cd rotation;  // Q' + i U' = rotation (Q_c + i U_c)
};

CopyPoint copy_point(const Base& base, int s, int64 pixel) {
  const vec3 c = base.pix2vec(pixel);  // the copy's pixel centre; R^-1 (x', y', z') = (-z', y', x')
  const vec3 v(-c.z, c.y, c.x);
  CopyPoint out;
  const double t = std::atan2(std::hypot(v.x, v.y), s * v.z);  // colatitude from the cap's pole
  double phi = std::atan2(v.y, v.x);
  if (phi < 0.0) phi += 2.0 * pi;
  out.t = t;
  out.phi = phi;
  // The frame transported from the pole, f1 and f2, against the copy's e_theta' carried back by R^-1.
  const double theta = s > 0 ? t : pi - t;
  const double ct = std::cos(theta), st = std::sin(theta), cp = std::cos(phi), sp = std::sin(phi);
  const vec3 e_theta(ct * cp, ct * sp, -st), e_phi(-sp, cp, 0.0);
  const vec3 f1 = e_theta * cp - e_phi * (double(s) * sp), f2 = e_theta * (double(s) * sp) + e_phi * cp;
  const double ct2 = c.z, st2 = std::hypot(c.x, c.y);  // the copy's colatitude theta'
  const double cp2 = st2 > 0.0 ? c.x / st2 : 1.0, sp2 = st2 > 0.0 ? c.y / st2 : 0.0;
  const vec3 e_theta2(ct2 * cp2, ct2 * sp2, -st2);
  const vec3 b1(-e_theta2.z, e_theta2.y, e_theta2.x);
  out.rotation = std::polar(1.0, -2.0 * std::atan2(dotprod(b1, f2), dotprod(b1, f1)));
  return out;
}

Stencil stencil(const Cap& cap, const CopyPoint& point) {
  const double t = point.t, phi = point.phi;
  Stencil out;
  out.rotation = point.rotation;
  // Nodes in t along the great circle through the pole at phi: u < 0 ring |u| at phi + pi, u = 0 the
  // pole, u > 0 ring u at phi.
  // Lagrange weights by the barycentric formula on uniform nodes, lambda_j = (-1)^j C(n - 1, j).
  const double ts = polar_ring_coordinate(t, cap.nside), fl = std::floor(ts), x = ts - fl;
  const int lo = static_cast<int>(fl) - kHalfWidth + 1;
  std::array<double, 2 * kHalfWidth> wt{};
  if (x == 0.0) {
    wt[kHalfWidth - 1] = 1.0;
  } else {
    double sum = 0.0, binomial = 1.0;
    for (int k = 0; k < 2 * kHalfWidth; ++k) {
      wt[k] = (k % 2 ? -binomial : binomial) / (x - double(k - kHalfWidth + 1));
      sum += wt[k];
      binomial = binomial * double(2 * kHalfWidth - 1 - k) / double(k + 1);
    }
    for (double& w : wt) w /= sum;
  }
  std::array<double, kPhiPoints> ds{}, wp{};
  for (int d = 0; d < kPhiPoints; ++d) ds[d] = double(d - (kPhiPoints / 2 - 1));
  for (int k = 0; k < 2 * kHalfWidth; ++k) {
    const int u = lo + k;
    if (u == 0) {
      out.index[out.count] = cap.pole;
      out.weight[out.count++] = wt[k];
      continue;
    }
    const Ring& r = cap.rings[std::size_t(std::abs(u) - 1)];
    const int m = r.size();
    double x = ((u < 0 ? phi + pi : phi) - r.phi0) * double(m) / (2.0 * pi);
    x -= double(m) * std::floor(x / double(m));
    const double k0 = std::floor(x);
    lagrange(ds, kPhiPoints, x - k0, wp);
    const int first = static_cast<int>(k0) - (kPhiPoints / 2 - 1);
    for (int d = 0; d < kPhiPoints; ++d) {
      out.index[out.count] = r.offset + static_cast<std::size_t>(bin(first + d, m));
      out.weight[out.count++] = wt[k] * wp[d];
    }
  }
  return out;
}

// The copy's pixels of each cap: within reach of (sign, 0, 0).
std::vector<int64> targets(const Base& base, int sign, double reach) {
  rangeset<int64> set;
  base.query_disc(pointing(vec3(double(sign), 0.0, 0.0)), reach, set);
  std::vector<int64> out;
  out.reserve(static_cast<std::size_t>(set.nval()));
  for (tsize r = 0; r < set.nranges(); ++r)
    for (int64 p = set.ivbegin(r); p < set.ivend(r); ++p) out.push_back(p);
  return out;
}

void check_reach(int nside, double reach, const char* what) {
  if (!polar_copy_fits(nside, reach))
    throw Error(std::string(what) + ": the reach of the polar copy is " + std::to_string(reach) +
                " rad; expected more than 0, less than 88 deg and within the rings of NSIDE " + std::to_string(nside));
}

void make_plans(const Cap& cap, Plans& plans) {
  for (const Ring& r : cap.rings) {
    plans.make(r.n);
    plans.make(r.size());
  }
}
}  // namespace

bool polar_copy_fits(int nside, double reach) { return reach > 0.0 && reach < 88.0 * pi / 180.0 && rings_needed(nside, reach) > 0; }

std::array<std::size_t, 2> polar_band(int nside, double reach) {
  check_reach(nside, reach, "the polar copy's band");
  const Base base(nside, RING, SET_NSIDE);
  int64 lo = base.Npix(), hi = 0;
  for (const int sign : {1, -1}) {
    rangeset<int64> set;
    base.query_disc(pointing(vec3(double(sign), 0.0, 0.0)), reach, set);
    if (set.nranges() == 0) continue;
    lo = std::min(lo, set.ivbegin(0));
    hi = std::max(hi, set.ivend(set.nranges() - 1));
  }
  // Whole rings, then the first pixel down to a multiple of 64.
  int64 start = 0, n = 0;
  double theta = 0.0;
  bool shifted = false;
  base.get_ring_info2(base.pix2ring(lo), start, n, theta, shifted);
  const auto first = std::size_t(start) / 64 * 64;
  base.get_ring_info2(base.pix2ring(hi - 1), start, n, theta, shifted);
  return {first, std::size_t(start + n) - first};
}

SkyBand band_of(const SkyView& maps, std::size_t first, std::size_t count) {
  SkyBand band;
  band.nside = maps.nside();
  band.first = first;
  for (int c = 0; c < 4; ++c) {
    const std::span<const double> m = maps.stokes(StokesIndex(c));
    if (m.empty()) band.maps[std::size_t(c)].assign(count, 0.0);
    else band.maps[std::size_t(c)].assign(m.begin() + std::ptrdiff_t(first), m.begin() + std::ptrdiff_t(first + count));
  }
  return band;
}


PolarSource polar_source(const SkyView& sky, double reach) {
  check_reach(sky.nside(), reach, "the sky's polar copy");
  const Base base(sky.nside(), RING, SET_NSIDE);
  const int K = rings_needed(sky.nside(), reach);
  int64 start = 0, n = 0;
  double theta = 0.0;
  bool shifted = false;
  base.get_ring_info2(K, start, n, theta, shifted);
  const auto cap = std::size_t(start + n);  // the pixels of rings 1 to K
  PolarSource s;
  s.nside = sky.nside();
  s.reach = reach;
  for (const double x : sky.I()) s.mean += x;
  s.mean /= double(sky.npix());
  s.north = band_of(sky, 0, cap);
  s.south = band_of(sky, sky.npix() - cap, cap);
  return s;
}

SkyBand polar_sky(const SkyView& sky, bool weigh_boundaries, double reach, unsigned threads) {
  return polar_sky(polar_source(sky, reach), weigh_boundaries, threads);
}

namespace {
// Pixel j of the fit's ring r in the north (sign 1) or the south cap: the south's ring t mirrors the
// north's, from the sky's end.
std::size_t cap_pixel(const PolarFit::Ring& r, int j, int sign, std::size_t npix) {
  return sign > 0 ? r.start + std::size_t(j) : npix - r.start - std::size_t(r.n) + std::size_t(j);
}

// The fit's samples: each ring's pixels in both caps, I + iV and Q_c + iU_c (polar_fit.hpp), I less
// the sky's mean (added back to the copy's pixels: a monopole thousands of times the rest, as a CMB
// sky in K has, is then exact rather than fitted).
std::vector<cd> fit_samples(const PolarFit& fit, const PolarSource& source) {
  const std::size_t npix = 12 * std::size_t(source.nside) * std::size_t(source.nside);
  std::vector<cd> out(fit.sample_count() * PolarFit::kFields);
  for (const PolarFit::Ring& r : fit.rings())
    for (int j = 0; j < r.n; ++j) {
      const double phi = r.phi0 + 2.0 * pi * j / double(r.n);
      cd* x = out.data() + (r.offset + std::size_t(j)) * PolarFit::kFields;
      for (const int sign : {1, -1}) {
        const SkyBand& rings = sign > 0 ? source.north : source.south;
        const std::size_t p = cap_pixel(r, j, sign, npix);
        const int f = sign > 0 ? 0 : 2;
        x[f] = cd(rings.value(0, p) - source.mean, rings.value(3, p));
        x[f + 1] = to_pole_frame(sign, phi) * cd(rings.value(1, p), rings.value(2, p));
      }
    }
  return out;
}

// Their transpose, added into whole-sky maps; returns the sum of I's part, which the mean takes.
double add_fit_samples_transpose(const PolarFit& fit, const std::vector<cd>& samples, Sky& out) {
  const std::size_t npix = out.npix();
  double mean_part = 0.0;
  for (const PolarFit::Ring& r : fit.rings())
    for (int j = 0; j < r.n; ++j) {
      const double phi = r.phi0 + 2.0 * pi * j / double(r.n);
      const cd* x = samples.data() + (r.offset + std::size_t(j)) * PolarFit::kFields;
      for (const int sign : {1, -1}) {
        const std::size_t p = cap_pixel(r, j, sign, npix);
        const int f = sign > 0 ? 0 : 2;
        const cd qu = std::conj(to_pole_frame(sign, phi)) * x[f + 1];
        out.I()[p] += x[f].real();
        out.V()[p] += x[f].imag();
        out.Q()[p] += qu.real();
        out.U()[p] += qu.imag();
        mean_part += x[f].real();
      }
    }
  return mean_part;
}

// A cap's copy pixels within reach: those the fit gives (weight w > 0) and those the rings'
// interpolation gives (w < 1). Within the fit's zone w = 1; where the reach goes beyond it, w falls
// from 1 to 0 over the zone's last kBlendRings rings (a raised cosine in the colatitude), so that the
// copy passes from one reconstruction to the other without a step (the two differ at the pixel
// scale for power near 3 NSIDE, which a beam with a sharp edge would read at the seam).
constexpr int kBlendRings = 16;
struct Targets {
  std::vector<int64> near, far;
  std::vector<CopyPoint> near_points, far_points;
  std::vector<double> near_weights, far_weights;
};
Targets split_targets(const Base& base, int sign, double reach, const PolarFit& fit) {
  Targets out;
  const double zone = fit.zone();
  const auto& rings = fit.rings();
  const int zone_rings = static_cast<int>(rings.size()) - PolarFit::kMarginRings;
  const bool beyond = reach > zone;
  const double start = beyond ? rings[std::size_t(std::max(zone_rings - kBlendRings, 1) - 1)].theta : zone;
  for (const int64 pixel : targets(base, sign, reach)) {
    const CopyPoint point = copy_point(base, sign, pixel);
    const double w = point.t <= start ? 1.0 : point.t > zone ? 0.0 : 0.5 * (1.0 + std::cos(pi * (point.t - start) / (zone - start)));
    if (w > 0.0) {
      out.near.push_back(pixel);
      out.near_points.push_back(point);
      out.near_weights.push_back(w);
    }
    if (w < 1.0) {
      out.far.push_back(pixel);
      out.far_points.push_back(point);
      out.far_weights.push_back(1.0 - w);
    }
  }
  return out;
}

// Steps 1 to 4 of the rings' interpolation (for the copy's pixels beyond the fit's zone).
void interpolate_rings(const PolarSource& source, int sign, Cap& cap, Plans& plans, ThreadPool& pool) {
  make_plans(cap, plans);  // both caps' rings have the same lengths: planned once
  const std::size_t K = cap.rings.size();
  // 1. The rings' samples and DFTs.
  std::array<std::vector<std::vector<cd>>, 2> spectra{std::vector<std::vector<cd>>(K), std::vector<std::vector<cd>>(K)};
  pool.parallel_for(K, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const Ring& r = cap.rings[i];
      std::array<std::vector<cd>, 2> x{std::vector<cd>(std::size_t(r.n)), std::vector<cd>(std::size_t(r.n))};
      const SkyBand& rings = sign > 0 ? source.north : source.south;
      for (int j = 0; j < r.n; ++j) {
        const auto p = std::size_t(r.start + j);
        x[0][j] = cd(rings.value(0, p), rings.value(3, p));
        x[1][j] = to_pole_frame(sign, r.phi0 + 2.0 * pi * j / double(r.n)) * cd(rings.value(1, p), rings.value(2, p));
      }
      for (int f = 0; f < 2; ++f) {
        spectra[f][i].resize(std::size_t(r.n));
        plans.run(r.n, FFTW_FORWARD, x[f].data(), spectra[f][i].data());
      }
    }
  });
  // 2. Their upsampled spectra, from the outermost ring in.
  for (std::size_t i = K; i-- > 0;)
    for (int f = 0; f < 2; ++f) ring_spectrum(cap, i, spectra[f][i], cap.values[f]);
  // 3. Their upsampled values.
  pool.parallel_for(K, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const Ring& r = cap.rings[i];
      std::vector<cd> t(static_cast<std::size_t>(r.size()));
      for (auto& values : cap.values) {
        cd* v = values.data() + r.offset;
        plans.run(r.size(), FFTW_BACKWARD, v, t.data());
        for (int k = 0; k < r.size(); ++k) v[k] = t[k] / double(r.n);
      }
    }
  });
  // 4. The pole's value from the rings' means.
  const std::vector<double>& c = pole_weights();
  for (auto& values : cap.values) {
    cd pole(0.0);
    for (int q = 0; q < kPoleRings; ++q) {
      const Ring& r = cap.rings[std::size_t(q)];
      cd mean_q(0.0);
      for (int k = 0; k < r.size(); ++k) mean_q += values[r.offset + k];
      pole += c[q] * mean_q / double(r.size());
    }
    values[cap.pole] = pole;
  }
}

// The transpose of steps 4 to 1, from the cap's values into whole-sky maps.
void interpolate_rings_transpose(int sign, Cap& cap, Plans& plans, Sky& out) {
  make_plans(cap, plans);
  const std::size_t K = cap.rings.size();
  // 4. The pole's value onto the rings' values.
  const std::vector<double>& c = pole_weights();
  for (auto& values : cap.values) {
    const cd pole = values[cap.pole];
    for (int q = 0; q < kPoleRings; ++q) {
      const Ring& r = cap.rings[std::size_t(q)];
      for (int k = 0; k < r.size(); ++k) values[r.offset + k] += c[q] * pole / double(r.size());
    }
  }
  // 3. The inverse transform's transpose: (1/n) times the forward transform.
  for (const Ring& r : cap.rings) {
    std::vector<cd> t(static_cast<std::size_t>(r.size()));
    for (auto& values : cap.values) {
      cd* v = values.data() + r.offset;
      plans.run(r.size(), FFTW_FORWARD, v, t.data());
      for (int k = 0; k < r.size(); ++k) v[k] = t[k] / double(r.n);
    }
  }
  // 2. and 1. From the innermost ring out: the spectra's transposes, the DFTs' (the backward
  // transform), and the samples'.
  for (std::size_t i = 0; i < K; ++i) {
    const Ring& r = cap.rings[i];
    std::array<std::vector<cd>, 2> x;
    for (int f = 0; f < 2; ++f) {
      std::vector<cd> cbar;
      ring_spectrum_transpose(cap, i, cap.values[f], cbar);
      x[f].resize(std::size_t(r.n));
      plans.run(r.n, FFTW_BACKWARD, cbar.data(), x[f].data());
    }
    for (int j = 0; j < r.n; ++j) {
      const auto p = static_cast<std::size_t>(r.start + j);
      const cd qu = std::conj(to_pole_frame(sign, r.phi0 + 2.0 * pi * j / double(r.n))) * x[1][j];
      out.I()[p] += x[0][j].real();
      out.V()[p] += x[0][j].imag();
      out.Q()[p] += qu.real();
      out.U()[p] += qu.imag();
    }
  }
}

// A copy pixel's value, or its part added to what the fit gave it (`add`).
void write_copy_pixel(SkyBand& out, int64 pixel, const cd& a, const cd& qu, bool add) {
  const std::size_t p = static_cast<std::size_t>(pixel) - out.first;
  const double k = add ? 1.0 : 0.0;
  out.maps[0][p] = k * out.maps[0][p] + a.real();
  out.maps[3][p] = k * out.maps[3][p] + a.imag();
  out.maps[1][p] = k * out.maps[1][p] + qu.real();
  out.maps[2][p] = k * out.maps[2][p] + qu.imag();
}
}  // namespace

SkyBand polar_sky(const PolarSource& source, bool weigh_boundaries, unsigned threads) {
  const double reach = source.reach;
  check_reach(source.nside, reach, "the sky's polar copy");
  const Base base(source.nside, RING, SET_NSIDE);
  const auto band = polar_band(source.nside, reach);
  SkyBand out;
  out.nside = source.nside;
  out.first = band[0];
  const double mean = source.mean;
  for (int c = 0; c < 4; ++c) out.maps[std::size_t(c)].assign(band[1], c == 0 ? mean : 0.0);

  ThreadPool pool(threads ? threads : std::max(1u, std::thread::hardware_concurrency()));
  // The fit around both poles, for the copy's pixels within its zone.
  const std::shared_ptr<const PolarFit> fitted = polar_fit_for(source.nside, reach, pool);
  const PolarFit& fit = *fitted;
  const PolarFit::Modes modes = fit.fit(fit_samples(fit, source), pool);
  Plans plans;
  for (const int sign : {1, -1}) {
    const Targets targets = split_targets(base, sign, reach, fit);
    const int f = sign > 0 ? 0 : 2;
    pool.parallel_for(targets.near.size(), 64, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        const CopyPoint& point = targets.near_points[i];
        const PolarFit::Values v = fit.value(modes, point.t, point.phi);
        const double w = targets.near_weights[i];
        write_copy_pixel(out, targets.near[i], w * (v[std::size_t(f)] + mean), w * (point.rotation * v[std::size_t(f + 1)]), false);
      }
    });
    if (targets.far.empty()) continue;
    // Beyond the zone: the rings interpolated (steps 1 to 4) and each pixel's stencil (step 5).
    Cap cap = make_cap(base, sign, reach);
    interpolate_rings(source, sign, cap, plans, pool);
    pool.parallel_for(targets.far.size(), 256, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        const Stencil st = stencil(cap, targets.far_points[i]);
        cd a(0.0), b(0.0);
        for (int k = 0; k < st.count; ++k) {
          a += st.weight[k] * cap.values[0][st.index[k]];
          b += st.weight[k] * cap.values[1][st.index[k]];
        }
        const double w = targets.far_weights[i];
        write_copy_pixel(out, targets.far[i], w * a, w * (st.rotation * b), w < 1.0);
      }
    });
  }
  if (weigh_boundaries) weigh_cap_boundaries(out.nside, out.first, {out.maps[0], out.maps[1], out.maps[2], out.maps[3]});
  return out;
}

Sky polar_sky_adjoint(const SkyBand& maps, bool weigh_boundaries, double reach, unsigned threads) {
  check_reach(maps.nside, reach, "the adjoint of the sky's polar copy");
  const auto band = polar_band(maps.nside, reach);
  const std::size_t first = band[0], count = band[1];  // not a structured binding: the lambda below takes first
  if (maps.first != first || maps.size() != count)
    throw Error("the adjoint of the sky's polar copy: a band of pixels " + std::to_string(maps.first) + " to " +
                std::to_string(maps.first + maps.size()) + "; expected " + std::to_string(first) + " to " +
                std::to_string(first + count));
  const Base base(maps.nside, RING, SET_NSIDE);
  SkyBand in = maps;
  if (weigh_boundaries) weigh_cap_boundaries(in.nside, in.first, {in.maps[0], in.maps[1], in.maps[2], in.maps[3]});
  Sky out(maps.nside);
  ThreadPool pool(threads ? threads : std::max(1u, std::thread::hardware_concurrency()));
  const std::shared_ptr<const PolarFit> fitted = polar_fit_for(maps.nside, reach, pool);
  const PolarFit& fit = *fitted;
  PolarFit::Modes bar = fit.zero_modes();
  // The mean-I fill of the band's pixels outside the caps, the mean in the fitted pixels, less the mean
  // taken from the fit's samples: each pixel's I gets their sum / Npix.
  double rest = 0.0;
  for (const double x : in.maps[0]) rest += x;
  Plans plans;
  for (const int sign : {1, -1}) {
    const Targets targets = split_targets(base, sign, reach, fit);
    const int f = sign > 0 ? 0 : 2;
    const auto at = [&](int64 pixel) { return static_cast<std::size_t>(pixel) - first; };
    for (std::size_t i = 0; i < targets.near.size(); ++i) {
      const std::size_t p = at(targets.near[i]);  // w of its I is the mean's: that part stays in `rest`
      const double w = targets.near_weights[i];
      rest -= (1.0 - w) * in.maps[0][p];
      PolarFit::Values v{};
      v[std::size_t(f)] = w * cd(in.maps[0][p], in.maps[3][p]);
      v[std::size_t(f + 1)] = w * (std::conj(targets.near_points[i].rotation) * cd(in.maps[1][p], in.maps[2][p]));
      fit.add_value_transpose(bar, targets.near_points[i].t, targets.near_points[i].phi, v);
    }
    if (targets.far.empty()) continue;
    Cap cap = make_cap(base, sign, reach);
    // 5. The copy's pixels onto the stencils.
    for (std::size_t i = 0; i < targets.far.size(); ++i) {
      const std::size_t p = at(targets.far[i]);
      const double w = targets.far_weights[i];
      if (w == 1.0) rest -= in.maps[0][p];  // (a blended pixel's was taken above)
      const Stencil st = stencil(cap, targets.far_points[i]);
      const cd a = w * cd(in.maps[0][p], in.maps[3][p]);
      const cd b = w * (std::conj(st.rotation) * cd(in.maps[1][p], in.maps[2][p]));
      for (int k = 0; k < st.count; ++k) {
        cap.values[0][st.index[k]] += st.weight[k] * a;
        cap.values[1][st.index[k]] += st.weight[k] * b;
      }
    }
    interpolate_rings_transpose(sign, cap, plans, out);
  }
  rest -= add_fit_samples_transpose(fit, fit.fit_transpose(bar, pool), out);
  const double fill = rest / double(out.npix());
  for (double& x : out.I()) x += fill;
  return out;
}

}  // namespace pisco::detail
