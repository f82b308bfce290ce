#include "pisco/mapmaker.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

#include <healpix_base.h>
#include <pointing.h>
#include <vec3.h>

#include "kernel/frame.hpp"
#include "core/thread_pool.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace {

using Base = T_Healpix_Base<int64>;
using Sym3 = std::array<double, 6>;  // upper triangle, row by row: 00 01 02 11 12 22
using Vec3 = std::array<double, 3>;

// Symmetric 3x3 as a full matrix, for the eigenvalue iteration.
using Mat3 = std::array<std::array<double, 3>, 3>;

Mat3 full(const Sym3& s) {
  return {{{s[0], s[1], s[2]}, {s[1], s[3], s[4]}, {s[2], s[4], s[5]}}};
}

// Eigenvalues of a symmetric 3x3 by cyclic Jacobi rotations. Unlike the closed (trigonometric) form,
// Jacobi keeps small eigenvalues accurate relative to the large ones, which is what the
// condition-number cut needs to tell a rank-deficient pixel from a merely poor one.
Vec3 eigenvalues(const Sym3& s) {
  Mat3 a = full(s);
  for (int sweep = 0; sweep < 50; ++sweep) {
    const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    if (off <= 1e-34 * diag || off == 0.0) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0.0) continue;
        // Rotation angle that zeroes a[p][q] (Numerical Recipes' stable form).
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0.0 ? 1.0 : -1.0) /
                         (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0);
        const double sn = t * c;
        for (int k = 0; k < 3; ++k) {  // columns p, q
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - sn * akq;
          a[k][q] = sn * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {  // rows p, q
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - sn * aqk;
          a[q][k] = sn * apk + c * aqk;
        }
      }
  }
  return {a[0][0], a[1][1], a[2][2]};
}

// Smallest over largest eigenvalue; 0 for a zero or (by rounding) indefinite matrix.
double reciprocal_condition(const Sym3& s) {
  const Vec3 ev = eigenvalues(s);
  const double lo = std::min({ev[0], ev[1], ev[2]});
  const double hi = std::max({ev[0], ev[1], ev[2]});
  if (!(hi > 0.0) || lo <= 0.0) return 0.0;
  return lo / hi;
}

// Solves s x = b by Cholesky; s is positive definite here (the condition cut came first).
Vec3 cholesky_solve(const Sym3& s, const Vec3& b) {
  const double l00 = std::sqrt(s[0]);
  const double l10 = s[1] / l00;
  const double l20 = s[2] / l00;
  const double l11 = std::sqrt(s[3] - l10 * l10);
  const double l21 = (s[4] - l20 * l10) / l11;
  const double l22 = std::sqrt(s[5] - l20 * l20 - l21 * l21);
  // Forward substitution L y = b, then back substitution L^T x = y.
  const double y0 = b[0] / l00;
  const double y1 = (b[1] - l10 * y0) / l11;
  const double y2 = (b[2] - l20 * y0 - l21 * y1) / l22;
  const double x2 = y2 / l22;
  const double x1 = (y1 - l21 * x2) / l11;
  const double x0 = (y0 - l10 * x1 - l20 * x2) / l00;
  return {x0, x1, x2};
}

// stokes_weights from cos 2 gamma and sin 2 gamma.
std::array<double, 3> weights_of_angle(const Detector& detector, double c2, double s2, double hwp_angle) {
  const double co = 0.5 * detector.gain * (1.0 + detector.epsilon);
  const double pol = 0.5 * detector.gain * (1.0 - detector.epsilon);
  if (!detector.hwp) return {co, pol * c2, pol * s2};
  // r = D(0) M(theta) R(gamma), D(0) = (co, pol, 0, 0): the plate-modulated response to I, Q, U.
  const Mueller m = rotated_mueller(detector.hwp->mueller, hwp_angle - detector.hwp->gamma);
  double dm[4];
  for (int b = 0; b < 4; ++b) dm[b] = co * m[0][b] + pol * m[1][b];
  return {dm[0], dm[1] * c2 - dm[2] * s2, dm[1] * s2 + dm[2] * c2};
}
}  // namespace

