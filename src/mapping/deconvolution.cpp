// The beam-deconvolving map-maker (docs/physics.md, "Map-making with the beams").
#include "pisco/deconvolution.hpp"

#include <algorithm>
#include <cmath>

#include "core/sky_alm.hpp"
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
  if (c.quaternions) engine.normal(c.detector, c.quats, c.hwp_angle);
  else engine.normal(c.detector, c.angles, c.hwp_angle);
}

void adjoint_chunk(Engine& engine, const SurveyChunk& c, std::span<const double> tod) {
  if (c.quaternions) engine.adjoint(c.detector, c.quats, tod, c.hwp_angle);
  else engine.adjoint(c.detector, c.angles, tod, c.hwp_angle);
}

void diagonal_chunk(Engine& engine, const SurveyChunk& c) {
  if (c.quaternions) engine.adjoint_diagonal(c.detector, c.quats, c.hwp_angle);
  else engine.adjoint_diagonal(c.detector, c.angles, c.hwp_angle);
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
  if (!(options.target_fwhm >= 0.0 && options.target_fwhm < 3.14159265358979323846))
    throw Error("deconvolution: target_fwhm = " + std::to_string(options.target_fwhm) +
                " rad; expected 0 (none) or an angle below pi");
}

void DeconvolvingMapmaker::add(const SurveyChunk& chunk, std::span<const double> tod) {
  adjoint_chunk(engine_, chunk, tod);
  any_ = true;
}

DeconvolvedMaps DeconvolvingMapmaker::solve(const Survey& survey,
                                            const std::function<void(const DeconvolutionProgress&)>& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  const int nside = engine_.nside();
  if (!any_ && !options_.reduce)
    throw Error("deconvolution: no TOD was added; call add() for every chunk of the survey before solve()");
  Sky b(nside), x(nside), r(nside), p(nside), q(nside), z(nside), diagonal(nside);
  // The engine's adjoint maps, summed over the processes when there are several.
  std::vector<double> buffer;
  const auto take = [&](Sky& out) {
    engine_.take_adjoint(maps_of(out));
    if (!options_.reduce) return;
    const std::size_t n = out.npix();
    buffer.resize(4 * n);
    for (int k = 0; k < 4; ++k) std::copy_n(out.stokes(StokesIndex(k)).begin(), n, buffer.begin() + std::ptrdiff_t(k * n));
    options_.reduce(buffer);
    for (int k = 0; k < 4; ++k) std::copy_n(buffer.begin() + std::ptrdiff_t(k * n), n, out.stokes(StokesIndex(k)).begin());
  };
  take(b);
  // The Jacobi preconditioner: the diagonal of A^T A (Engine::adjoint_diagonal), one more pass.
  survey([&](const SurveyChunk& c) { diagonal_chunk(engine_, c); });
  take(diagonal);
  // Pixels no sample's disc reaches have a zero diagonal: they stay zero. Pixels that only the far
  // tails of the beams reach have a tiny one: the preconditioner's divisor is floored at 1e-3 of the
  // mean non-zero diagonal of its Stokes parameter (else it would multiply their residual by up to
  // 1e27), and the maps mark them unseen (the data hardly constrain them).
  std::vector<bool> seen(x.npix(), false);
  double floor[4] = {0, 0, 0, 0};
  for (int k = 0; k < 4; ++k) {
    const auto ds = diagonal.stokes(StokesIndex(k));
    double sum = 0;
    std::size_t n = 0;
    for (double v : ds)
      if (v > 0.0) sum += v, ++n;
    floor[k] = n ? 1e-3 * sum / double(n) : 0.0;
  }
  {
    const auto di = diagonal.I();
    for (std::size_t i = 0; i < di.size(); ++i) seen[i] = di[i] >= floor[0] && di[i] > 0.0;
  }
  const double bb = dot(b, b);
  DeconvolvedMaps out;
  out.nside = nside;
  // q = (A^T A + lambda) p: the survey convolved with the sky p, then its adjoint (Engine::normal:
  // in one pass over each disc where the backend can).
  double lambda = 0.0;
  const auto apply = [&](const Sky& in, Sky& result) {
    engine_.set_sky(in);
    survey([&](const SurveyChunk& c) { normal_chunk(engine_, c); });
    for (int k = 0; k < 4; ++k)
      for (double& v : result.stokes(StokesIndex(k))) v = 0.0;
    take(result);
  };
  const bool temperature_too = options_.regularize == DeconvolutionOptions::Regularize::all;
  // z = M^-1 r, M the diagonal (plus lambda where it applies); zero where the diagonal is.
  const auto precondition = [&](const Sky& in, Sky& result) {
    for (int k = 0; k < 4; ++k) {
      const auto ds = diagonal.stokes(StokesIndex(k));
      const auto is = in.stokes(StokesIndex(k));
      const auto os = result.stokes(StokesIndex(k));
      const double lk = k == 0 && !temperature_too ? 0.0 : lambda;
      for (std::size_t i = 0; i < ds.size(); ++i) os[i] = ds[i] > 0.0 ? is[i] / (std::max(ds[i], floor[k]) + lk) : 0.0;
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
  if (options_.target_fwhm > 0.0) {
    const int lmax = 3 * nside - 1;
    detail::SkyAlm a = detail::sky_alm(x, lmax, 3, false);
    const std::vector<double> wt = gaussian_beam_window(options_.target_fwhm, lmax, false);
    const std::vector<double> wp = gaussian_beam_window(options_.target_fwhm, lmax, true);
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
  }
  out.I.assign(x.I().begin(), x.I().end());
  out.Q.assign(x.Q().begin(), x.Q().end());
  out.U.assign(x.U().begin(), x.U().end());
  out.V.assign(x.V().begin(), x.V().end());
  for (std::size_t i = 0; i < seen.size(); ++i)
    if (!seen[i]) out.I[i] = out.Q[i] = out.U[i] = out.V[i] = unseen;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  out.seconds_per_iteration = out.iterations ? out.seconds / out.iterations : 0.0;
  any_ = false;
  return out;
}

}  // namespace pisco
