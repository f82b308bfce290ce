#include "vulkan/tables.hpp"

#include <cmath>
#include <cstring>
#include <numbers>

#include "kernel/disc.hpp"
#include "core/poles.hpp"
#include "pisco/quaternion.hpp"

namespace pisco::detail::vk {
namespace {

// x - double(float(x)): what float(x) lacks of x. Kept out of line: GCC 12's vectorizer at -O3 folds
// x - double(float(x)) to zero when this runs inside a pixel loop.
[[gnu::noinline]] float float_residual(double x) {
  const float hi = float(x);
  return float(x - double(hi));
}

}  // namespace

double ff_bits(double x) {
  const float pair[2] = {float(x), float_residual(x)};
  double bits;
  static_assert(sizeof(pair) == sizeof(bits));
  std::memcpy(&bits, pair, sizeof bits);
  return bits;
}

double from_ff_bits(double bits) {
  float pair[2];
  std::memcpy(pair, &bits, sizeof bits);
  return double(pair[0]) + double(pair[1]);
}

bool use_float_float(bool device_float64, const std::string& device_name, Arithmetic arithmetic) {
  switch (arithmetic) {
    case Arithmetic::float_float: return true;
    case Arithmetic::float64:
      if (!device_float64)
        throw Error("vulkan: arithmetic \"float64\" was asked for, but " + device_name +
                    " lacks shaderFloat64; use \"float-float\" or \"auto\"");
      return false;
    case Arithmetic::automatic: break;
  }
  return !device_float64;
}

KernelMode kernel_mode(const EngineInputs& in, const SkyView& sky, bool ff) {
  KernelMode m;
  m.ff = ff;
  m.monopole = float32_monopole(sky);
  m.per_sample = in.normalization == Normalization::per_sample;
  m.float64 = m.monopole != 0.0 || m.per_sample;
  m.boundary = cap_boundary(sky.nside(), in.quadrature);
  return m;
}

void pack_sky(const std::array<std::span<const double>, 4>& maps, std::size_t maps_first, const KernelMode& mode,
              std::size_t first, std::size_t n, const double* xyz, float* out) {
  for (std::size_t j = 0; j < n; ++j) {
    const std::size_t p = first + j, i = p - maps_first;
    float* rec = out + 8 * j;
    rec[0] = float(xyz[3 * j]);
    rec[1] = float(xyz[3 * j + 1]);
    rec[2] = float(xyz[3 * j + 2]);
    rec[3] = float(maps[0][i] - mode.monopole * mode.boundary.at(p));
    rec[4] = float(maps[1][i]);
    rec[5] = float(maps[2][i]);
    rec[6] = float(maps[3][i]);
    rec[7] = 0.0f;
  }
}

void pack_sky(const SkyView& sky, const KernelMode& mode, std::size_t first, std::size_t n, const double* xyz, float* out) {
  pack_sky({sky.I(), sky.Q(), sky.U(), sky.V()}, 0, mode, first, n, xyz, out);
}

void pack_sky_lo(std::size_t n, const double* xyz, float* out) {
  for (std::size_t j = 0; j < n; ++j) {
    for (int c = 0; c < 3; ++c) out[4 * j + c] = float_residual(xyz[3 * j + c]);
    out[4 * j + 3] = 0.0f;
  }
}

std::vector<std::uint32_t> pack_rings(const PreparedSky& sky, const CapBoundary& boundary, bool ff) {
  std::vector<std::uint32_t> rings;
  rings.reserve(4 * sky.rings.size() + 8);
  // A float64 number's bits (float-float with ff), low word first.
  const auto words = [&](double x) {
    const double v = ff ? ff_bits(x) : x;
    std::uint64_t bits = 0;
    static_assert(sizeof(bits) == sizeof(v));
    std::memcpy(&bits, &v, sizeof(bits));
    rings.insert(rings.end(), {std::uint32_t(bits), std::uint32_t(bits >> 32)});
  };
  for (const RingEntry& r : sky.rings) {
    words(r.z);
    rings.insert(rings.end(), {r.first, r.count | (r.shifted ? 1u << 31 : 0u)});
  }
  // The monopole's weights on the rings about the caps' edges (kernel.glsl's cap_weight).
  for (const uint ring : {0u, CAP_LAST_RING, CAP_EDGE_RING, CAP_BELT_RING}) words(boundary.weight(ring));
  return rings;
}

Grids pack_grids(const EngineInputs& in, const KernelMode& mode) {
  Grids g;
  std::vector<float>& w32 = g.w32;
  std::vector<double>& w64 = g.w64;
  for (const PreparedDetector& d : in.detectors) {
    // Each node with its neighbour along x (or r), (w[k], w[k + 1]) in 2 x columns floats, so that
    // the pair is one texel (2 columns) or two neighbouring ones (4 columns).
    g.offset.push_back(std::uint32_t(w32.size() / 4));
    const bool plate = d.plate == PreparedDetector::Plate::aperture;
    // A plate detector's float64 nodes are 3 texels each (src/kernel/contribution.glsl), from a texel
    // index divisible by 3.
    if (plate && mode.float64)
      while ((w64.size() / 2) % 3 != 0) w64.insert(w64.end(), {0.0, 0.0});
    g.offset64.push_back(std::uint32_t(w64.size() / 2 / (plate ? 3 : 1)));
    const std::size_t columns = std::size_t(weight_columns(d));  // core/prepared.hpp
    g.columns.push_back(std::uint32_t(columns));
    const std::vector<float> dw = float32_weights(d);
    const std::size_t nodes = dw.size() / 4;
    for (std::size_t k = 0; k < nodes; ++k)
      for (std::size_t m = 0; m < 2; ++m)
        for (std::size_t c = 0; c < columns; ++c) {
          const std::size_t src = 4 * (k + m) + c;
          w32.push_back(src < dw.size() ? dw[src] : 0.0f);
        }
    if (mode.float64)
      for (std::size_t k = 0; k < nodes; ++k) {
        w64.push_back(d.weights[4 * k]);
        w64.push_back(mode.per_sample ? d.norm_weights[4 * k] : 0.0);
        if (plate) w64.insert(w64.end(), {d.weights[4 * k + 1], d.weights[4 * k + 2], d.weights[4 * k + 3], 0.0});
      }
    // The plate's M0, row by row: 8 texels.
    g.plate_offset64.push_back(std::uint32_t(w64.size() / 2));
    if (plate)
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) w64.push_back(d.plate_mueller[i][j]);
  }
  if (w64.empty()) w64.assign(2, 0.0);
  if (mode.ff)
    for (double& x : w64) x = ff_bits(x);
  return g;
}

