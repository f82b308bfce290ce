// The vulkan kernel's own source (src/kernel/kernel.glsl with contribution.glsl, disc.glsl, frame.glsl,
// ff.glsl and fp64.glsl, turned into C++ by tests/glsl_to_cpp.cmake), compiled on glm's GLSL types and
// run sample by sample on the very tables the device gets (src/vulkan/tables.hpp), against the float64
// reference and HEALPix's query_disc. Built twice: PISCO_FF=0 runs the float64 kernel, PISCO_FF=1 the
// float-float kernel of devices without shaderFloat64 (docs/vulkan.md, "Devices without float64"). The
// vulkan tests hold the compiled kernels on a device to the same bars.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <set>
#include <cstring>
#include <limits>
#include <numbers>
#include <vector>

#include <glm/glm.hpp>

#include <healpix_base.h>
#include <pointing.h>

#include "backend_fixtures.hpp"
#include "support.hpp"
#include "core/polar_copy.hpp"
#include "core/poles.hpp"
#include "core/prepared.hpp"
#include "pisco/hwp.hpp"
#include "pisco/quaternion.hpp"
#include "vulkan/tables.hpp"

#ifndef PISCO_FF
#error "PISCO_FF must be 0 (the float64 kernel) or 1 (the float-float kernel)"
#endif

// The kernel's world: GLSL's types and built-ins (glm), the bindings, push constants and
// specialization constants it reads, then the kernel itself.
namespace glsl {
// Declarations, not `using namespace glm`: HEALPix has a vec3 of its own in the global namespace.
using glm::dmat4, glm::dvec2, glm::dvec3, glm::dvec4, glm::mat4, glm::uvec2, glm::uvec4, glm::vec2, glm::vec3, glm::vec4;
using glm::acos, glm::atan, glm::clamp, glm::dot, glm::max, glm::min, glm::packDouble2x32, glm::transpose,
    glm::uintBitsToFloat;
using uint = glm::uint;
using std::abs;
using std::floor;
using std::sqrt;
// GLSL's max(double, float): the float converts (the float64 interpolation's max(r2, 0.0f)).
inline double max(double a, float b) { return glm::max(a, double(b)); }

// The push constants as the kernel reads them: interface.h again, with the kernel's float64 type
// (float-float: glm::vec2), filled with the bytes the host pushes.
#undef PISCO_F64
#if PISCO_FF
#define PISCO_F64 glm::vec2
#else
#define PISCO_F64 double
#endif
#undef PISCO_SHADER_INTERFACE_H
#include "interface.h"

struct usamplerBuffer {
  std::vector<uvec4> texels;
};
// Out of range is an error here (std::out_of_range), where a device would read zeros.
inline uvec4 texelFetch(const usamplerBuffer& b, int i) { return b.texels.at(std::size_t(i)); }

inline usamplerBuffer sky, sky_lo, rings, weight_pairs, weights64;
inline std::vector<PISCO_F64> pointing, plate_angle;
inline pisco::detail::vk::PushConstants pc;
inline bool RADIAL = false, FLOAT64 = false, PLATE = false;
inline int PARTS = 1, COLUMNS = 4;
inline uint SKY_FIRST = 0;

#include "kernel_host.hpp"  // src/kernel/kernel.glsl and its includes
}  // namespace glsl

#if PISCO_TEST_CONTRACTED
// rings.glsl compiled with contraction into fused multiply-adds (rings_contracted.cpp).
namespace contracted_rings {
int above(int nside, double z);
double edge_x(double z, double z0, double xa, double cos_rho);
double edge_ysq(double z, double x);
double bound(unsigned count, bool shifted, double phi);
}  // namespace contracted_rings
#endif

