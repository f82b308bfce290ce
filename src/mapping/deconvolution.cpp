// The beam-deconvolving map-maker (docs/physics.md, "Map-making with the beams").
#include "pisco/deconvolution.hpp"

#include <healpix_base.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "core/sky_alm.hpp"
#include "core/text.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/spectra.hpp"

namespace pisco {
namespace {

double dot(const Sky& a, const Sky& b) {
  double s = 0.0;
  for (int c = 0; c < 4; ++c) {
    const auto x = a.stokes(StokesIndex(c)), y = b.stokes(StokesIndex(c));
    for (std::size_t p = 0; p < x.size(); ++p) s += x[p] * y[p];
  }
  return s;
}

// y += a x
void axpy(Sky& y, double a, const Sky& x) {
  for (int c = 0; c < 4; ++c) {
    const auto xs = x.stokes(StokesIndex(c));
    const auto ys = y.stokes(StokesIndex(c));
    for (std::size_t p = 0; p < xs.size(); ++p) ys[p] += a * xs[p];
  }
}

StokesMaps maps_of(Sky& s) { return {s.I(), s.Q(), s.U(), s.V()}; }

void normal_chunk(Engine& engine, const SurveyChunk& c) {
  if (c.quaternions) engine.normal(c.detector, c.quats, c.hwp_angle, c.time);
  else engine.normal(c.detector, c.angles, c.hwp_angle, c.time);
}

void adjoint_chunk(Engine& engine, const SurveyChunk& c, std::span<const double> tod) {
  if (c.quaternions) engine.adjoint(c.detector, c.quats, tod, c.hwp_angle, c.time);
  else engine.adjoint(c.detector, c.angles, tod, c.hwp_angle, c.time);
}

void diagonal_chunk(Engine& engine, const SurveyChunk& c) {
  if (c.quaternions) engine.adjoint_diagonal(c.detector, c.quats, c.hwp_angle, c.time);
  else engine.adjoint_diagonal(c.detector, c.angles, c.hwp_angle, c.time);
}
}  // namespace

DeconvolvingMapmaker::DeconvolvingMapmaker(Engine& engine, const DeconvolutionOptions& options)
    : engine_(engine), options_(options) {
  if (options.max_iterations < 1)
    throw Error("deconvolution: max_iterations = " + std::to_string(options.max_iterations) + "; expected at least 1");
  if (!(options.tolerance > 0.0 && options.tolerance < 1.0))
    throw Error("deconvolution: tolerance = " + std::to_string(options.tolerance) + "; expected a number in (0, 1)");
  if (!(options.regularization >= 0.0 && std::isfinite(options.regularization)))
    throw Error("deconvolution: regularization = " + std::to_string(options.regularization) +
                "; expected a finite number >= 0");
  if (!(options.rcond_min >= 0.0 && options.rcond_min < 1.0))
    throw Error("deconvolution: rcond_min = " + detail::number_text(options.rcond_min) +
                "; expected a number in [0, 1) (a reciprocal condition number)");
  if (options.coverage_nside < 0 || options.coverage_nside > max_nside ||
      (options.coverage_nside & (options.coverage_nside - 1)) != 0)
    throw Error("deconvolution: coverage_nside = " + std::to_string(options.coverage_nside) +
                "; expected 0 (the engine's NSIDE / 4) or a power of two up to " + std::to_string(max_nside));
  if (!(options.target_fwhm >= 0.0 && options.target_fwhm < 3.14159265358979323846))
    throw Error("deconvolution: target_fwhm = " + std::to_string(options.target_fwhm) +
                " rad; expected 0 (none) or an angle below pi");
}

void DeconvolvingMapmaker::add(const SurveyChunk& chunk, std::span<const double> tod) {
  adjoint_chunk(engine_, chunk, tod);
  any_ = true;
}

namespace {

// The engine's adjoint maps into `out`, summed over the processes by `reduce` when it is given.
class Taker {
 public:
  Taker(Engine& engine, const std::function<void(std::span<double>)>& reduce) : engine_(engine), reduce_(reduce) {}
  void operator()(Sky& out) {
    engine_.take_adjoint(maps_of(out));
    if (!reduce_) return;
    const std::size_t n = out.npix();
    buffer_.resize(4 * n);
    for (int k = 0; k < 4; ++k) std::copy_n(out.stokes(StokesIndex(k)).begin(), n, buffer_.begin() + std::ptrdiff_t(k * n));
    reduce_(buffer_);
    for (int k = 0; k < 4; ++k) std::copy_n(buffer_.begin() + std::ptrdiff_t(k * n), n, out.stokes(StokesIndex(k)).begin());
  }