PushConstants push_constants(const EngineInputs& in, const Grids& grids, const KernelMode& mode, std::size_t detector,
                             bool quaternions) {
  const PreparedDetector& det = in.detectors.at(detector);
  PushConstants push{};
  push.rho_max = det.rho_max;
  push.cos_rho_max = det.cos_rho_max;
  push.monopole = mode.monopole;
  push.grid_a = det.grid_a;
  push.grid_inv_step = det.grid_inv_step;
  push.offset_quat[0] = det.offset.quat.x;
  push.offset_quat[1] = det.offset.quat.y;
  push.offset_quat[2] = det.offset.quat.z;
  push.offset_quat[3] = det.offset.quat.w;
  push.grid_a32 = float(det.grid_a);
  push.grid_inv_step32 = float(det.grid_inv_step);
  push.cos_zeta = float(det.cos_zeta);
  push.sin_zeta = float(det.sin_zeta);
  push.grid_n = std::uint32_t(det.grid_n);
  push.grid_offset = grids.offset.at(detector);
  push.grid_offset64 = grids.offset64.at(detector);
  push.plate_offset64 = grids.plate_offset64.at(detector);
  push.nside = std::uint32_t(in.sky.nside);
  push.flags = (mode.per_sample ? PISCO_FLAG_PER_SAMPLE : 0u) | (quaternions || mode.ff ? PISCO_FLAG_QUATERNION : 0u) |
               (det.offset.active ? PISCO_FLAG_OFFSET : 0u);
  if (mode.ff)
    for (double* x : {&push.rho_max, &push.cos_rho_max, &push.monopole, &push.grid_a, &push.grid_inv_step,
                      &push.offset_quat[0], &push.offset_quat[1], &push.offset_quat[2], &push.offset_quat[3]})
      *x = ff_bits(*x);
  return push;
}

void pack_pointing(const PointingInput& pointing, bool ff, double* p) {
  constexpr double twopi = 2 * std::numbers::pi;
  const std::size_t n = pointing.size();
  if (ff) {
    // The float-float kernel takes every sample as a boresight quaternion (src/kernel/frame.glsl).
    for (std::size_t i = 0; i < n; ++i) {
      const Quat q = pointing.quaternions ? pointing.quats.quats[i]
                                          : quat_from_pointing(pointing.angles.theta[i], pointing.angles.phi[i],
                                                               pointing.angles.psi[i]);
      p[4 * i] = ff_bits(q.x);
      p[4 * i + 1] = ff_bits(q.y);
      p[4 * i + 2] = ff_bits(q.z);
      p[4 * i + 3] = ff_bits(q.w);
    }
  } else if (pointing.quaternions) {
    std::memcpy(p, pointing.quats.quats.data(), n * sizeof(Quat));
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      double phi = pointing.angles.phi[i];
      if (!(phi >= 0.0 && phi < twopi)) phi = wrap_phi(phi);  // as the reference does
      p[4 * i] = pointing.angles.theta[i];
      p[4 * i + 1] = phi;
      p[4 * i + 2] = pointing.angles.psi[i];
      p[4 * i + 3] = 0.0;
    }
  }
}

void pack_plate(std::span<const double> plate_angle, bool ff, double* out) {
  if (!ff) {
    std::memcpy(out, plate_angle.data(), plate_angle.size() * sizeof(double));
    return;
  }
  for (std::size_t i = 0; i < plate_angle.size(); ++i) {
    out[2 * i] = ff_bits(std::cos(2.0 * plate_angle[i]));
    out[2 * i + 1] = ff_bits(std::sin(2.0 * plate_angle[i]));
  }
}

}  // namespace pisco::detail::vk