namespace {

namespace vk = pisco::detail::vk;
constexpr double pi = std::numbers::pi;
using pisco::deg;
using pisco_test::compare;
using pisco_test::Stats;

// `bytes` of host data as texels.
template <class T>
glsl::usamplerBuffer texels(const std::vector<T>& v) {
  glsl::usamplerBuffer b;
  b.texels.resize((v.size() * sizeof(T) + 15) / 16);
  std::memcpy(b.texels.data(), v.data(), v.size() * sizeof(T));
  return b;
}

template <class To>
std::vector<To> reinterpret(const std::vector<double>& v) {
  static_assert(sizeof(To) == sizeof(double));
  std::vector<To> out(v.size());
  std::memcpy(out.data(), v.data(), v.size() * sizeof(double));
  return out;
}

// The kernel's tables for a sky: what VulkanBackend uploads.
void load_sky(const pisco::Sky& sky, const pisco::detail::PreparedSky& prepared, const vk::KernelMode& mode) {
  const pisco::detail::PixelVectors vectors(sky.nside());
  std::vector<double> xyz(3 * sky.npix());
  vectors.get(0, sky.npix(), xyz.data(), 2);
  std::vector<float> records(8 * sky.npix()), lo(4 * sky.npix());
  vk::pack_sky(sky, mode, 0, sky.npix(), xyz.data(), records.data());
  vk::pack_sky_lo(sky.npix(), xyz.data(), lo.data());
  glsl::sky = texels(records);
  glsl::sky_lo = texels(lo);
  glsl::rings = texels(vk::pack_rings(prepared, mode.boundary, mode.ff));
}

// The TOD of `detector` by the kernel source, sample by sample (one invocation a sample), with the
// pixels each disc counted.
std::vector<double> host_kernel(const pisco::detail::EngineInputs& in, const vk::KernelMode& mode,
                                const vk::Grids& grids, std::size_t detector, const pisco::detail::PointingInput& p,
                                std::vector<std::uint32_t>* counts = nullptr) {
  const pisco::detail::PreparedDetector& det = in.detectors.at(detector);
  glsl::RADIAL = det.radial;
  glsl::FLOAT64 = mode.float64;
  glsl::PLATE = det.plate == pisco::detail::PreparedDetector::Plate::aperture;
  glsl::COLUMNS = int(grids.columns.at(detector));
  glsl::PARTS = 1;
  vk::PushConstants push = vk::push_constants(in, grids, mode, detector, p.quaternions);
  push.sample_count = std::uint32_t(p.size());
  static_assert(sizeof(push) == sizeof(glsl::pc));
  std::memcpy(&glsl::pc, &push, sizeof push);
  std::vector<double> packed(4 * p.size());
  vk::pack_pointing(p, mode.ff, packed.data());
  glsl::pointing = reinterpret<PISCO_F64>(packed);
  if (glsl::PLATE) {
    std::vector<double> plate(p.size() * (mode.ff ? 2 : 1));
    vk::pack_plate(p.plate_angle, mode.ff, plate.data());
    glsl::plate_angle = reinterpret<PISCO_F64>(plate);
  }
  std::vector<double> tod(p.size());
  if (counts) counts->assign(p.size(), 0);
  for (std::uint32_t sid = 0; sid < p.size(); ++sid) {
    glsl::Sums acc;
    std::uint32_t count = 0;
    glsl::convolve_sample(sid, 0, acc, count);
    const PISCO_F64 d = glsl::sample_value(glsl::float_part(acc), acc.s0, acc.n0);
    double v = 0.0;
    std::memcpy(&v, &d, sizeof v);
    tod[sid] = mode.ff ? vk::from_ff_bits(v) : v;
    if (counts) (*counts)[sid] = count;
  }
  return tod;
}

// The backends' scene (mismatched elliptical pair with cross-polar lobes and leakage, radial and 2D
// grids with 2 and 4 weight columns), its detectors off the boresight and behind aperture plates in
// turn, on a sky with and without a monopole, pointing as angles and as quaternions, with integral
// and per-sample normalization: every sample within the B bars of the reference, and every disc
// HEALPix's query_disc.
TEST(KernelOnHost, MatchesTheReferenceAndQueryDisc) {
  const int nside = 32;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const pisco::Pointing p = pisco_test::random_pointing(160, 5);
  std::vector<pisco::Quat> q;
  for (std::size_t i = 0; i < p.size(); ++i) q.push_back(pisco::quat_from_pointing(p.theta[i], p.phi[i], p.psi[i]));
  std::vector<double> h(p.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = 0.113 * double(i);
  const double offsets[][3] = {{2 * deg, -1 * deg, 0.3}, {0, 0, 0}, {-4 * deg, 3 * deg, -1.2}, {0, 6 * deg, 0}, {1 * deg, 0, 2.5}};
  const pisco_test::Scene plain = pisco_test::backend_scene(nside, 0.0);
  int checked = 0;
  for (const double monopole : {0.0, 2.725})
    for (const bool plates : {false, true})
      for (const auto norm : {pisco::Normalization::integral, pisco::Normalization::per_sample}) {
        if (plates && norm == pisco::Normalization::per_sample) continue;
        const pisco_test::Scene s = pisco_test::backend_scene(nside, monopole);
        std::vector<pisco::Detector> dets = s.focal_plane.detectors();
        for (std::size_t i = 0; i < dets.size(); ++i) {
          dets[i].set_offset(offsets[i][0], offsets[i][1], offsets[i][2]);
          if (plates) dets[i].hwp = pisco::HalfWavePlate{pisco_test::generic_plate(), pisco::HwpPlacement::aperture, 0.2 * double(i)};
        }
        const pisco::FocalPlane fp(dets);
        pisco::EngineOptions o;
        o.quadrature = pisco::Quadrature::plain;  // the kernel itself, against the plain reference
        o.normalization = norm;
        pisco::Engine cpu(s.sky, s.beams, fp, o);
        pisco::Engine cpu_plain(plain.sky, plain.beams, fp, o);  // the anisotropies' scale
        const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, fp, norm);
        ASSERT_EQ(in.detectors.size(), fp.size());
        const vk::KernelMode mode = vk::kernel_mode(in, s.sky, PISCO_FF != 0);
        ASSERT_EQ(mode.float64, monopole != 0.0 || norm == pisco::Normalization::per_sample);
        const vk::Grids grids = vk::pack_grids(in, mode);
        load_sky(s.sky, in.sky, mode);
        glsl::weight_pairs = texels(grids.w32);
        glsl::weights64 = texels(grids.w64);
        for (const bool quaternions : {false, true})
          for (std::size_t d = 0; d < fp.size(); ++d) {
            pisco::detail::PointingInput input;
            input.quaternions = quaternions;
            input.angles = p;
            input.quats = pisco::QuatPointingView{q};
            std::vector<double> theta(h.size());  // the plate's angle from the detector's axis, as the engine gives it
            for (std::size_t i = 0; i < h.size(); ++i) theta[i] = h[i] - in.detectors[d].plate_gamma;
            if (plates) input.plate_angle = theta;
            std::vector<std::uint32_t> counts;
            const std::vector<double> got = host_kernel(in, mode, grids, d, input, &counts);
            std::vector<double> ref(p.size()), scale(p.size());
            if (quaternions) {
              cpu.convolve(d, pisco::QuatPointingView{q}, ref, false, plates ? h : std::vector<double>{});
              cpu_plain.convolve(d, pisco::QuatPointingView{q}, scale, false, plates ? h : std::vector<double>{});
            } else {
              cpu.convolve(d, p, ref, false, plates ? h : std::vector<double>{});
              cpu_plain.convolve(d, p, scale, false, plates ? h : std::vector<double>{});
            }
            const Stats st = compare(ref, got);
            const double rms = compare(scale, scale).rms_ref;
            const std::string what = fp[d].name + (monopole ? ", monopole" : "") + (plates ? ", plate" : "") +
                                     (quaternions ? ", quaternions" : ", angles") +
                                     (norm == pisco::Normalization::per_sample ? ", per-sample" : "");
            EXPECT_EQ(st.non_finite, 0u) << what;
            EXPECT_LE(st.rms_err, 1e-5 * rms) << what;
            EXPECT_LE(st.max_err, 1e-4 * rms) << what;
            if (d == 0) std::cout << what << ": relative rms error " << st.rms_err / rms << "\n";
            // The disc of each sample: the offset detector's own line of sight.
            pisco::Pointing los;
            pisco::detector_pointing(p, fp[d].offset, los);
            std::vector<int> pix;
            for (std::size_t i = 0; i < p.size(); ++i) {
              base.query_disc(pointing(los.theta[i], los.phi[i]), std::acos(in.detectors[d].cos_rho_max), pix);
              EXPECT_EQ(counts[i], pix.size()) << what << ", sample " << i;
            }
            ++checked;
          }
      }
  EXPECT_EQ(checked, 2 * 3 * 2 * 5);
}

// The polar copy's band as the backend binds it (its tables from pixel SKY_FIRST): the kernel reads
// nothing outside it (texelFetch here throws out of range) and sums what it would sum from a whole-sky
// table holding the same copy, bit for bit, for samples near both poles turned onto it as the engine
// turns them, on the float64 path (a monopole) and without.
TEST(KernelOnHost, ThePolarCopysBandReadsAsTheWholeCopy) {
  const int nside = 32;
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  pisco::Pointing p;
  for (int i = 0; i < 600; ++i) {
    const double t = 20.0 * deg * std::sqrt(u(rng));  // beyond the cut: its edge reached
    p.theta.push_back(i % 2 ? t : pi - t);
    p.phi.push_back(2 * pi * u(rng));
    p.psi.push_back(2 * pi * u(rng));
  }
  int checked = 0;
  for (const double monopole : {0.0, 2.725}) {
    const pisco_test::Scene s = pisco_test::backend_scene(nside, monopole);
    std::vector<pisco::Detector> dets = s.focal_plane.detectors();
    for (std::size_t i = 0; i < dets.size(); ++i) dets[i].set_offset(1.5 * deg * double(i % 3), -1.0 * deg, 0.4 * double(i));
    const pisco::FocalPlane fp(dets);
    const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, fp, pisco::Normalization::integral);
    double reach = 0.0;
    for (const auto& d : in.detectors)
      reach = std::max(reach, pisco::detail::polar_cut(d.rho_max, nside) + d.rho_max + 2.0 * std::sqrt(pi / 3) / nside);
    const pisco::detail::SkyBand band = pisco::detail::polar_sky(s.sky, false, reach);
    const vk::KernelMode mode = vk::kernel_mode(in, s.sky, PISCO_FF != 0);
    const vk::Grids grids = vk::pack_grids(in, mode);
    glsl::weight_pairs = texels(grids.w32);
    glsl::weights64 = texels(grids.w64);
    glsl::rings = texels(vk::pack_rings(in.sky, mode.boundary, mode.ff));
    // The tables of pixels [first, first + count) of the maps (whose values start at maps_first).
    const auto tables = [&](const std::array<std::span<const double>, 4>& maps, std::size_t maps_first,
                            std::size_t first, std::size_t count) {
      const pisco::detail::PixelVectors vectors(nside);
      std::vector<double> xyz(3 * count);
      vectors.get(first, count, xyz.data(), 2);
      std::vector<float> records(8 * count), lo(4 * count);
      vk::pack_sky(maps, maps_first, mode, first, count, xyz.data(), records.data());
      vk::pack_sky_lo(count, xyz.data(), lo.data());
      glsl::sky = texels(records);
      glsl::sky_lo = texels(lo);
      glsl::SKY_FIRST = std::uint32_t(first);
    };
    pisco::Sky copy(nside);  // the same copy in a whole sky
    for (int c = 0; c < 4; ++c)
      std::copy(band.maps[std::size_t(c)].begin(), band.maps[std::size_t(c)].end(),
                copy.stokes(pisco::StokesIndex(c)).begin() + std::ptrdiff_t(band.first));
    for (std::size_t d = 0; d < fp.size(); ++d) {
      pisco::detail::PointingInput input;
      input.angles = p;
      pisco::detail::PolarSamples polar;
      ASSERT_TRUE(pisco::detail::find_polar_samples(input, in.detectors[d].offset, pi,
                                                    pisco::detail::polar_cut(in.detectors[d].rho_max, nside), polar));
      const pisco::detail::PointingInput turned = polar.input();
      tables({band.maps[0], band.maps[1], band.maps[2], band.maps[3]}, band.first, band.first, band.size());
      const std::vector<double> from_band = host_kernel(in, mode, grids, d, turned);
      tables({copy.I(), copy.Q(), copy.U(), copy.V()}, 0, 0, copy.npix());
      const std::vector<double> from_whole = host_kernel(in, mode, grids, d, turned);
      ASSERT_EQ(from_band, from_whole) << fp[d].name << (monopole ? ", monopole" : "");
      EXPECT_GT(turned.size(), 100u);
      ++checked;
    }
  }
  glsl::SKY_FIRST = 0;
  EXPECT_EQ(checked, 10);
}