std::array<double, 3> stokes_weights(const Detector& detector, double psi, double hwp_angle) {
  const double gamma = psi + detector.zeta;
  return weights_of_angle(detector, std::cos(2.0 * gamma), std::sin(2.0 * gamma), hwp_angle);
}

BinnedMapmaker::BinnedMapmaker(int nside, double rcond_min) : nside_(nside), rcond_min_(rcond_min) {
  check_nside(nside, "BinnedMapmaker");
  if (!std::isfinite(rcond_min) || rcond_min < 0.0 || rcond_min > 1.0)
    throw Error("BinnedMapmaker: rcond_min = " + std::to_string(rcond_min) +
                " must be in [0, 1]");
  const std::size_t npix = 12 * std::size_t(nside) * std::size_t(nside);
  ata_.assign(6 * npix, 0.0);
  atd_.assign(3 * npix, 0.0);
  hits_.assign(npix, 0);
}

namespace {
// add()'s and add_from_boresight()'s checks, before anything is accumulated.
template <class View>
void check_chunk(const char* what, const Detector& detector, const View& pointing, std::span<const double> tod,
                 std::span<const double> hwp_angle, std::span<const std::uint8_t> flags) {
  const std::size_t n = pointing.size();
  const std::string op = std::string("BinnedMapmaker::") + what;
  if (tod.size() != n)
    throw Error(op + ": detector '" + detector.name + "': " + std::to_string(tod.size()) + " TOD samples for " +
                std::to_string(n) + " pointing samples");
  if (!std::isfinite(detector.zeta) || !std::isfinite(detector.epsilon) || !std::isfinite(detector.gain))
    throw Error(op + ": detector '" + detector.name + "' has a non-finite zeta, epsilon or gain");
  check_pointing(pointing, op.c_str());
  for (std::size_t i = 0; i < tod.size(); ++i)
    if (!std::isfinite(tod[i]))
      throw Error(op + ": detector '" + detector.name + "': TOD sample " + std::to_string(i) + " is not finite");
  if (!flags.empty() && flags.size() != tod.size())
    throw Error(op + ": detector '" + detector.name + "': " + std::to_string(flags.size()) + " flags for " +
                std::to_string(tod.size()) + " TOD samples (expected one per sample, or none)");
  if (detector.hwp) {
    if (hwp_angle.size() != tod.size())
      throw Error(op + ": detector '" + detector.name + "' has a half-wave plate: expected " +
                  std::to_string(tod.size()) + " plate angles, got " + std::to_string(hwp_angle.size()));
    for (std::size_t i = 0; i < hwp_angle.size(); ++i)
      if (!std::isfinite(hwp_angle[i]))
        throw Error(op + ": detector '" + detector.name + "': plate angle of sample " + std::to_string(i) +
                    " is not finite");
  } else if (!hwp_angle.empty()) {
    throw Error(op + ": detector '" + detector.name + "' has no half-wave plate, but plate angles were given");
  }
}

// cos 2 psi and sin 2 psi of the detector whose rotation is r (theta' = r.ex, line of sight r.ez):
// psi is the angle of theta' from the meridian theta^ towards phi^ at the line of sight p, whose
// components along theta^ and phi^ times sin(theta) are a = p_z (theta'_x p_x + theta'_y p_y) -
// theta'_z (p_x^2 + p_y^2) and b = theta'_y p_x - theta'_x p_y. Exactly at a pole (a = b = 0), where the
// meridian is HEALPix's phi = 0 one, through the angles.
void double_angle(const detail::Rotation& r, double& c2, double& s2) {
  const detail::Vec3<double>& p = r.ez;
  const detail::Vec3<double>& t = r.ex;
  const double a = p.z * (t.x * p.x + t.y * p.y) - t.z * (p.x * p.x + p.y * p.y);
  const double b = t.y * p.x - t.x * p.y;
  const double n = a * a + b * b;
  if (n > 0.0) {
    c2 = (a * a - b * b) / n;
    s2 = 2.0 * a * b / n;
    return;
  }
  double theta = 0.0, phi = 0.0;
  detail::direction_angles(p, theta, phi);
  const double psi = detail::position_angle(t, theta, phi);
  c2 = std::cos(2.0 * psi);
  s2 = std::sin(2.0 * psi);
}
}  // namespace

