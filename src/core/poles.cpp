// Samples near the HEALPix poles on a turned copy of the sky (polar_copy.cpp), and the cap-boundary rings
// (docs/physics.md, "The quadrature").
#include "core/poles.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include "pisco/error.hpp"

namespace pisco::detail {

CapBoundary cap_boundary(int nside, Quadrature quadrature) {
  CapBoundary b;
  if (quadrature == Quadrature::corrected) b.nside = static_cast<std::uint32_t>(nside);
  return b;
}

std::array<std::pair<std::size_t, std::size_t>, 2> cap_boundary_runs(int nside) {
  const auto n = static_cast<std::uint32_t>(nside);
  const std::size_t north = cap_boundary_north(n), south = cap_boundary_south(n), north_end = north + 8 * n;
  // At NSIDE 1, where ring 2 is both NSIDE + 1 and 3 NSIDE - 1, the second run starts after the first.
  return {std::pair{north - 4 * (n - 1), north_end}, std::pair{std::max(south - 4 * n, north_end), south + 8 * n - 4}};
}

void weigh_cap_boundaries(int nside, std::size_t first, const std::array<std::span<double>, 4>& maps) {
  const CapBoundary b = cap_boundary(nside, Quadrature::corrected);
  const std::size_t end = first + maps[0].size();
  for (const auto& [begin, stop] : cap_boundary_runs(nside))
    for (const std::span<double> map : maps)
      for (std::size_t p = std::max(begin, first); p < std::min(stop, end); ++p) map[p - first] *= b.at(p);
}

void weigh_cap_boundaries(Sky& sky) { weigh_cap_boundaries(sky.nside(), 0, {sky.I(), sky.Q(), sky.U(), sky.V()}); }

double polar_cut(double rho_max, int nside) {
  const double pixel = std::sqrt(std::numbers::pi / 3.0) / nside;
  const double cut = rho_max + 4.0 * pixel;
  return cut < 44.0 * std::numbers::pi / 180.0 ? cut : 0.0;
}

PointingInput PolarSamples::input() const {
  PointingInput in;
  in.quaternions = true;
  in.quats = QuatPointingView{quats};
  in.plate_angle = plate_angle;
  in.sky = 1;
  return in;
}

namespace {
Q4 q4(const Quat& q) { return {q.x, q.y, q.z, q.w}; }
Quat quat(const Q4& q) { return {q.x, q.y, q.z, q.w}; }
// The z component of q z^ q*.
double line_of_sight_z(const Q4& q) {
  const double s = 2.0 / (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  return 1.0 - s * (q.x * q.x + q.y * q.y);
}
}  // namespace

bool find_polar_samples(const PointingInput& in, const DetectorOffset& offset, double offset_angle, double cut,
                        PolarSamples& out) {
  out.index.clear();
  out.quats.clear();
  out.plate_angle.clear();
  if (cut <= 0.0) return false;
  const double cos_cut = std::cos(cut);
  // A boresight farther than cut + offset_angle from both poles cannot carry the detector within cut.
  // The test on theta itself (no cosine per sample): |cos theta| <= cos(wide) is wide <= theta <= pi - wide.
  const double wide = cut + offset_angle;
  const bool far_exists = wide < std::numbers::pi / 2;
  const double cos_wide = far_exists ? std::cos(wide) : -1.0;
  const double theta_lo = far_exists ? wide : std::numbers::pi, theta_hi = far_exists ? std::numbers::pi - wide : 0.0;
  const std::size_t n = in.size();
  for (std::size_t i = 0; i < n; ++i) {
    Q4 b;
    if (in.quaternions) {
      b = q4(in.quats.quats[i]);
      if (std::abs(line_of_sight_z(b)) <= cos_wide) continue;
    } else {
      const double theta = in.angles.theta[i];
      if (theta >= theta_lo && theta <= theta_hi) continue;
      b = q4(quat_from_pointing(theta, in.angles.phi[i], in.angles.psi[i]));
    }
    const double z = offset.active ? line_of_sight_z(quat_mul(b, offset.quat)) : line_of_sight_z(b);
    if (std::abs(z) <= cos_cut) continue;
    out.index.push_back(i);
    out.quats.push_back(quat(quat_mul(polar_rotation, b)));
    if (!in.plate_angle.empty()) out.plate_angle.push_back(in.plate_angle[i]);
  }
  return !out.index.empty();
}

std::vector<std::array<std::size_t, 2>> sky_runs(const std::vector<std::size_t>& polar, std::size_t n,
                                                 std::size_t gap) {
  std::vector<std::array<std::size_t, 2>> runs;
  std::size_t begin = 0;  // the first sample not yet in a run or a skipped gap
  for (std::size_t k = 0; k < polar.size();) {
    std::size_t e = k + 1;  // polar[k .. e) consecutive
    while (e < polar.size() && polar[e] == polar[e - 1] + 1) ++e;
    if (e - k >= gap) {
      if (polar[k] > begin) runs.push_back({begin, polar[k]});
      begin = polar[e - 1] + 1;
    }
    k = e;
  }
  if (begin < n) runs.push_back({begin, n});
  return runs;
}

}  // namespace pisco::detail