// The disc walk alone (the kernel's ring bounds and ranges) against query_disc, pixel for pixel, from
// NSIDE 4 to 512, radii 0.5 to 60 deg, on and near the poles and across phi = 0.
TEST(KernelOnHost, DiscsArePixelForPixelQueryDisc) {
  std::size_t discs = 0;
  for (int nside : {4, 64, 512}) {
    pisco::Sky sky(nside);
    vk::KernelMode mode;
    mode.ff = PISCO_FF != 0;
    load_sky(sky, pisco::detail::prepare_sky(sky), mode);
    const Healpix_Base base(nside, RING, SET_NSIDE);
    pisco::Pointing p = pisco_test::random_pointing(nside == 512 ? 150 : 400, 7 + std::uint64_t(nside));
    // On the poles and beside them. (Not closer than 1e-6: at 1e-9, cos(theta) rounds to 1 and
    // query_disc takes the axis for the pole, where a ring lying on the disc's edge falls out whole.)
    for (double t : {0.0, 1e-6, pi / 2, pi - 1e-6, pi}) p.push_back(t, 0.0, 0.0);
    for (double rho_deg : {0.5, 5.0, 20.0, 60.0}) {
      if (nside == 512 && rho_deg > 5) continue;  // keeps the test short
      const double rho = rho_deg * deg;
      for (std::size_t i = 0; i < p.size(); ++i) {
        std::vector<int> want;
        base.query_disc(pointing(p.theta[i], p.phi[i]), rho, want);
        std::sort(want.begin(), want.end());
        std::vector<int> got;
        auto add = [&](std::uint32_t b, std::uint32_t l) {
          for (std::uint32_t k = 0; k < l; ++k) got.push_back(int(b + k));
        };
#if PISCO_FF
        const pisco::Quat q = pisco::quat_from_pointing(p.theta[i], p.phi[i], p.psi[i]);
        const auto ff = [](double x) { return glm::vec2(float(x), float(x - double(float(x)))); };
        glsl::ffquat b{ff(q.x), ff(q.y), ff(q.z), ff(q.w)};
        glsl::ff3 tp, pp, axis;
        glsl::ff_sample_frame(false, b, b, tp, pp, axis);
        const glm::vec2 sin_theta0 = glsl::ff_sqrt(glsl::ff_add(glsl::ff_mul(axis.x, axis.x), glsl::ff_mul(axis.y, axis.y)));
        float phi0 = std::atan2(axis.y.x, axis.x.x);
        if (phi0 < 0.0f) phi0 += 6.28318530717958647693f;
        int first = 0, last = 0;
        glsl::ff_disc_rings(nside, axis.z, sin_theta0, ff(std::cos(rho)), first, last);
        for (int iz = first; iz <= last; ++iz) {
          std::uint32_t b0, l0, b1, l1;
          glsl::ff_ring_ranges(glsl::ring_entry(iz), axis, sin_theta0, phi0, ff(std::cos(rho)), b0, l0, b1, l1);
          add(b0, l0);
          add(b1, l1);
        }
#else
        const double theta = p.theta[i], phi = pisco::detail::wrap_phi(p.phi[i]);
        const double z0 = glsl::pisco_cos(theta), xa = 1.0 / std::sqrt((1.0 - z0) * (1.0 + z0));
        int first = 0, last = 0, irmin = 0, irmax = 0;
        glsl::disc_rings(nside, theta, rho, first, last, irmin, irmax);
        for (int iz = first; iz <= last; ++iz) {
          const glsl::RingEntry ring = glsl::ring_entry(iz);
          if (iz < irmin || iz > irmax) {
            add(ring.first, ring.count);
            continue;
          }
          std::uint32_t b0, l0, b1, l1;
          glsl::ring_ranges(ring, z0, xa, phi, std::cos(rho), b0, l0, b1, l1);
          add(b0, l0);
          add(b1, l1);
        }
#endif
        std::sort(got.begin(), got.end());
        EXPECT_EQ(got, want) << "NSIDE " << nside << ", rho " << rho_deg << " deg, theta " << p.theta[i] << ", phi "
                             << p.phi[i];
        ++discs;
      }
    }
  }
  std::cout << discs << " discs, each HEALPix's query_disc\n";
}

