// Beamsor builders, grid sampling, interpolation and the integral normalization (docs/physics.md,
// "Beamsors").
#include "pisco/beamsor.hpp"
#include "pisco/beam_files.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "kernel/grid_curvature.hpp"
#include "core/text.hpp"
#include "pisco/error.hpp"
#include "pisco/spectra.hpp"

namespace pisco {
namespace {

constexpr double pi = std::numbers::pi;
using detail::degrees_text;

// An input error about the option `field` (Error::key; docs/library.md, "Errors").
[[noreturn]] void fail_option(const char* field, const std::string& what) { throw Error(what, ErrorKind::input, field); }

void check_rho_max(double rho_max) {
  if (!(rho_max > 0.0 && rho_max < pi / 2))
    fail_option("rho_max", degrees_text(rho_max) + " is outside (0, 90) deg; beams are limited to the front hemisphere");
}

// A split's main part within rho_max, its taper within the main part (0: a quarter of it), and the
// outer part's NSIDE a power of two (0: from its band limit).
void check_split(const SidelobeSplit& split, double rho_max) {
  if (split.rho_main == 0.0) return;
  if (!(std::isfinite(split.rho_main) && split.rho_main > 0.0 && split.rho_main < rho_max))
    fail_option("split.rho_main", degrees_text(split.rho_main) + " must lie in (0, rho_max = " + degrees_text(rho_max) +
                                      "): the main part lies within the beam's disc");
  if (!(std::isfinite(split.taper) && split.taper >= 0.0 && split.taper <= split.rho_main))
    fail_option("split.taper", degrees_text(split.taper) + " must lie in [0, rho_main = " + degrees_text(split.rho_main) +
                                   "] (0: a quarter of it)");
  if (split.nside != 0 && !(split.nside > 0 && split.nside <= 8192 && (split.nside & (split.nside - 1)) == 0))
    fail_option("split.nside", std::to_string(split.nside) +
                                   " must be a power of two up to 8192 (or 0: chosen from the outer part's band limit)");
}

// Gauss-Legendre nodes and weights on [-1, 1] by Newton iteration on P_n.
struct GaussLegendre {
  std::vector<double> x, w;
  explicit GaussLegendre(int n) : x(n), w(n) {
    for (int i = 0; i < n; ++i) {
      double z = std::cos(pi * (i + 0.75) / (n + 0.5));
      for (int it = 0; it < 100; ++it) {
        double p0 = 1.0, p1 = 0.0;
        for (int k = 1; k <= n; ++k) {
          const double p2 = p1;
          p1 = p0;
          p0 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p2) / k;
        }
        const double dp = n * (z * p0 - p1) / (z * z - 1.0);
        const double dz = p0 / dp;
        z -= dz;
        if (std::abs(dz) < 1e-16) {
          x[i] = z;
          w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
          break;
        }
        x[i] = z;
        w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
      }
    }
  }
};

// X(kappa) = (1 + kappa^2) R(atan kappa): an in-phase cross-polar field E_cx = kappa E_co turns the
// detector's effective polarization axis by atan(kappa) towards phi' and raises its total power.
Mueller cross_polar_mueller(double kappa) {
  Mueller m{};
  const double k2 = kappa * kappa;
  m[0][0] = 1.0 + k2;
  m[1][1] = 1.0 - k2;
  m[1][2] = 2.0 * kappa;
  m[2][1] = -2.0 * kappa;
  m[2][2] = 1.0 - k2;
  m[3][3] = 1.0 + k2;
  return m;
}

Mueller multiply(const Mueller& a, const Mueller& b) {
  Mueller c{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

Beamsor::Field gaussian_field(double sx, double sy, double angle, const BeamOptions& o) {
  const double ax = 0.5 / (sx * sx), ay = 0.5 / (sy * sy);
  const double kappa = o.cross_polar;
  const CrossPolarPattern pattern = o.cross_polar_pattern;
  const Mueller m = o.mueller;
  const double q_scale = 0.5 / (sx * sy);  // 1 / 2 s^2 with s the geometric-mean width
  const FarSidelobe far = o.far_sidelobe;
  return [=](double rho, double sigma) {
    const double u = rho * std::cos(sigma - angle), v = rho * std::sin(sigma - angle);
    double b = std::exp(-(ax * u * u + ay * v * v));
    if (far.level > 0.0) {
      const double r = (rho - far.radius) / far.width;
      b += far.level * std::exp(-0.5 * r * r) * (1.0 + far.asymmetry * std::cos(sigma - far.angle)) /
           (1.0 + far.asymmetry);
    }
    double k = kappa;
    if (pattern == CrossPolarPattern::quadrupole) {
      // rho^2 sin(2 sigma) is smooth through the axis; the radial factor peaks at rho = sqrt(2) s.
      const double q = rho * rho * q_scale;
      k = kappa * std::sin(2.0 * sigma) * q * std::exp(1.0 - q);
    }
    Mueller out = multiply(cross_polar_mueller(k), m);
    for (auto& row : out)
      for (double& e : row) e *= b;
    return out;
  };
}

}  // namespace

void check_beam_width(double fwhm, double rho_max, const std::string& field) {
  if (!(std::isfinite(fwhm) && fwhm > 0.0))
    throw Error("expected a positive finite angle, got " + degrees_text(fwhm), ErrorKind::input, field);
  if (fwhm / 2 >= rho_max)
    throw Error("a FWHM of " + degrees_text(fwhm) +
                    " is wider than the beam grid: its half-maximum radius does not fit within rho_max = " +
                    degrees_text(rho_max),
                ErrorKind::input, field);
}

void check_beam_options(const BeamOptions& options) {
  check_rho_max(options.rho_max);
  if (!(std::isfinite(options.grid_step) && options.grid_step >= 0.0))
    fail_option("grid_step", "expected a positive finite angle (or 0 for the default step), got " +
                                 degrees_text(options.grid_step));
  check_split(options.split, options.rho_max);
  if (!std::isfinite(options.cross_polar)) fail_option("cross_polar", "must be finite");
  try {
    check_mueller(options.mueller, "the constant Mueller matrix", MuellerBounds::relative);
  } catch (const Error& e) {
    fail_option("mueller", e.what());
  }
  const FarSidelobe& far = options.far_sidelobe;
  if (!(std::isfinite(far.level) && far.level >= 0.0))
    fail_option("far_sidelobe.level", "expected a finite power ratio of the main beam's peak, not negative, got " +
                                          detail::number_text(far.level));
  if (far.level == 0.0) return;
  if (!(std::isfinite(far.radius) && far.radius > 0.0 && far.radius <= options.rho_max))
    fail_option("far_sidelobe.radius", "the ring's radius, " + degrees_text(far.radius) + ", must lie in (0, rho_max = " +
                                           degrees_text(options.rho_max) + "]");
  if (!(std::isfinite(far.width) && far.width > 0.0 && far.width <= pi))
    fail_option("far_sidelobe.width", "expected a positive width up to 180 deg, got " + degrees_text(far.width));
  if (!std::isfinite(far.angle)) fail_option("far_sidelobe.angle", "must be finite");
  if (!(far.asymmetry >= 0.0 && far.asymmetry <= 1.0))
    fail_option("far_sidelobe.asymmetry", "expected a number in [0, 1] (0: a uniform ring, 1: a single lobe), got " +
                                              detail::number_text(far.asymmetry));
}

void check_file_beam_options(const FileBeamOptions& options, const std::string& source) {
  try {
    BeamOptions o;
    o.rho_max = options.rho_max;
    o.grid_step = options.grid_step;
    o.split = options.split;
    check_beam_options(o);
    if (!std::isfinite(options.angle)) fail_option("angle", "must be finite");
  } catch (const Error& e) {
    if (source.empty()) throw;
    throw Error(source + ": " + e.named(), e.kind());
  }
}

Mueller identity_mueller() {
  Mueller m{};
  for (int i = 0; i < 4; ++i) m[i][i] = 1.0;
  return m;
}

// docs/physics.md, "Physical bounds on Mueller matrices".
void check_mueller(const Mueller& m, const std::string& what, MuellerBounds bounds) {
  using detail::number_text;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      if (!std::isfinite(m[i][j]))
        throw Error(what + ": Mueller entry [" + std::to_string(i) + "][" + std::to_string(j) + "] is " +
                    number_text(m[i][j]) + " (expected 16 finite numbers, row by row)");
  if (bounds == MuellerBounds::finite) return;
  const double tol = mueller_tolerance;
  const double m00 = m[0][0];
  if (!(m00 > 0.0))
    throw Error(what + ": M00 = " + number_text(m00) +
                " (T to T) is not positive; a Mueller matrix passes unpolarized light with a positive intensity");
  if (bounds == MuellerBounds::passive) {
    const double out = m00 + std::hypot(m[0][1], m[0][2], m[0][3]);
    if (!(out <= 1.0 + tol))
      throw Error(what + ": transmits up to " + number_text(out) + " times the light (M00 + |(M01, M02, M03)| = " +
                  number_text(out) + "), at most " + number_text(1.0 + tol) + " for a passive element");
    const double polarized = std::hypot(m[1][0], m[2][0], m[3][0]);
    if (!(polarized <= (1.0 + tol) * m00))
      throw Error(what + ": polarizes unpolarized light to a degree of " + number_text(polarized / m00) +
                  " (|(M10, M20, M30)| / M00), at most " + number_text(1.0 + tol) +
                  " (light is at most fully polarized)");
  }
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      if (!(std::abs(m[i][j]) <= (1.0 + tol) * m00))
        throw Error(what + ": |M" + std::to_string(i) + std::to_string(j) + "| = " + number_text(std::abs(m[i][j])) +
                    " exceeds (1 + " + number_text(tol) + ") M00 = " + number_text((1.0 + tol) * m00) +
                    "; no entry of a Mueller matrix exceeds its T-to-T entry M00");
}

int Beamsor::radial_nodes(double rho_max, double grid_step, const std::string& who) {
  // Nodes at r = i * step up to a little beyond a, so every r <= a has two neighbours.
  const double nodes = std::ceil(std::sin(rho_max) / (grid_step / radial_oversampling)) + 2.0;
  if (!(nodes <= max_radial_nodes))
    throw Error(who + ": grid_step = " + degrees_text(grid_step) + " needs " + detail::number_text(nodes) +
                " radial profile nodes for rho_max = " + degrees_text(rho_max) + "; at most " +
                std::to_string(max_radial_nodes) + " are allowed: choose a larger grid_step");
  return std::max(3, static_cast<int>(nodes));
}

double cap_integral(const std::function<double(double, double)>& f, double rho_max,
                    double feature_scale, int sigma_points) {
  static const GaussLegendre gl(16);
  const double panel = feature_scale > 0 ? feature_scale / 4 : rho_max / 64;
  const int panels = std::max(1, static_cast<int>(std::ceil(rho_max / panel)));
  const double h = rho_max / panels;
  const double dsigma = 2 * pi / sigma_points;
  double total = 0.0;
  for (int p = 0; p < panels; ++p) {
    const double r0 = p * h;
    double panel_sum = 0.0;
    for (std::size_t i = 0; i < gl.x.size(); ++i) {
      const double rho = r0 + 0.5 * h * (gl.x[i] + 1.0);
      double ring = 0.0;
      for (int s = 0; s < sigma_points; ++s) ring += f(rho, s * dsigma);
      panel_sum += gl.w[i] * ring * dsigma * std::sin(rho);
    }
    total += 0.5 * h * panel_sum;
  }
  return total;
}

namespace {

// The node k of a beamsor's grid, for messages: its index and direction.
std::string node_text(std::size_t k, bool radial, int n, double a, double step) {
  if (radial)
    return "radial node " + std::to_string(k) + " (rho = " + degrees_text(std::asin(std::min(1.0, k * step))) + ")";
  const std::size_t i = k % static_cast<std::size_t>(n), j = k / static_cast<std::size_t>(n);
  const double x = -a + i * step, y = -a + j * step;
  return "node (" + std::to_string(i) + ", " + std::to_string(j) + ") (rho = " +
         degrees_text(std::asin(std::min(1.0, std::sqrt(x * x + y * y)))) + ", sigma = " +
         degrees_text(std::atan2(y, x)) + ")";
}

// The sampled field's physical bounds (docs/physics.md, "Physical bounds on Mueller matrices"):
// every entry finite, and none above (1 + tol) times the peak B_TT, which must be positive. A B_TT
// zero everywhere is left to the builders, which say so.
void check_field(const std::array<std::vector<double>, 16>& values, const std::string& description, bool radial,
                 int n, double a, double step) {
  static constexpr char stokes[] = "TQUV";
  // The paper's B_XY is row Y, column X.
  const auto entry = [](int e) {
    return std::string("B_") + stokes[e % 4] + stokes[e / 4] + " (row " + std::to_string(e / 4) + ", column " +
           std::to_string(e % 4) + ")";
  };
  for (int e = 0; e < 16; ++e)
    for (std::size_t k = 0; k < values[e].size(); ++k)
      if (!std::isfinite(values[e][k]))
        throw Error("beam '" + description + "': " + entry(e) + " is " + detail::number_text(values[e][k]) + " at " +
                    node_text(k, radial, n, a, step) + "; a beam's Mueller field must be finite");
  const auto& tt = values[0];
  if (std::all_of(tt.begin(), tt.end(), [](double v) { return v == 0.0; })) return;
  const double peak = *std::max_element(tt.begin(), tt.end());
  if (!(peak > 0.0))
    throw Error("beam '" + description + "': B_TT is nowhere positive (its largest value is " +
                detail::number_text(peak) + "); a beam's peak T-to-T response must be positive");
  // The largest entry, reported where it lies.
  int worst_e = 0;
  std::size_t worst_k = 0;
  double worst = 0.0;
  for (int e = 0; e < 16; ++e)
    for (std::size_t k = 0; k < values[e].size(); ++k)
      if (std::abs(values[e][k]) > worst) {
        worst = std::abs(values[e][k]);
        worst_e = e;
        worst_k = k;
      }
  if (!(worst <= (1.0 + mueller_tolerance) * peak))
    throw Error("beam '" + description + "': " + entry(worst_e) + " = " + detail::number_text(values[worst_e][worst_k]) +
                " at " + node_text(worst_k, radial, n, a, step) + " exceeds the beam's peak B_TT = " +
                detail::number_text(peak) + " by more than " + detail::number_text(100 * mueller_tolerance) +
                "%; no entry of a beam's Mueller field exceeds its peak T-to-T response");
}

}  // namespace

void Beamsor::sample(const Field& field) {
  std::array<std::vector<double>, 16> values;
  if (radial_) {
    for (auto& v : values) v.assign(static_cast<std::size_t>(n_), 0.0);
    for (int i = 0; i < n_; ++i) {
      const Mueller m = field(std::asin(std::min(1.0, i * step_)), 0.0);
      for (int e = 0; e < 16; ++e) values[e][static_cast<std::size_t>(i)] = m[e / 4][e % 4];
    }
    check_field(values, description_, true, n_, a_, step_);
    for (int e = 0; e < 16; ++e) {
      const bool zero = std::all_of(values[e].begin(), values[e].end(), [](double v) { return v == 0.0; });
      elements_[e] = zero ? std::vector<double>{} : std::move(values[e]);
    }
    return;
  }
  for (auto& v : values) v.assign(static_cast<std::size_t>(n_) * n_, 0.0);
  for (int j = 0; j < n_; ++j) {
    const double y = -a_ + j * step_;
    for (int i = 0; i < n_; ++i) {
      const double x = -a_ + i * step_;
      const double r = std::min(1.0, std::sqrt(x * x + y * y));
      const Mueller m = field(std::asin(r), std::atan2(y, x));
      for (int e = 0; e < 16; ++e) values[e][static_cast<std::size_t>(j) * n_ + i] = m[e / 4][e % 4];
    }
  }
  check_field(values, description_, false, n_, a_, step_);
  for (int e = 0; e < 16; ++e) {
    const bool zero = std::all_of(values[e].begin(), values[e].end(), [](double v) { return v == 0.0; });
    elements_[e] = zero ? std::vector<double>{} : std::move(values[e]);
  }
}

Beamsor Beamsor::from_field(const Field& field, double rho_max, double grid_step,
                            std::string description, double feature_scale, bool radial,
                            const SidelobeSplit& split) {
  check_rho_max(rho_max);
  if (!(std::isfinite(grid_step) && grid_step > 0.0))
    throw Error("beam: grid_step must be a positive finite angle, got " + degrees_text(grid_step));
  if (grid_step > std::sin(split.rho_main > 0.0 ? split.rho_main : rho_max))
    throw Error("beam '" + description + "': grid_step = " + degrees_text(grid_step) + " is coarser than the grid's " +
                "half width, sin(rho_max) = " + degrees_text(std::sin(split.rho_main > 0.0 ? split.rho_main : rho_max)) +
                ": the grid would not sample the beam");
  if (split.rho_main != 0.0) return split_field(field, rho_max, grid_step, std::move(description), feature_scale, radial, split);
  Beamsor b;
  b.rho_max_ = rho_max;
  b.a_ = std::sin(rho_max);
  const double nodes = std::ceil(2.0 * b.a_ / grid_step) + 1.0;
  if (nodes > max_grid_nodes)
    throw Error("beam: grid_step = " + degrees_text(grid_step) + " needs " + std::to_string(nodes) +
                " nodes per axis for rho_max = " + degrees_text(rho_max) + "; at most " +
                std::to_string(max_grid_nodes) + " are allowed");
  b.radial_ = radial;
  if (radial) {
    b.n_ = radial_nodes(rho_max, grid_step, "beam");
    b.step_ = grid_step / radial_oversampling;
  } else {
    b.n_ = std::max(3, static_cast<int>(nodes));
    b.step_ = 2.0 * b.a_ / (b.n_ - 1);
  }
  b.description_ = std::move(description);
  b.sample(field);
  if (!b.has_element(0, 0)) throw Error("beam '" + b.description_ + "': B_TT is zero everywhere");
  b.omega_ = cap_integral([&](double r, double s) { return field(r, s)[0][0]; }, rho_max,
                          feature_scale > 0 ? feature_scale : grid_step * 4);
  if (!(b.omega_ > 0.0 && std::isfinite(b.omega_)))
    throw Error("beam '" + b.description_ + "': the integral of B_TT over the cap is not positive");
  return b;
}

Beamsor Beamsor::split_field(const Field& field, double rho_max, double grid_step, std::string description,
                             double feature_scale, bool radial, const SidelobeSplit& split) {
  check_split(split, rho_max);
  const double rho_main = split.rho_main;
  const double taper = split.taper == 0.0 ? rho_main / 4 : split.taper;
  const double start = rho_main - taper;
  // tau: 1 within rho_main - taper, a half cosine down to 0 at rho_main.
  const auto tau = [=](double rho) {
    if (rho <= start) return 1.0;
    if (rho >= rho_main) return 0.0;
    return 0.5 * (1.0 + std::cos(pi * (rho - start) / taper));
  };
  const auto scaled = [&field](double f, double rho, double sigma) {
    Mueller m = field(rho, sigma);
    for (auto& row : m)
      for (double& e : row) e *= f;
    return m;
  };
  const double feature = feature_scale > 0 ? feature_scale : grid_step * 4;
  std::ostringstream d;
  d << description << "; split at " << rho_main / deg << " deg (taper " << taper / deg << " deg)";
  Beamsor main = from_field([&](double r, double s) { return scaled(tau(r), r, s); }, rho_main, grid_step, d.str(),
                            feature_scale, radial);
  // The outer part's band limit, from its mean radial profile (T to T) on the field itself; it sets
  // the outer grid's step (its features are no finer than the taper or pi / l_b): bilinear
  // interpolation at taper / 8 or 0.5 / l_b, and a grid small enough to stay in cache.
  // Simpson's rule resolves P_l up to lcheck only with four or more nodes per period (2 pi / l): fewer
  // alias the profile's low harmonics onto high l, which would read as a band limit near lcheck.
  const int lcheck = 4096;
  const int steps = 2 * std::max({512, static_cast<int>(std::ceil(rho_max / (grid_step / 2) / 2)),
                                  static_cast<int>(std::ceil(lcheck * rho_max / pi))});
  const auto profile = [&](double rho) {
    double sum = 0.0;
    for (int k = 0; k < 32; ++k) sum += field(rho, 2 * pi * k / 32)[0][0];
    return (1.0 - tau(rho)) * sum / 32;
  };
  int band = lcheck;
  try {
    const std::vector<double> bl = radial_beam_window(profile, rho_max, lcheck, steps);
    band = 0;
    for (int l = lcheck; l >= 0; --l)
      if (std::abs(bl[static_cast<std::size_t>(l)]) > 1e-4) {
        band = l;
        break;
      }
  } catch (const Error&) {
    throw Error("beam '" + description + "': its outer part beyond " + degrees_text(start) +
                " carries no power; split it at a larger rho_main or not at all");
  }
  band = std::max(band, 1);
  const double outer_step = std::max(grid_step, std::min(taper / 8, 0.5 / band));
  Beamsor outer;
  try {
    outer = from_field([&](double r, double s) { return scaled(1.0 - tau(r), r, s); }, rho_max, outer_step,
                       "sidelobes of " + description, std::max(feature, outer_step * 4), radial);
  } catch (const Error&) {
    throw Error("beam '" + description + "': its outer part beyond " + degrees_text(start) +
                " carries no power; split it at a larger rho_main or not at all");
  }
  // The whole beam's Omega~ for both parts.
  const double omega = cap_integral([&](double r, double s) { return field(r, s)[0][0]; }, rho_max, feature);
  if (!(omega > 0.0 && std::isfinite(omega)))
    throw Error("beam '" + description + "': the integral of B_TT over the cap is not positive");
  main.omega_ = omega;
  outer.omega_ = omega;
  main.outer_ = std::make_shared<const Beamsor>(std::move(outer));
  main.outer_nside_ = split.nside;
  main.outer_lmax_ = band;
  main.description_ += "; sidelobes to " + std::to_string(rho_max / deg).substr(0, 6) + " deg, band limit l = " +
                       std::to_string(main.outer_lmax_);
  return main;
}

Beamsor Beamsor::gaussian(double fwhm, const BeamOptions& options) {
  check_beam_options(options);
  check_beam_width(fwhm, options.rho_max, "fwhm");
  return elliptical_gaussian(fwhm, fwhm, 0.0, options);
}

Beamsor Beamsor::elliptical_gaussian(double fwhm_x, double fwhm_y, double angle,
                                     const BeamOptions& options) {
  check_beam_options(options);
  check_beam_width(fwhm_x, options.rho_max, "fwhm_x");
  check_beam_width(fwhm_y, options.rho_max, "fwhm_y");
  if (!std::isfinite(angle)) fail_option("angle", "must be finite");
  const FarSidelobe& far = options.far_sidelobe;
  const double to_sigma = 1.0 / std::sqrt(8.0 * std::log(2.0));
  const double smallest = std::min(fwhm_x, fwhm_y);
  const bool radial = fwhm_x == fwhm_y &&
                      (options.cross_polar == 0.0 || options.cross_polar_pattern == CrossPolarPattern::uniform) &&
                      (far.level == 0.0 || far.asymmetry == 0.0);
  // The default step: FWHM / 16 on the 2D grid (its interpolation error is of order step^3, docs/physics.md,
  // "Interpolation on the grid"), FWHM / 20 for a radial profile (sampled 64 times finer).
  const double step = options.grid_step > 0 ? options.grid_step : smallest / (radial ? 20.0 : 16.0);
  std::ostringstream d;
  if (fwhm_x == fwhm_y)
    d << "Gaussian FWHM " << fwhm_x * 180 / pi << " deg";
  else
    d << "elliptical Gaussian FWHM " << fwhm_x * 180 / pi << " x " << fwhm_y * 180 / pi
      << " deg at " << angle * 180 / pi << " deg";
  if (far.level > 0.0)
    d << ", far sidelobe " << 10.0 * std::log10(far.level) << " dB at " << far.radius * 180 / pi << " deg";
  if (options.cross_polar != 0.0)
    d << ", cross-polar " << options.cross_polar
      << (options.cross_polar_pattern == CrossPolarPattern::uniform ? " (uniform)" : " (quadrupole)");
  d << ", rho_max " << options.rho_max * 180 / pi << " deg, grid step " << step * 180 / pi * 60
    << " arcmin";
  if (radial) d << " (radial profile every " << step / radial_oversampling / deg * 60 << " arcmin)";
  return from_field(gaussian_field(fwhm_x * to_sigma, fwhm_y * to_sigma, angle, options),
                    options.rho_max, step, d.str(), smallest, radial, options.split);
}

Mueller Beamsor::stokes_mueller(double i, double q, double u, double v) {
  Mueller m{};
  m[0][0] = i;
  const double p = std::sqrt(q * q + u * u + v * v);
  if (!(p > 0.0)) return m;
  // n = (a, b, c) = (q, u, v) / p; the rotation R = 1 + [k]x + [k]x^2 / (1 + a), k = e_Q x n, takes
  // e_Q onto n; the Q, U, V block is p R^T (docs/beams.md, "From fields to a beamsor").
  const double a = q / p, b = u / p, c = v / p;
  double r[3][3];
  if (1.0 + a > 1e-12) {
    const double f = 1.0 / (1.0 + a);
    r[0][0] = a;  r[0][1] = b;              r[0][2] = c;
    r[1][0] = -b; r[1][1] = 1.0 - b * b * f; r[1][2] = -b * c * f;
    r[2][0] = -c; r[2][1] = -b * c * f;      r[2][2] = 1.0 - c * c * f;
  } else {  // purely cross-polar: a half turn about V
    r[0][0] = -1; r[0][1] = 0;  r[0][2] = 0;
    r[1][0] = 0;  r[1][1] = -1; r[1][2] = 0;
    r[2][0] = 0;  r[2][1] = 0;  r[2][2] = 1;
  }
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) m[row + 1][col + 1] = p * r[row][col];
  return m;
}

std::span<const double> Beamsor::element(int row, int col) const {
  return elements_.at(static_cast<std::size_t>(row * 4 + col));
}

bool Beamsor::has_element(int row, int col) const { return !element(row, col).empty(); }

Mueller Beamsor::at(double x, double y) const {
  Mueller m{};
  if (x * x + y * y > a_ * a_) return m;
  if (radial_) {
    const double u = std::sqrt(x * x + y * y) / step_;
    const int i = std::min(static_cast<int>(u), n_ - 2);
    const double f = u - i;
    for (int e = 0; e < 16; ++e)
      if (!elements_[e].empty()) m[e / 4][e % 4] = (1 - f) * elements_[e][i] + f * elements_[e][i + 1];
    return m;
  }
  const double u = (x + a_) / step_, v = (y + a_) / step_;
  if (!(u >= 0 && v >= 0 && u <= n_ - 1 && v <= n_ - 1)) return m;
  const int i = std::min(static_cast<int>(u), n_ - 2), j = std::min(static_cast<int>(v), n_ - 2);
  const double fu = u - i, fv = v - j;
  for (int e = 0; e < 16; ++e) {
    const auto& g = elements_[e];
    if (g.empty()) continue;
    // Bilinear less the curvature terms, as every backend interpolates (kernel/grid_curvature.hpp).
    m[e / 4][e % 4] = detail::interpolate_grid(g.data(), n_, 1, i, j, fu, fv, 0);
  }
  return m;
}

}  // namespace pisco
