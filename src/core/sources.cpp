// Point sources, fixed or moving, evaluated per sample (core/sources.hpp; docs/sources.md).
#include "core/sources.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "kernel/contribution.hpp"
#include "kernel/plate.hpp"
#include "core/text.hpp"
#include "pisco/error.hpp"

namespace pisco {

SourceTrack SourceTrack::fixed(std::string name, double theta, double phi, double I, double Q, double U, double V) {
  SourceTrack s;
  s.name = std::move(name);
  s.time = {0.0};
  s.theta = {theta};
  s.phi = {phi};
  s.I = {I};
  s.Q = {Q};
  s.U = {U};
  s.V = {V};
  return s;
}

void SourceTrack::check(const std::string& origin) const {
  const std::string who = origin + ": source '" + name + "'";
  const std::size_t n = time.size();
  if (n == 0) throw Error(who + " has no point: expected at least one time, direction and flux");
  const auto same = [&](const std::vector<double>& v, const char* field, bool optional) {
    if (v.size() != n && !(optional && v.empty()))
      throw Error(who + ": " + field + " has " + std::to_string(v.size()) + " values; expected " + std::to_string(n) +
                  " (one per time)" + (optional ? " or none" : ""));
  };
  same(theta, "theta", false);
  same(phi, "phi", false);
  same(I, "I", false);
  same(Q, "Q", true);
  same(U, "U", true);
  same(V, "V", true);
  for (std::size_t k = 0; k < n; ++k) {
    const std::string at = who + ", point " + std::to_string(k) + ": ";
    if (!std::isfinite(time[k])) throw Error(at + "the time is " + detail::number_text(time[k]) + "; expected a finite number");
    if (k > 0 && !(time[k] > time[k - 1]))
      throw Error(at + "the time " + detail::number_text(time[k]) + " does not follow " +
                  detail::number_text(time[k - 1]) + "; times must increase strictly");
    if (!(theta[k] >= 0.0 && theta[k] <= std::numbers::pi))
      throw Error(at + "theta is " + detail::number_text(theta[k]) + "; expected a colatitude in [0, pi] radians");
    if (!std::isfinite(phi[k])) throw Error(at + "phi is " + detail::number_text(phi[k]) + "; expected a finite longitude");
    for (const auto& [v, field] : {std::pair{&I, "I"}, {&Q, "Q"}, {&U, "U"}, {&V, "V"}})
      if (!v->empty() && !std::isfinite((*v)[k]))
        throw Error(at + "the flux " + field + " is " + detail::number_text((*v)[k]) + "; expected a finite number");
  }
  for (std::size_t k = 1; k < n; ++k) {
    const double c = std::cos(theta[k - 1]) * std::cos(theta[k]) +
                     std::sin(theta[k - 1]) * std::sin(theta[k]) * std::cos(phi[k] - phi[k - 1]);
    if (c < -1.0 + 1e-12)
      throw Error(who + ", point " + std::to_string(k) +
                  ": the direction is opposite the previous point's, so no great circle joins them; add a point between");
  }
}

namespace detail {
namespace {

Vec3<double> unit(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

double at(const std::vector<double>& v, std::size_t k) { return v.empty() ? 0.0 : v[k]; }

// A source at one time: its direction and flux.
struct SourceState {
  Vec3<double> k;
  Vec4<double> flux;
};

// The track at time t, within it: between points k and k + 1, the great circle at a constant rate and
// the flux linear in time. `cursor` remembers the last interval (samples usually come in order).
SourceState state_at(const SourceTrack& s, double t, std::size_t& cursor) {
  const std::size_t n = s.time.size();
  const auto flux = [&](std::size_t k) { return Vec4<double>{s.I[k], at(s.Q, k), at(s.U, k), at(s.V, k)}; };
  if (n == 1) return {unit(s.theta[0], s.phi[0]), flux(0)};
  if (cursor + 1 >= n || !(s.time[cursor] <= t && t <= s.time[cursor + 1])) {
    const auto it = std::upper_bound(s.time.begin(), s.time.end(), t);
    cursor = std::min<std::size_t>(std::size_t(it - s.time.begin()), n - 1) - 1;
  }
  const std::size_t k = cursor;
  const double u = (t - s.time[k]) / (s.time[k + 1] - s.time[k]);
  const Vec3<double> a = unit(s.theta[k], s.phi[k]), b = unit(s.theta[k + 1], s.phi[k + 1]);
  const double c = std::clamp(a.x * b.x + a.y * b.y + a.z * b.z, -1.0, 1.0), omega = std::acos(c);
  double wa = 1.0 - u, wb = u;
  if (omega > 1e-9) {
    wa = std::sin((1.0 - u) * omega) / std::sin(omega);
    wb = std::sin(u * omega) / std::sin(omega);
  }
  Vec3<double> k3{wa * a.x + wb * b.x, wa * a.y + wb * b.y, wa * a.z + wb * b.z};
  const double norm = std::sqrt(k3.x * k3.x + k3.y * k3.y + k3.z * k3.z);
  k3 = {k3.x / norm, k3.y / norm, k3.z / norm};
  const Vec4<double> f0 = flux(k), f1 = flux(k + 1);
  return {k3, {f0.x + u * (f1.x - f0.x), f0.y + u * (f1.y - f0.y), f0.z + u * (f1.z - f0.z), f0.w + u * (f1.w - f0.w)}};
}

// One prepared detector's response to a source of brightness S = flux / Omega_pix at k: the reference
// backend's per-pixel arithmetic, with the plate's effective weights where its columns (plate_columns)
// are given. Zero beyond the detector's disc, as a pixel beyond it is not summed.
double response(const PreparedDetector& det, const SampleFrame<double>& f, const Vec3<double>& los,
                const Vec3<double>& k, const Vec4<double>& S, const Vec4<double>* plate) {
  if (los.x * k.x + los.y * k.y + los.z * k.z < det.cos_rho_max) return 0.0;
  const ArrayGrid<double> grid{det.weights.data(), det.grid_n, det.grid_a, det.grid_inv_step};
  PixelGeometry<double> g = pixel_geometry(f, k);
  if (!std::isfinite(g.cos2chi) || !std::isfinite(g.sin2chi)) {  // a source exactly at a pole: its frame's phi
    g.cos2chi = 1.0;
    g.sin2chi = 0.0;
  }
  Vec4<double> w = det.radial ? interpolate_radial(grid, g.r2) : interpolate_weights(grid, g.x, g.y);
  if (plate) w = effective_weights(w, plate[0], plate[1], plate[2], plate[3]);
  return stokes_response(w, g.cos2chi, g.sin2chi, S);
}

}  // namespace

void add_source_tod(const PointingInput& in, std::span<const double> plate_angle, std::span<const double> time,
                    const std::vector<SourceTrack>& sources, const std::vector<SourcePart>& parts,
                    std::span<double> tod) {
  // Every sample within every moving source's track, checked before the TOD changes.
  for (const SourceTrack& s : sources)
    if (s.time.size() > 1)
      for (std::size_t i = 0; i < time.size(); ++i)
        if (!(time[i] >= s.time.front() && time[i] <= s.time.back()))
          throw Error("source '" + s.name + "': sample " + std::to_string(i) + " is at time " + number_text(time[i]) +
                      ", outside its track (" + number_text(s.time.front()) + " to " + number_text(s.time.back()) +
                      "); the TOD is unchanged");
  std::vector<std::size_t> cursor(sources.size(), 0);
  const PreparedDetector& main = *parts.at(0).detector;
  double m[16];          // the plate's M(theta) this sample, row-major
  Vec4<double> cols[4];  // and by columns, for an aperture plate's effective weights
  for (std::size_t i = 0; i < tod.size(); ++i) {
    double theta = 0.0, phi = 0.0;
    const SampleFrame<double> f = detector_frame(in, i, main, theta, phi);
    const Vec3<double> los = unit(theta, phi);
    if (main.plate != PreparedDetector::Plate::none) {
      plate_at(&main.plate_mueller[0][0], std::cos(2 * plate_angle[i]), std::sin(2 * plate_angle[i]), m);
      plate_columns(m, cols);
    }
    double d = 0.0;
    for (std::size_t s = 0; s < sources.size(); ++s) {
      const SourceState st = state_at(sources[s], time[i], cursor[s]);
      for (const SourcePart& part : parts) {
        const Vec4<double> S{st.flux.x / part.pixel_area, st.flux.y / part.pixel_area, st.flux.z / part.pixel_area,
                             st.flux.w / part.pixel_area};
        const PreparedDetector& det = *part.detector;
        if (det.plate == PreparedDetector::Plate::detector) {
          // d = D(0) M(theta) s, s_b the row detector b's response (as Engine::complete combines them).
          for (int b = 0; b < 4; ++b)
            d += (det.d0[0] * m[b] + det.d0[1] * m[4 + b]) * response(*part.rows[b], f, los, st.k, S, nullptr);
        } else {
          d += response(det, f, los, st.k, S, det.plate == PreparedDetector::Plate::aperture ? cols : nullptr);
        }
      }
    }
    tod[i] += d;
  }
}

}  // namespace detail
}  // namespace pisco