// The arithmetic a device gets: float-float where it lacks float64 or where asked for; float64 asked
// of a device without it is an error naming the device, and an unknown name one naming the choices.
TEST(KernelArithmetic, ChosenByTheDeviceOrAskedFor) {
  using vk::arithmetic_from;
  EXPECT_FALSE(vk::use_float_float(true, "gpu", arithmetic_from("auto")));
  EXPECT_TRUE(vk::use_float_float(false, "gpu", arithmetic_from("auto")));
  EXPECT_TRUE(vk::use_float_float(true, "gpu", arithmetic_from("float-float")));
  EXPECT_TRUE(vk::use_float_float(false, "gpu", arithmetic_from("float-float")));
  EXPECT_FALSE(vk::use_float_float(true, "gpu", arithmetic_from("float64")));
  pisco_test::expect_error([] { vk::use_float_float(false, "Apple M2", vk::Arithmetic::float64); },
                           "Apple M2 lacks shaderFloat64");
  try {
    arithmetic_from("double");
    ADD_FAILURE() << "arithmetic_from(\"double\") did not throw";
  } catch (const pisco::Error& e) {
    EXPECT_EQ(e.named(), "arithmetic: expected \"auto\", \"float64\" or \"float-float\", got \"double\"");
  }
  for (const auto a : {vk::Arithmetic::automatic, vk::Arithmetic::float64, vk::Arithmetic::float_float})
    EXPECT_EQ(arithmetic_from(vk::arithmetic_name(a)), a);
}

