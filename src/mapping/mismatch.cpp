// Pair mismatch metrics (paper 7.1.5; docs/physics.md, "Mismatch metrics").
#include "pisco/mismatch.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "pisco/error.hpp"

namespace pisco {
namespace {

constexpr double pi = std::numbers::pi;
const double fwhm_to_sigma = 1.0 / std::sqrt(8.0 * std::log(2.0));

void check_beam(const GaussianBeamShape& b, const char* which) {
  auto positive = [&](double v, const char* key) {
    if (!(std::isfinite(v) && v > 0.0))
      throw Error(std::string("beam mismatch: beam ") + which + ": " + key + " must be a positive finite angle, got " +
                  std::to_string(v));
  };
  positive(b.fwhm_x, "fwhm_x");
  positive(b.fwhm_y, "fwhm_y");
  if (!std::isfinite(b.angle) || !std::isfinite(b.xi) || !std::isfinite(b.eta))
    throw Error(std::string("beam mismatch: beam ") + which + ": angle, xi and eta must be finite");
}

// exp(-(u^2 / 2 sx^2 + v^2 / 2 sy^2)) times `scale`.
std::function<double(double, double)> profile(const GaussianBeamShape& b, double scale) {
  const double sx = b.fwhm_x * fwhm_to_sigma, sy = b.fwhm_y * fwhm_to_sigma;
  const double ax = 0.5 / (sx * sx), ay = 0.5 / (sy * sy), c = std::cos(b.angle), s = std::sin(b.angle);
  const double x0 = b.xi, y0 = b.eta;
  return [=](double x, double y) {
    const double dx = x - x0, dy = y - y0;
    const double u = c * dx + s * dy, v = -s * dx + c * dy;
    return scale * std::exp(-(ax * u * u + ay * v * v));
  };
}

double integral(const GaussianBeamShape& b) {
  return 2.0 * pi * (b.fwhm_x * fwhm_to_sigma) * (b.fwhm_y * fwhm_to_sigma);
}

}  // namespace

MismatchMaximum profile_difference_maximum(const std::function<double(double, double)>& a,
                                           const std::function<double(double, double)>& b,
                                           double centre_xi, double centre_eta, double half_width) {
  if (!(std::isfinite(half_width) && half_width > 0.0) || !std::isfinite(centre_xi) || !std::isfinite(centre_eta))
    throw Error("beam mismatch: the search square needs a finite centre and a positive finite half width");
  auto diff = [&](double x, double y) { return std::abs(a(x, y) - b(x, y)); };
  constexpr int n = 201;
  const double h = 2.0 * half_width / (n - 1);
  std::vector<double> grid(std::size_t(n) * n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      grid[std::size_t(j) * n + i] = diff(centre_xi - half_width + i * h, centre_eta - half_width + j * h);
  // Grid points at least as large as their 8 neighbours: the candidates for the maximum.
  std::vector<std::pair<double, std::size_t>> candidates;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double v = grid[std::size_t(j) * n + i];
      bool peak = true;
      for (int dj = -1; dj <= 1 && peak; ++dj)
        for (int di = -1; di <= 1; ++di) {
          const int ii = i + di, jj = j + dj;
          if ((di || dj) && ii >= 0 && jj >= 0 && ii < n && jj < n && grid[std::size_t(jj) * n + ii] > v) {
            peak = false;
            break;
          }
        }
      if (peak) candidates.push_back({v, std::size_t(j) * n + i});
    }
  std::sort(candidates.begin(), candidates.end(), [](auto& p, auto& q) { return p.first > q.first; });
  candidates.resize(std::min<std::size_t>(candidates.size(), 8));
  MismatchMaximum best;
  for (const auto& [v0, k] : candidates) {
    double x = centre_xi - half_width + double(k % n) * h, y = centre_eta - half_width + double(k / n) * h, v = v0;
    // Compass search: a smooth maximum is reached to rounding in its value.
    for (double step = h; step > 1e-12 * half_width;) {
      double bx = x, by = y, bv = v;
      for (int dj = -1; dj <= 1; ++dj)
        for (int di = -1; di <= 1; ++di) {
          if (!di && !dj) continue;
          const double tx = x + di * step, ty = y + dj * step, tv = diff(tx, ty);
          if (tv > bv) bx = tx, by = ty, bv = tv;
        }
      if (bv > v)
        x = bx, y = by, v = bv;
      else
        step *= 0.5;
    }
    if (v > best.delta) best = {v, x, y};
  }
  return best;
}

MismatchMaximum beam_difference_maximum(const GaussianBeamShape& a, const GaussianBeamShape& b,
                                        BeamNormalization normalization) {
  check_beam(a, "a");
  check_beam(b, "b");
  double sa = 1.0, sb = 1.0, unit = 1.0;
  if (normalization == BeamNormalization::integral) {
    sa = 1.0 / integral(a);
    sb = 1.0 / integral(b);
    unit = 0.5 * (sa + sb);  // the peak of the mean of the two unit-integral beams
  }
  const double width = std::max({a.fwhm_x, a.fwhm_y, b.fwhm_x, b.fwhm_y}) * fwhm_to_sigma;
  const double cx = 0.5 * (a.xi + b.xi), cy = 0.5 * (a.eta + b.eta);
  const double reach = 0.5 * std::hypot(a.xi - b.xi, a.eta - b.eta) + 5.0 * width;
  MismatchMaximum m = profile_difference_maximum(profile(a, sa / unit), profile(b, sb / unit), cx, cy, reach);
  return m;
}

GaussianBeamShape mean_beam(const GaussianBeamShape& a, const GaussianBeamShape& b) {
  GaussianBeamShape m;
  m.fwhm_x = 0.5 * (a.fwhm_x + b.fwhm_x);
  m.fwhm_y = 0.5 * (a.fwhm_y + b.fwhm_y);
  // An axis: average the doubled angles as unit vectors.
  m.angle = 0.5 * std::atan2(std::sin(2 * a.angle) + std::sin(2 * b.angle), std::cos(2 * a.angle) + std::cos(2 * b.angle));
  m.xi = 0.5 * (a.xi + b.xi);
  m.eta = 0.5 * (a.eta + b.eta);
  return m;
}

PairMismatch pair_mismatch(const GaussianBeamShape& a, const GaussianBeamShape& b, BeamNormalization normalization) {
  check_beam(a, "a");
  check_beam(b, "b");
  const GaussianBeamShape mean = mean_beam(a, b);
  GaussianBeamShape pa = mean, pb = mean;  // pointing only
  pa.xi = a.xi, pa.eta = a.eta, pb.xi = b.xi, pb.eta = b.eta;
  GaussianBeamShape ba = a, bb = b;  // shapes only
  ba.xi = bb.xi = mean.xi;
  ba.eta = bb.eta = mean.eta;
  PairMismatch r;
  r.pointing = beam_difference_maximum(pa, pb, normalization).delta;
  r.beam = beam_difference_maximum(ba, bb, normalization).delta;
  r.total = beam_difference_maximum(a, b, normalization).delta;
  return r;
}

}  // namespace pisco