 private:
  Engine& engine_;
  const std::function<void(std::span<double>)>& reduce_;
  std::vector<double> buffer_;
};

// The Jacobi preconditioner: the diagonal of A^T A (Engine::adjoint_diagonal), one more pass; and,
// in the same pass, the polarization angles the scan gives each region of the sky (the detectors'
// (I, Q, U) weights binned at the coverage NSIDE, as the binned map-maker bins them).
BinnedMaps diagonal_and_angles(Engine& engine, const DeconvolvingMapmaker::Survey& survey, const DeconvolutionOptions& options,
                               int coverage_nside, Taker& take, Sky& diagonal) {
  BinnedMapmaker coverage(coverage_nside, options.rcond_min);
  {
    const FocalPlane& fp = engine.focal_plane();
    std::vector<double> zeros;
    survey([&](const SurveyChunk& c) {
      diagonal_chunk(engine, c);
      zeros.assign(c.size(), 0.0);
      const Detector& d = fp.detectors().at(c.detector);
      if (c.quaternions) coverage.add_from_boresight(d, c.quats, zeros, c.hwp_angle);
      else coverage.add(d, c.angles, zeros, c.hwp_angle);
    });
  }
  take(diagonal);
  if (options.reduce) {  // the coverage of every process's chunks
    const auto ata = coverage.normal_matrices();
    std::vector<double> sum(ata.begin(), ata.end());
    sum.resize(ata.size() + coverage.hits().size());
    std::copy(coverage.hits().begin(), coverage.hits().end(), sum.begin() + std::ptrdiff_t(ata.size()));
    options.reduce(sum);
    BinnedMapmaker all(coverage_nside, options.rcond_min);
    std::vector<std::uint32_t> hits(coverage.hits().size());
    for (std::size_t i = 0; i < hits.size(); ++i)
      hits[i] = static_cast<std::uint32_t>(std::min(sum[ata.size() + i], 4e9));
    all.add_normal_equations(std::span<const double>(sum.data(), ata.size()),
                             std::vector<double>(coverage.normal_vectors().size(), 0.0), hits);
    coverage = std::move(all);
  }
  return coverage.solve();
}

// What is solved and what the maps show.
struct Solved {
  std::array<bool, 4> solve{};      // Stokes parameter k solved at all
  std::vector<std::uint8_t> polarized;  // pixel i's Q and U (and V) shown
  std::vector<bool> seen;           // pixel i shown
  double floor[4] = {0, 0, 0, 0};   // the preconditioner's least divisor, per Stokes parameter
};

// 0.1 of the median of the positive values of d (0 when none is).
double tenth_of_median(std::span<const double> d) {
  std::vector<double> values;
  for (double v : d)
    if (v > 0.0) values.push_back(v);
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
  return 0.1 * values[values.size() / 2];
}

// What is solved: solve[k][i], Stokes parameter k of pixel i. A pixel no sample's disc reaches has a
// zero diagonal and stays zero, as conjugate gradients from zero leave it.
// - A Stokes parameter the beams do not respond to (a diagonal below 1e-12 of I's: the V of a beam
//   whose circular response is rounding, not zero) is left out everywhere: dividing by its diagonal
//   would multiply rounding by 1e16.
// - Q and U (and V) are left out everywhere when the scan's angles constrain them in no coverage
//   pixel (a 3x3 matrix with reciprocal condition number below rcond_min everywhere, as the binned
//   map-maker cuts: one angle): the solver would fill them with amplified noise. Where only some
//   pixels' angles fail (the edges of a scan) they are solved, for the data's sake, and marked
//   unseen in the maps.
// What was left out is told in out.left_out.
Solved what_to_solve(const Sky& diagonal, const BinnedMaps& angles, const DeconvolutionOptions& options, int nside,
                     int coverage_nside, DeconvolvedMaps& out) {
  const std::size_t npix = diagonal.npix();
  Solved v;
  std::array<double, 4> mean{};
  for (int k = 0; k < 4; ++k) {
    double sum = 0;
    std::size_t n = 0;
    for (double d : diagonal.stokes(StokesIndex(k)))
      if (d > 0.0) sum += d, ++n;
    mean[std::size_t(k)] = n ? sum / double(n) : 0.0;
  }
  std::array<bool, 4> responds{};
  for (int k = 0; k < 4; ++k) responds[std::size_t(k)] = k == 0 ? mean[0] > 0.0 : mean[std::size_t(k)] > 1e-12 * mean[0];
  const bool any_polarization = responds[1] || responds[2] || responds[3];
  std::vector<std::uint8_t>& polarized = v.polarized;
  polarized.assign(npix, 0);
  {
    T_Healpix_Base<int> sky_base(nside, RING, SET_NSIDE), coverage_base(coverage_nside, RING, SET_NSIDE);
    for (std::size_t i = 0; i < npix; ++i) {
      const int c = coverage_base.ang2pix(sky_base.pix2ang(int(i)));
      polarized[i] = angles.rcond[std::size_t(c)] >= options.rcond_min;
    }
  }
  std::size_t reached = 0, polarization_poor = 0;
  for (std::size_t i = 0; i < npix; ++i)
    if (diagonal.I()[i] > 0.0) {
      ++reached;
      if (polarized[i]) ++out.polarization_pixels;
      else ++polarization_poor;
    }
  out.polarization_unconstrained = any_polarization && reached > 0 && out.polarization_pixels == 0;
  std::array<bool, 4>& solve = v.solve;
  for (int k = 0; k < 4; ++k) solve[std::size_t(k)] = responds[std::size_t(k)] && (k == 0 || !out.polarization_unconstrained);
  const char* names[4] = {"I", "Q", "U", "V"};
  for (int k = 1; k < 4; ++k)
    if (!responds[std::size_t(k)] && mean[std::size_t(k)] > 0.0)
      out.left_out.push_back(std::string(names[k]) + " everywhere: the beams' response to it is " +
                             detail::number_text(std::sqrt(mean[std::size_t(k)] / mean[0]), 2) +
                             " of their response to I (rounding, not a response); it is written as 0");
  if (out.polarization_unconstrained)
    out.left_out.push_back("Q and U everywhere: the scan's polarization angles constrain them in none of the " +
                           std::to_string(reached) + " pixels the beams reach (reciprocal condition number below " +
                           detail::number_text(options.rcond_min) + " at NSIDE " + std::to_string(coverage_nside) +
                           "); they are unseen in the maps");
  else if (any_polarization && polarization_poor > 0)
    out.left_out.push_back("Q and U from the maps in " + std::to_string(polarization_poor) + " of the " +
                           std::to_string(reached) +
                           " pixels the beams reach, where the scan's polarization angles do not constrain them "
                           "(reciprocal condition number below " + detail::number_text(options.rcond_min) +
                           " at NSIDE " + std::to_string(coverage_nside) + "): solved, and unseen in the maps");
  // Pixels that only the far tails of the beams reach have a tiny diagonal: the preconditioner's
  // divisor is floored at 1e-3 of the mean non-zero diagonal of its Stokes parameter (else it would
  // multiply their residual by up to 1e27), and the maps mark them unseen (the data hardly constrain
  // them).
  std::vector<bool>& seen = v.seen;
  seen.assign(npix, false);
  double* floor = v.floor;
  for (int k = 0; k < 4; ++k) floor[k] = 1e-3 * mean[std::size_t(k)];
  {
    const auto di = diagonal.I();
    for (std::size_t i = 0; i < di.size(); ++i) seen[i] = di[i] >= floor[0] && di[i] > 0.0;
  }
  // The edges of the coverage, where the beams reach pixels from one side only: the solution there is
  // an extrapolation of the interior, and its errors grow several times. The maps mark unseen the
  // pixels whose I diagonal is below a tenth of its median, and Q, U and V where Q's is.
  {
    const auto di = diagonal.I();
    const double least = tenth_of_median(di);
    std::size_t edge = 0;
    for (std::size_t i = 0; i < npix; ++i)
      if (seen[i] && di[i] < least) seen[i] = false, ++edge;
    if (edge > 0)
      out.left_out.push_back("I, Q and U from the maps in " + std::to_string(edge) +
                             " pixels at the edge of the coverage, whose diagonal is below a tenth of the median: "
                             "solved, and unseen in the maps");
  }
  if (solve[1]) {
    const auto dq = diagonal.Q();
    const double least = tenth_of_median(dq);
    std::size_t edge = 0;
    for (std::size_t i = 0; i < npix; ++i)
      if (polarized[i] && seen[i] && dq[i] < least) polarized[i] = 0, ++edge;
    if (edge > 0)
      out.left_out.push_back("Q and U from the maps in " + std::to_string(edge) +
                             " more pixels at the edge of the coverage, whose Q diagonal is below a tenth of the "
                             "median: solved, and unseen in the maps");
  }
  return v;
}

// The solution smoothed by a Gaussian of options.target_fwhm, with the maps' unseen pixels.
void smoothed_maps(const Sky& x, const Solved& v, const DeconvolutionOptions& options, int nside, DeconvolvedMaps& out) {
  const std::vector<bool>& seen = v.seen;
  const std::vector<std::uint8_t>& polarized = v.polarized;
  const int lmax = 3 * nside - 1;
  detail::SkyAlm a = detail::sky_alm(x, lmax, 3);
  const std::vector<double> wt = gaussian_beam_window(options.target_fwhm, lmax, false);
  const std::vector<double> wp = gaussian_beam_window(options.target_fwhm, lmax, true);
  for (int m = 0; m <= lmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      a.t(l, m) *= wt[std::size_t(l)];
      a.e(l, m) *= wp[std::size_t(l)];
      a.b(l, m) *= wp[std::size_t(l)];
    }
  a.has_v = false;
  const Sky s = detail::sky_from_alm(a, nside, x.units());
  out.smoothed_I.assign(s.I().begin(), s.I().end());
  out.smoothed_Q.assign(s.Q().begin(), s.Q().end());
  out.smoothed_U.assign(s.U().begin(), s.U().end());
  for (std::size_t i = 0; i < seen.size(); ++i)
    if (!seen[i]) out.smoothed_I[i] = out.smoothed_Q[i] = out.smoothed_U[i] = unseen;
    else if (!polarized[i]) out.smoothed_Q[i] = out.smoothed_U[i] = unseen;
}

}  // namespace

DeconvolvedMaps DeconvolvingMapmaker::solve(const Survey& survey,
                                            const std::function<void(const DeconvolutionProgress&)>& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  const int nside = engine_.nside();
  if (!any_ && !options_.reduce)
    throw Error("deconvolution: no TOD was added; call add() for every chunk of the survey before solve()");
  Sky b(nside), x(nside), r(nside), p(nside), q(nside), z(nside), diagonal(nside);
  // The engine's adjoint maps, summed over the processes when there are several.
  Taker take(engine_, options_.reduce);
  take(b);
  const int coverage_nside = options_.coverage_nside > 0 ? std::min(options_.coverage_nside, nside)
                                                         : std::max(1, nside / 4);
  const BinnedMaps angles = diagonal_and_angles(engine_, survey, options_, coverage_nside, take, diagonal);

  DeconvolvedMaps out;
  out.nside = nside;
  const Solved v = what_to_solve(diagonal, angles, options_, nside, coverage_nside, out);
  const std::array<bool, 4>& solve = v.solve;
  const double* floor = v.floor;
  // The right-hand side of the parameters solved; the rest is zero and stays so.
  const auto project = [&](Sky& m) {
    for (int k = 0; k < 4; ++k)
      if (!solve[std::size_t(k)])
        for (double& v : m.stokes(StokesIndex(k))) v = 0.0;
  };
  project(b);
  const double bb = dot(b, b);
  // q = (A^T A + lambda) p: the survey convolved with the sky p, then its adjoint (Engine::normal:
  // in one pass over each disc where the backend can).
  double lambda = 0.0;
  const auto apply = [&](const Sky& in, Sky& result) {
    engine_.set_sky(in);
    survey([&](const SurveyChunk& c) { normal_chunk(engine_, c); });
    for (int k = 0; k < 4; ++k)
      for (double& v : result.stokes(StokesIndex(k))) v = 0.0;
    take(result);
    project(result);
  };
  const bool temperature_too = options_.regularize == DeconvolutionOptions::Regularize::all;
  // z = M^-1 r, M the diagonal (plus lambda where it applies); zero where the diagonal is, and for the
  // parameters left out.
  const auto precondition = [&](const Sky& in, Sky& result) {
    for (int k = 0; k < 4; ++k) {
      const auto ds = diagonal.stokes(StokesIndex(k));
      const auto is = in.stokes(StokesIndex(k));
      const auto os = result.stokes(StokesIndex(k));
      const double lk = k == 0 && !temperature_too ? 0.0 : lambda;
      const bool sk = solve[std::size_t(k)];
      for (std::size_t i = 0; i < ds.size(); ++i) os[i] = sk && ds[i] > 0.0 ? is[i] / (std::max(ds[i], floor[k]) + lk) : 0.0;
    }
  };
  if (bb > 0.0) {
    r = b;
    precondition(r, z);
    p = z;
    double rz = dot(r, z);
    for (int it = 1; it <= options_.max_iterations; ++it) {
      apply(p, q);
      if (it == 1 && options_.regularization > 0.0) lambda = options_.regularization * dot(p, q) / dot(p, p);
      if (lambda > 0.0)
        for (int k = temperature_too ? 0 : 1; k < 4; ++k) {
          const auto ps = p.stokes(StokesIndex(k));
          const auto qs = q.stokes(StokesIndex(k));
          for (std::size_t i = 0; i < ps.size(); ++i) qs[i] += lambda * ps[i];
        }
      const double pq = dot(p, q);
      if (!(pq > 0.0)) break;  // A^T A p = 0: the Krylov space is exhausted
      const double alpha = rz / pq;
      axpy(x, alpha, p);
      axpy(r, -alpha, q);
      out.iterations = it;
      out.residuals.push_back(std::sqrt(dot(r, r) / bb));
      if (progress)
        progress({it, out.residuals.back(),
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()});
      if (out.residuals.back() <= options_.tolerance) {
        out.converged = true;
        break;
      }
      precondition(r, z);
      const double rz_new = dot(r, z);
      const double beta = rz_new / rz;
      rz = rz_new;
      for (int k = 0; k < 4; ++k) {
        const auto ps = p.stokes(StokesIndex(k));
        const auto zs = z.stokes(StokesIndex(k));
        for (std::size_t i = 0; i < ps.size(); ++i) ps[i] = zs[i] + beta * ps[i];
      }
    }
  } else {
    out.converged = true;  // A^T d = 0: the solution is zero
  }
  if (options_.target_fwhm > 0.0) smoothed_maps(x, v, options_, nside, out);
  out.I.assign(x.I().begin(), x.I().end());
  out.Q.assign(x.Q().begin(), x.Q().end());
  out.U.assign(x.U().begin(), x.U().end());
  out.V.assign(x.V().begin(), x.V().end());
  for (std::size_t i = 0; i < v.seen.size(); ++i)
    if (!v.seen[i]) out.I[i] = out.Q[i] = out.U[i] = out.V[i] = unseen;
    else if (!v.polarized[i]) out.Q[i] = out.U[i] = out.V[i] = unseen;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  out.seconds_per_iteration = out.iterations ? out.seconds / out.iterations : 0.0;
  any_ = false;
  return out;
}

}  // namespace pisco