// One text for the maths (src/kernel/pixel.glsl, plate.glsl, rings.glsl): every shared function, run through
// the GLSL-as-C++ build (glm's types, as the shaders see it) and through the C++ template build the
// reference, the simd backend and the CUDA kernels use (float here, as on the devices), on random
// inputs: the same bits.
template <class T>
std::uint64_t bits(T v) {
  if constexpr (sizeof(T) == 4)
    return std::bit_cast<std::uint32_t>(v);
  else
    return std::bit_cast<std::uint64_t>(v);
}

TEST(SharedMaths, PixelFunctionsGiveTheSameBitsInBothBuilds) {
  namespace d = pisco::detail;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  auto unit = [&] {
    glm::vec3 v(u(rng), u(rng), u(rng));
    return v / std::sqrt(glm::dot(v, v));
  };
  // A beam grid of n x n nodes with 4 weights each and its 2 n^2 records of edge curvatures
  // (src/kernel/grid_curvature.hpp; random here like the nodes), as the shaders' texels (COLUMNS 4 and 2)
  // and as the reference's array.
  const int n = 9;
  std::vector<float> nodes(4 * 3 * n * n + 4);
  for (float& w : nodes) w = u(rng);
  std::vector<float> two = nodes;  // COLUMNS 2: w_U = w_V = 0
  for (std::size_t k = 0; k + 3 < two.size(); k += 4) two[k + 2] = two[k + 3] = 0.0f;
  std::vector<float> pairs4, pairs2;
  for (int k = 0; k < 3 * n * n; ++k) {
    for (int m = 0; m < 8; ++m) pairs4.push_back(nodes[4 * k + m]);
    for (int m : {0, 1, 4, 5}) pairs2.push_back(nodes[4 * k + m]);
  }
  const float a = 0.05f, inv_step = float(n - 1) / (2 * a);
  glsl::Grid g{};
  g.offset = 0;
  g.n = n;
  g.a = a;
  g.inv_step = inv_step;
  std::size_t checked = 0;
  for (int t = 0; t < 20000; ++t) {
    // Frame and pixel: an antenna basis from random angles, a pixel within ~0.07 rad of p'.
    const float th = std::acos(u(rng)), ph = 3.14159f * u(rng), ps = 3.14159f * u(rng), ze = 3.14159f * u(rng);
    const d::SampleFrame<float> fc = d::make_frame<float>(std::cos(th), std::sin(th), std::cos(ph), std::sin(ph),
                                                          std::cos(ps), std::sin(ps), std::cos(ze), std::sin(ze));
    glsl::SampleFrame fg;
    fg.theta_p = glsl::vec3(fc.theta_p.x, fc.theta_p.y, fc.theta_p.z);
    fg.phi_p = glsl::vec3(fc.phi_p.x, fc.phi_p.y, fc.phi_p.z);
    fg.p = glsl::vec3(fc.p.x, fc.p.y, fc.p.z);
    fg.e_c = glsl::vec3(fc.e_c.x, fc.e_c.y, fc.e_c.z);
    glm::vec3 kg = fg.p + 0.07f * unit();
    kg /= std::sqrt(glm::dot(kg, kg));
    const d::Vec3<float> kc{kg.x, kg.y, kg.z};
    const glsl::PixelGeometry pg = glsl::pixel_geometry(fg, kg);
    const d::PixelGeometry<float> pc = d::pixel_geometry(fc, kc);
    for (auto [x, y] : {std::pair{pg.x, pc.x}, {pg.y, pc.y}, {pg.z, pc.z}, {pg.r2, pc.r2}, {pg.cos2chi, pc.cos2chi},
                        {pg.sin2chi, pc.sin2chi}})
      ASSERT_EQ(bits(x), bits(y)) << "pixel_geometry, case " << t;
    // Interpolation on the grid (in and out of it) and radially, with 4 and 2 columns.
    for (const int columns : {4, 2}) {
      glsl::COLUMNS = columns;
      glsl::weight_pairs = texels(columns == 4 ? pairs4 : pairs2);
      const d::ArrayGrid<float> gc{columns == 4 ? nodes.data() : two.data(), n, a, inv_step};
      const glm::vec4 wg = glsl::interpolate_weights(g, pg.x, pg.y);
      const d::Vec4<float> wc = d::interpolate_weights(gc, pc.x, pc.y);
      const glm::vec4 rg = glsl::interpolate_radial(g, pg.r2);
      const d::Vec4<float> rc = d::interpolate_radial(gc, pc.r2);
      for (int m = 0; m < 4; ++m) {
        const float cm[4] = {wc.x, wc.y, wc.z, wc.w}, rm[4] = {rc.x, rc.y, rc.z, rc.w};
        ASSERT_EQ(bits(wg[m]), bits(cm[m])) << "interpolate_weights, case " << t << ", columns " << columns;
        ASSERT_EQ(bits(rg[m]), bits(rm[m])) << "interpolate_radial, case " << t << ", columns " << columns;
      }
    }
    // Stokes response, plate weights, a Kahan step.
    const glm::vec4 w(u(rng), u(rng), u(rng), u(rng)), S(u(rng), u(rng), u(rng), u(rng));
    const d::Vec4<float> wc{w.x, w.y, w.z, w.w}, Sc{S.x, S.y, S.z, S.w};
    ASSERT_EQ(bits(glsl::stokes_response(w, pg.cos2chi, pg.sin2chi, S)),
              bits(d::stokes_response(wc, pc.cos2chi, pc.sin2chi, Sc)));
    ASSERT_EQ(bits(glsl::stokes_response_iq(w, pg.cos2chi, pg.sin2chi, S)),
              bits(d::stokes_response_iq(wc, pc.cos2chi, pc.sin2chi, Sc)));
    {  // the adjoint's scatter weights: the same bits, and the transpose of the response
      const glm::vec4 ag = glsl::stokes_adjoint(w, pg.cos2chi, pg.sin2chi);
      const d::Vec4<float> ac = d::stokes_adjoint(wc, pc.cos2chi, pc.sin2chi);
      const float am[4] = {ac.x, ac.y, ac.z, ac.w};
      for (int m = 0; m < 4; ++m) ASSERT_EQ(bits(ag[m]), bits(am[m])) << "stokes_adjoint, case " << t;
      // Without U, V weights: stokes_adjoint_iq gives stokes_adjoint's I, Q, U values.
      const glm::vec4 w2(w.x, w.y, 0.0f, 0.0f);
      const d::Vec4<float> wc2{w.x, w.y, 0.0f, 0.0f};
      const glm::vec3 ig = glsl::stokes_adjoint_iq(w2, pg.cos2chi, pg.sin2chi);
      const d::Vec3<float> ic = d::stokes_adjoint_iq(wc2, pc.cos2chi, pc.sin2chi);
      const d::Vec4<float> full = d::stokes_adjoint(wc2, pc.cos2chi, pc.sin2chi);
      const float im[3] = {ic.x, ic.y, ic.z}, fm[3] = {full.x, full.y, full.z};
      for (int m = 0; m < 3; ++m) {
        ASSERT_EQ(bits(ig[m]), bits(im[m])) << "stokes_adjoint_iq, case " << t;
        ASSERT_EQ(im[m], fm[m]) << "stokes_adjoint_iq against stokes_adjoint, case " << t;
      }
      const d::Vec4<double> wd{w.x, w.y, w.z, w.w}, Sd{S.x, S.y, S.z, S.w};
      const d::Vec4<double> ad = d::stokes_adjoint(wd, double(pc.cos2chi), double(pc.sin2chi));
      const double forward = d::stokes_response(wd, double(pc.cos2chi), double(pc.sin2chi), Sd);
      ASSERT_NEAR(ad.x * Sd.x + ad.y * Sd.y + ad.z * Sd.z + ad.w * Sd.w, forward, 1e-14) << "case " << t;
    }
    glm::vec4 col[4];
    d::Vec4<float> colc[4];
    for (int c = 0; c < 4; ++c) {
      col[c] = glm::vec4(u(rng), u(rng), u(rng), u(rng));
      colc[c] = {col[c].x, col[c].y, col[c].z, col[c].w};
    }
    const glm::vec4 vg = glsl::effective_weights(w, col[0], col[1], col[2], col[3]);
    const d::Vec4<float> vc = d::effective_weights(wc, colc[0], colc[1], colc[2], colc[3]);
    ASSERT_EQ(bits(vg.x), bits(vc.x));
    ASSERT_EQ(bits(vg.w), bits(vc.w));
    float sg = u(rng), cg = 1e-8f * u(rng), sc = sg, cc = cg;
    const float value = 1e-3f * u(rng);
    glsl::kahan_add(sg, cg, value);
    d::kahan_add(sc, cc, value);
    ASSERT_EQ(bits(sg), bits(sc));
    ASSERT_EQ(bits(cg), bits(cc));
#if !PISCO_FF
    const double dd = u(rng), s0 = u(rng), n0 = u(rng) + 0.5, mono = 2.725;
    for (const bool per_sample : {false, true})
      ASSERT_EQ(bits(glsl::finish_sample(dd, mono, s0, n0, per_sample)),
                bits(d::finish_sample(dd, mono, s0, n0, per_sample)));
#endif
    ++checked;
  }
  std::cout << checked << " random cases, every value the same bits in both builds\n";
}