void BinnedMapmaker::add(const Detector& detector, const PointingView& ptg,
                         std::span<const double> tod, std::span<const double> hwp_angle,
                         std::span<const std::uint8_t> flags) {
  // Everything is checked before anything is accumulated, so a bad chunk leaves the maps intact.
  check_chunk("add", detector, ptg, tod, hwp_angle, flags);
  const Base base(int64(nside_), RING, SET_NSIDE);
  bin(tod, [&](std::size_t i, std::size_t& pixel, std::array<double, 3>& weights) {
    if (!flags.empty() && flags[i] != 0) return false;
    pixel = std::size_t(base.ang2pix(pointing(ptg.theta[i], ptg.phi[i])));
    weights = stokes_weights(detector, ptg.psi[i], detector.hwp ? hwp_angle[i] : 0.0);
    return true;
  });
}

void BinnedMapmaker::add_from_boresight(const Detector& detector, const QuatPointingView& boresight,
                                        std::span<const double> tod, std::span<const double> hwp_angle,
                                        std::span<const std::uint8_t> flags) {
  check_chunk("add_from_boresight", detector, boresight, tod, hwp_angle, flags);
  const Base base(int64(nside_), RING, SET_NSIDE);
  const Quat& o = detector.offset;
  const detail::DetectorOffset offset = detail::make_offset({o.x, o.y, o.z, o.w});
  const double c2z = std::cos(2.0 * detector.zeta), s2z = std::sin(2.0 * detector.zeta);
  bin(tod, [&](std::size_t i, std::size_t& pixel, std::array<double, 3>& weights) {
    if (!flags.empty() && flags[i] != 0) return false;
    const Quat& q = boresight.quats[i];
    const detail::Q4 b{q.x, q.y, q.z, q.w};
    const detail::Rotation r = detail::rotation_matrix(offset.active ? detail::quat_mul(b, offset.quat) : b);
    pixel = std::size_t(base.vec2pix(vec3(r.ez.x, r.ez.y, r.ez.z)));  // HEALPix normalizes it
    double c2 = 0.0, s2 = 0.0;
    double_angle(r, c2, s2);
    // 2 gamma = 2 psi + 2 zeta
    weights = weights_of_angle(detector, c2 * c2z - s2 * s2z, s2 * c2z + c2 * s2z, detector.hwp ? hwp_angle[i] : 0.0);
    return true;
  });
}

template <class Sample>
void BinnedMapmaker::bin(std::span<const double> tod, const Sample& sample) {
  const std::size_t n = tod.size();
  const auto accumulate = [&](std::size_t pix, const std::array<double, 3>& a, double d) {
    double* m = &ata_[6 * pix];
    m[0] += a[0] * a[0];
    m[1] += a[0] * a[1];
    m[2] += a[0] * a[2];
    m[3] += a[1] * a[1];
    m[4] += a[1] * a[2];
    m[5] += a[2] * a[2];
    double* v = &atd_[3 * pix];
    for (int k = 0; k < 3; ++k) v[k] += a[k] * d;
    ++hits_[pix];
  };
  constexpr std::size_t block = 4096;
  if (threads_ == 1 || n < 2 * block) {
    std::size_t pix = 0;
    std::array<double, 3> a{};
    for (std::size_t i = 0; i < n; ++i)
      if (sample(i, pix, a)) accumulate(pix, a, tod[i]);
    return;
  }
  // On several threads: each sample's pixel and weights (the costly part: the pixel, the cosine and
  // sine of 2 gamma), then the sums, each thread adding the samples of the pixels it owns (blocks of
  // 64 pixels dealt round the threads) in the order given, so that every pixel's sums are the same
  // bits as on one thread.
  if (!pool_) pool_ = std::make_unique<detail::ThreadPool>(threads_);
  constexpr std::size_t left_out = std::numeric_limits<std::size_t>::max();
  pixel_scratch_.resize(n);
  weight_scratch_.resize(n);
  pool_->parallel_for(n, block, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      if (!sample(i, pixel_scratch_[i], weight_scratch_[i])) pixel_scratch_[i] = left_out;
  });
  const std::size_t parts = pool_->size();
  pool_->parallel_for(parts, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t part = begin; part < end; ++part)
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t pix = pixel_scratch_[i];
        if (pix != left_out && (pix >> 6) % parts == part) accumulate(pix, weight_scratch_[i], tod[i]);
      }
  });
}