// A plate at an angle (src/kernel/plate.glsl): M(theta)'s rows in both builds, the same bits and the
// plain matrix product R(-theta) M0 R(theta), and the monopole's weight behind it.
TEST(SharedMaths, PlateRowsGiveTheSameBitsInBothBuilds) {
  namespace d = pisco::detail;
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int t = 0; t < 20000; ++t) {
    const float th = std::acos(u(rng));
#if PISCO_FF
    using PV = glm::vec4;
    using PR = float;
#else
    using PV = glm::dvec4;
    using PR = double;
#endif
    PV r[4], m[4];
    d::Vec4<PR> rc[4], mc[4];
    for (int i = 0; i < 4; ++i) {
      r[i] = PV(u(rng), u(rng), u(rng), u(rng));
      rc[i] = {r[i].x, r[i].y, r[i].z, r[i].w};
    }
    const PR c = std::cos(PR(2) * PR(th)), s = std::sin(PR(2) * PR(th));
    glsl::plate_rows(r[0], r[1], r[2], r[3], c, s, m[0], m[1], m[2], m[3]);
    d::plate_rows(rc[0], rc[1], rc[2], rc[3], c, s, mc[0], mc[1], mc[2], mc[3]);
    // R(-theta) M0 R(theta) as a plain matrix product, in float64.
    const double R[4][4] = {{1, 0, 0, 0}, {0, double(c), double(s), 0}, {0, -double(s), double(c), 0}, {0, 0, 0, 1}};
    for (int i = 0; i < 4; ++i) {
      const PR got[4] = {mc[i].x, mc[i].y, mc[i].z, mc[i].w};
      for (int j = 0; j < 4; ++j) {
        ASSERT_EQ(bits(m[i][j]), bits(got[j])) << "plate_rows, case " << t;
        double want = 0;
        for (int k = 0; k < 4; ++k)
          for (int l = 0; l < 4; ++l) want += R[k][i] * double(r[k][l]) * R[l][j];
        ASSERT_NEAR(double(got[j]), want, sizeof(PR) == 4 ? 1e-6 : 1e-15) << "plate_rows, case " << t;
      }
    }
    ASSERT_EQ(bits(glsl::plate_monopole_weight(m[1], r[2])), bits(d::plate_monopole_weight(mc[1], rc[2])));
  }
}

// The rings about the caps' edges (src/kernel/cap_boundary.hpp), pixel by pixel around them, in both
// builds, against HEALPix's own ring numbers; and CapBoundary's weights by ring.
TEST(SharedMaths, CapBoundaryRingsInBothBuilds) {
  namespace d = pisco::detail;
  for (const unsigned nside : {1u, 2u, 3u, 16u, 1024u, 8192u}) {
    ASSERT_EQ(glsl::cap_boundary_north(nside), d::cap_boundary_north(nside));
    ASSERT_EQ(glsl::cap_boundary_south(nside), d::cap_boundary_south(nside));
    const T_Healpix_Base<int64> base(int(nside), RING, SET_NSIDE);
    const d::CapBoundary b = d::cap_boundary(int(nside), pisco::Quadrature::corrected);
    const auto [north_run, south_run] = d::cap_boundary_runs(int(nside));
    const unsigned north = d::cap_boundary_north(nside), south = d::cap_boundary_south(nside);
    std::set<unsigned> pixels;  // two rings and more on either side of each edge
    for (const unsigned first : {north, south})
      for (unsigned p = first > 8 * nside ? first - 8 * nside : 0; p < std::min<std::size_t>(first + 16 * nside, base.Npix()); ++p)
        pixels.insert(p);
    std::size_t weighted = 0;
    for (const unsigned p : pixels) {
        const unsigned ring = d::cap_boundary_ring(p, nside);
        ASSERT_EQ(glsl::cap_boundary_ring(p, nside), ring) << "NSIDE " << nside << ", pixel " << p;
        const long t = long(base.pix2ring(p));  // 1-based
        const long n = long(nside);
        const unsigned want = (t == n || t == 3 * n) ? d::CAP_EDGE_RING
                              : (t == n + 1 || t == 3 * n - 1) ? d::CAP_BELT_RING
                              : (t == n - 1 || t == 3 * n + 1) ? d::CAP_LAST_RING : 0u;
        ASSERT_EQ(ring, want) << "NSIDE " << nside << ", pixel " << p << " on ring " << t;
        const bool in_runs = (p >= north_run.first && p < north_run.second) || (p >= south_run.first && p < south_run.second);
        ASSERT_EQ(in_runs, ring != 0u) << "NSIDE " << nside << ", pixel " << p;
        const double c = ring == d::CAP_EDGE_RING ? d::cap_edge_c0 : d::cap_edge_c1;
        const double spacing = ring == d::CAP_LAST_RING ? double(n - 1) : double(n);
        ASSERT_EQ(b.at(p), ring == 0u ? 1.0 : 1.0 - c / spacing) << "NSIDE " << nside << ", pixel " << p;
        ASSERT_EQ(d::cap_boundary(int(nside), pisco::Quadrature::plain).at(p), 1.0);
        weighted += ring != 0u;
      }
    // Six rings, of 4 NSIDE pixels but the caps' last two, of 4 (NSIDE - 1); five at NSIDE 1.
    EXPECT_EQ(weighted, nside == 1 ? 12u : 24u * nside - 8u) << "NSIDE " << nside;
  }
  // The uniform sky's term: c_0 + 2 c_1 = 1/12.
  EXPECT_NEAR(d::cap_edge_c0 + 2 * d::cap_edge_c1, 1.0 / 12.0, 1e-17);
}

// The adjoints' fixed point (src/kernel/fixed_point.glsl, the vulkan and CUDA adjoints' text): round(v g)
// to nearest, ties to even, as llrint in the default rounding mode; g^2 for the diagonal; zero
// where the weight is zero.
TEST(SharedMaths, FixedPointRoundsToNearestEven) {
  namespace d = pisco::detail;
  for (const auto& [v, want] : {std::pair{2.5, 2LL}, {3.5, 4LL}, {-2.5, -2LL}, {-3.5, -4LL}, {0.49999999999999994, 0LL},
                                {4503599627370495.5, 4503599627370496LL}, {-1e18, -1000000000000000000LL}})
    EXPECT_EQ(d::fixed_point(v, 1.0f), want) << v;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int t = 0; t < 100000; ++t) {
    const double v = std::ldexp(u(rng), 40);
    const float g = float(u(rng));
    ASSERT_EQ(d::fixed_point(v, g), std::llrint(v * double(g)));
    ASSERT_EQ(d::fixed_share(v, g, false), std::llrint(v * double(g)));
    ASSERT_EQ(d::fixed_share(v, g, true), std::llrint(v * double(g * g)));
  }
  EXPECT_EQ(d::fixed_share(std::numeric_limits<double>::infinity(), 0.0f, false), 0);
  EXPECT_EQ(d::fixed_share(std::numeric_limits<double>::quiet_NaN(), -0.0f, true), 0);
}