BinnedMapmaker::~BinnedMapmaker() = default;
BinnedMapmaker::BinnedMapmaker(BinnedMapmaker&&) noexcept = default;
BinnedMapmaker& BinnedMapmaker::operator=(BinnedMapmaker&&) noexcept = default;

BinnedMapmaker::BinnedMapmaker(const BinnedMapmaker& other)
    : nside_(other.nside_), rcond_min_(other.rcond_min_), threads_(other.threads_), ata_(other.ata_),
      atd_(other.atd_), hits_(other.hits_) {}

BinnedMapmaker& BinnedMapmaker::operator=(const BinnedMapmaker& other) {
  if (this != &other) *this = BinnedMapmaker(other);
  return *this;
}

void BinnedMapmaker::set_threads(unsigned threads) {
  if (threads > Engine::max_threads())
    throw Error("BinnedMapmaker: threads = " + std::to_string(threads) + "; expected 0 (all hardware threads) up to " +
                std::to_string(Engine::max_threads()));
  const unsigned n = threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : threads;
  if (n != threads_) pool_.reset();
  threads_ = n;
}

void BinnedMapmaker::add_normal_equations(std::span<const double> matrices, std::span<const double> vectors,
                                          std::span<const std::uint32_t> hits) {
  if (matrices.size() != ata_.size() || vectors.size() != atd_.size() || hits.size() != hits_.size())
    throw Error("BinnedMapmaker::add_normal_equations: " + std::to_string(matrices.size()) + ", " +
                std::to_string(vectors.size()) + " and " + std::to_string(hits.size()) +
                " values for the NSIDE " + std::to_string(nside_) + " map-maker (expected " +
                std::to_string(ata_.size()) + ", " + std::to_string(atd_.size()) + " and " +
                std::to_string(hits_.size()) + ")");
  for (std::size_t i = 0; i < ata_.size(); ++i) ata_[i] += matrices[i];
  for (std::size_t i = 0; i < atd_.size(); ++i) atd_[i] += vectors[i];
  for (std::size_t i = 0; i < hits_.size(); ++i) hits_[i] += hits[i];
}

BinnedMaps BinnedMapmaker::solve() const {
  const std::size_t npix = hits_.size();
  BinnedMaps out;
  out.nside = nside_;
  out.I.assign(npix, unseen);
  out.Q.assign(npix, unseen);
  out.U.assign(npix, unseen);
  out.hits = hits_;
  out.rcond.assign(npix, 0.0);
  for (std::size_t p = 0; p < npix; ++p) {
    if (hits_[p] == 0) continue;
    Sym3 m;
    std::copy_n(&ata_[6 * p], 6, m.begin());
    const double rc = reciprocal_condition(m);
    out.rcond[p] = rc;
    // A pixel seen at a single polarization angle (or two orthogonal ones) has a singular
    // matrix: its Q/U cannot be separated, and the cut leaves it UNSEEN.
    if (rc < rcond_min_ || rc == 0.0) continue;
    const Vec3 x = cholesky_solve(m, {atd_[3 * p], atd_[3 * p + 1], atd_[3 * p + 2]});
    // With a very permissive rcond_min, rounding can still defeat the factorization.
    if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2])) continue;
    out.I[p] = x[0];
    out.Q[p] = x[1];
    out.U[p] = x[2];
  }
  return out;
}

}  // namespace pisco