#if !PISCO_FF
// The ring arithmetic at every ring's own z and its neighbours (where ring_above's floor decides),
// and at random discs: the GLSL-as-C++ build and the reference's give the same bits; so does a build
// with contraction into fused multiply-adds (what a shader compiler may do where `precise` does not
// forbid it), which an unprotected product (2 - 1.5 z instead of 2 - mul_rn(1.5, z)) fails.
TEST(SharedMaths, RingArithmeticGivesTheSameBitsInEveryBuild) {
  namespace d = pisco::detail;
#if PISCO_TEST_CONTRACTED
  const bool fused = __builtin_cpu_supports("fma");
#else
  const bool fused = false;
#endif
  std::size_t checked = 0, fused_checked = 0;
  for (int nside = 1; nside <= 8192; nside *= 2) {
    for (int ring = 1; ring < 4 * nside; ++ring) {
      const double z0 = d::ring_z(nside, ring);
      for (const double z : {z0, std::nextafter(z0, 2.0), std::nextafter(z0, -2.0)}) {
        const int want = int(d::ring_above(nside, z));
        ASSERT_EQ(glsl::ring_above(nside, z), want) << "NSIDE " << nside << ", ring " << ring << ", z " << z;
#if PISCO_TEST_CONTRACTED
        if (fused) {
          ASSERT_EQ(contracted_rings::above(nside, z), want)
              << "fused: NSIDE " << nside << ", ring " << ring << ", z " << z;
          ++fused_checked;
        }
#endif
        ++checked;
      }
    }
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int t = 0; t < 100000; ++t) {
    const double z = u(rng), z0 = u(rng), xa = 1.0 / std::sqrt(1 - z0 * z0), cos_rho = 0.5 * (u(rng) + 1);
    const double phi = 7 * u(rng);
    const unsigned count = 4u << (t % 12);
    const double x = d::ring_edge_x(z, z0, xa, cos_rho);
    ASSERT_EQ(bits(glsl::ring_edge_x(z, z0, xa, cos_rho)), bits(x));
    ASSERT_EQ(bits(glsl::ring_edge_ysq(z, x)), bits(d::ring_edge_ysq(z, x)));
    ASSERT_EQ(bits(glsl::ring_bound(count, t % 2 == 1, phi)), bits(d::ring_bound(count, t % 2 == 1, phi)));
    {  // a ring's pixels within dphi of phi, as index bounds and as ranges, in both builds; the ranges
       // against the pixels taken one by one
      const double phi0 = std::numbers::pi * (u(rng) + 1), dphi = 0.5 * std::numbers::pi * (u(rng) + 1);
      const bool shifted = t % 2 == 1;
      int lo, hi;
      std::int64_t lo_c, hi_c;
      glsl::ring_pixel_span(count, shifted, phi0, dphi, lo, hi);
      d::ring_pixel_span(count, shifted, phi0, dphi, lo_c, hi_c);
      ASSERT_TRUE(lo == lo_c && hi == hi_c) << "ring_pixel_span, case " << t;
      const unsigned first = 1000u + unsigned(t);
      unsigned b[4], l[4];
      const int n = glsl::ring_pixel_ranges(first, count, lo, hi, b[0], l[0], b[1], l[1]);
      ASSERT_EQ(d::ring_pixel_ranges(first, count, lo_c, hi_c, b[2], l[2], b[3], l[3]), n) << "case " << t;
      for (int k = 0; k < 2; ++k) ASSERT_TRUE(b[k] == b[2 + k] && l[k] == l[2 + k]) << "ring_pixel_ranges, case " << t;
      if (count <= 512) {
        std::vector<unsigned> want, got;
        for (int j = lo; j <= hi; ++j) want.push_back(first + unsigned(((j % int(count)) + int(count)) % int(count)));
        for (int k = 0; k < n; ++k)
          for (unsigned q = 0; q < l[k]; ++q) got.push_back(b[k] + q);
        std::sort(want.begin(), want.end());
        std::sort(got.begin(), got.end());
        ASSERT_EQ(got, want) << "ring_pixel_ranges, case " << t << ": pixels " << lo << " ... " << hi << " of " << count;
      }
    }
#if PISCO_TEST_CONTRACTED
    if (fused) {
      ASSERT_EQ(bits(contracted_rings::edge_x(z, z0, xa, cos_rho)), bits(x));
      ASSERT_EQ(bits(contracted_rings::edge_ysq(z, x)), bits(d::ring_edge_ysq(z, x)));
      ASSERT_EQ(bits(contracted_rings::bound(count, t % 2 == 1, phi)), bits(d::ring_bound(count, t % 2 == 1, phi)));
    }
#endif
    ++checked;
  }
  std::cout << checked << " ring values the same in the GLSL and C++ builds; " << fused_checked
            << " also with fused multiply-adds" << (fused ? "" : " (none: this build or processor has no FMA)")
            << "\n";
}
#endif

}  // namespace
