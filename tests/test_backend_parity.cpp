// Backend parity (docs/validation.md, "B"): a float32 device backend against the float64 reference, built once per
// backend (PISCO_TEST_BACKEND = "vulkan" or "cuda") so that each carries its own ctest label. Every
// test is skipped, with the reason printed, where the backend has no device on this machine.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <random>

#include <healpix_base.h>
#include <pointing.h>

#include "backend_fixtures.hpp"
#include "support.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/hwp.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/scan.hpp"
#include "pisco/units.hpp"

#ifndef PISCO_TEST_BACKEND
#error "PISCO_TEST_BACKEND must name the backend under test"
#endif

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;
const std::string backend = PISCO_TEST_BACKEND;

using pisco_test::cmb_like_sky;
using pisco_test::compare;
using pisco_test::random_pointing;
using pisco_test::Stats;

#define SKIP_WITHOUT_DEVICE()                                                   \
  do {                                                                          \
    const std::string why = pisco_test::backend_unavailable(backend);           \
    if (!why.empty()) GTEST_SKIP() << backend << " backend unavailable: " << why; \
  } while (0)

using pisco_test::Scene;

Scene scene(int nside, double monopole = 0.0) { return pisco_test::backend_scene(nside, monopole); }

std::vector<double> run(pisco::Engine& engine, std::size_t detector, const pisco::Pointing& p) {
  std::vector<double> tod(p.size(), std::numeric_limits<double>::quiet_NaN());  // poisoned
  engine.convolve(detector, p, tod);
  return tod;
}

pisco::EngineOptions options(const std::string& name, std::size_t chunk = 0,
                             pisco::Normalization n = pisco::Normalization::integral) {
  pisco::EngineOptions o;
  o.backend = name;
  pisco_test::set_taken(o, "chunk_samples", (long long)chunk);
  o.normalization = n;
#ifdef PISCO_TEST_ARITHMETIC
  pisco_test::set_taken(o, "arithmetic", std::string(PISCO_TEST_ARITHMETIC));  // the vulkan kernel without float64, on any device
#endif
  return o;
}

// B1: relative RMS <= 1e-5 and max error <= 1e-4 of the RMS, every sample written, the same disc.
TEST(BackendParity, RandomSkyBeamsAndPointingMatchTheReference) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(64);
  const pisco::Pointing p = random_pointing(3000, 11);
  pisco::Engine cpu(s.sky, s.beams, s.focal_plane, options("cpu"));
  pisco::Engine dev(s.sky, s.beams, s.focal_plane, options(backend));
  std::cout << "device: " << dev.device_name() << "\n";
#ifdef PISCO_TEST_ARITHMETIC
  EXPECT_TRUE(pisco_test::contains(dev.device_name(), "float-float")) << dev.device_name();
#endif
  if (const char* v = std::getenv("PISCO_VK_VALIDATION"); backend == "vulkan" && v && std::string(v) == "1")
    EXPECT_TRUE(pisco_test::contains(dev.device_name(), "validation layer")) << "the validation layer is not active";
  for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
    const Stats st = compare(run(cpu, d, p), run(dev, d, p));
    std::cout << s.focal_plane[d].name << ": rms " << st.rms_ref << ", relative rms error "
              << st.rms_err / st.rms_ref << ", max error / rms " << st.max_err / st.rms_ref << "\n";
    EXPECT_EQ(st.non_finite, 0u) << "samples left unwritten";
    EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref) << s.focal_plane[d].name;
    EXPECT_LE(st.max_err, 1e-4 * st.rms_ref) << s.focal_plane[d].name;
  }
  EXPECT_DOUBLE_EQ(dev.mean_disc_pixels(), cpu.mean_disc_pixels()) << "the device's discs differ";
}

TEST(BackendParity, PerSampleNormalizationMatchesTheReference) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(64);
  const pisco::Pointing p = random_pointing(1000, 12);
  pisco::Engine cpu(s.sky, s.beams, s.focal_plane, options("cpu", 0, pisco::Normalization::per_sample));
  pisco::Engine dev(s.sky, s.beams, s.focal_plane, options(backend, 0, pisco::Normalization::per_sample));
  for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
    const Stats st = compare(run(cpu, d, p), run(dev, d, p));
    EXPECT_EQ(st.non_finite, 0u);
    EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref) << s.focal_plane[d].name;
    EXPECT_LE(st.max_err, 1e-4 * st.rms_ref) << s.focal_plane[d].name;
  }
}

// B1 with beams of compact support well inside their discs: B vanishes beyond 2 deg, rho_max is
// 6 deg, and the second beam is lopsided (nothing on one side of its axis, so that its weights jump
// from large values to zero) and leaks Q into U.
TEST(BackendParity, CompactBeamsMatchTheReference) {
  SKIP_WITHOUT_DEVICE();
  const double rho0 = 2 * deg;
  auto compact = [rho0](double rho, double sigma, bool lopsided) {
    pisco::Mueller m{};
    if (rho >= rho0 || (lopsided && std::cos(sigma) < -0.3)) return m;
    const double b = (1 - rho / rho0) * (1 - rho / rho0) * (lopsided ? 1 + 0.6 * std::cos(sigma) : 1.0);
    m[0][0] = m[1][1] = m[2][2] = b;
    if (lopsided) m[1][2] = 0.05 * b;
    return m;
  };
  std::vector<pisco::Beamsor> beams{
      pisco::Beamsor::from_field([&](double r, double s) { return compact(r, s, false); }, 6 * deg, 0.2 * deg,
                                 "compact round", rho0, true),
      pisco::Beamsor::from_field([&](double r, double s) { return compact(r, s, true); }, 6 * deg, 0.2 * deg,
                                 "compact lopsided", rho0, false)};
  pisco::FocalPlane fp;
  fp.add({"round", 0.0, 0.0, 1.0, 0});
  fp.add({"lopsided", 30 * deg, 0.0, 1.0, 1});
  const pisco::Sky sky = cmb_like_sky(64, 21);
  const pisco::Pointing p = random_pointing(1500, 22);
  pisco::Engine cpu(sky, beams, fp, options("cpu"));
  pisco::Engine dev(sky, beams, fp, options(backend));
  for (std::size_t d = 0; d < fp.size(); ++d) {
    const Stats st = compare(run(cpu, d, p), run(dev, d, p));
    std::cout << fp[d].name << ": relative rms error " << st.rms_err / st.rms_ref << ", max error / rms "
              << st.max_err / st.rms_ref << "\n";
    EXPECT_EQ(st.non_finite, 0u);
    EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref) << fp[d].name;
    EXPECT_LE(st.max_err, 1e-4 * st.rms_ref) << fp[d].name;
  }
}

// B1: chunks of 1, an odd size and the device's own give the same TOD, bit for bit.
TEST(BackendParity, ChunkSizesGiveTheSameTod) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(32);
  const pisco::Pointing p = random_pointing(517, 13);
  pisco::Engine big(s.sky, s.beams, s.focal_plane, options(backend));
  const std::vector<double> ref = run(big, 0, p);
  for (std::size_t chunk : {std::size_t(1), std::size_t(7), std::size_t(129)}) {
    pisco::Engine e(s.sky, s.beams, s.focal_plane, options(backend, chunk));
    const std::vector<double> tod = run(e, 0, p);
    for (std::size_t i = 0; i < p.size(); ++i)
      ASSERT_EQ(tod[i], ref[i]) << "chunk " << chunk << ", sample " << i;
  }
  // The same engine twice: deterministic.
  EXPECT_EQ(run(big, 0, p), ref);
}

// B2: a 2.725 K monopole plus ~100 uK anisotropies: error <= 1e-5 of the anisotropy RMS in the TOD.
TEST(BackendParity, MonopoleSkyKeepsTheAnisotropies) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(64, 2.725);
  const Scene a = scene(64, 0.0);  // the same anisotropies without the monopole
  const pisco::Pointing p = random_pointing(2000, 14);
  for (auto norm : {pisco::Normalization::integral, pisco::Normalization::per_sample}) {
    pisco::Engine cpu(s.sky, s.beams, s.focal_plane, options("cpu", 0, norm));
    pisco::Engine cpu_a(a.sky, a.beams, a.focal_plane, options("cpu", 0, norm));
    pisco::Engine dev(s.sky, s.beams, s.focal_plane, options(backend, 0, norm));
    for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
      const std::vector<double> ref = run(cpu, d, p);
      const Stats aniso = compare(run(cpu_a, d, p), run(cpu_a, d, p));
      const Stats st = compare(ref, run(dev, d, p));
      std::cout << s.focal_plane[d].name << ": anisotropy rms " << aniso.rms_ref << " K, max error "
                << st.max_err << " K\n";
      EXPECT_EQ(st.non_finite, 0u);
      EXPECT_LE(st.max_err, 1e-5 * aniso.rms_ref) << s.focal_plane[d].name;
    }
  }
}

// A3 on the device: with a unit sky and a flat (top-hat) beam, each sample is its disc's pixel count
// times one weight, so the count of every sample can be read off the TOD and compared with HEALPix's
// query_disc, at the Table 1 radii, next to the poles and across phi = 0.
TEST(BackendParity, DeviceDiscsAreQueryDisc) {
  SKIP_WITHOUT_DEVICE();
  for (int nside : {16, 128, 512}) {
    pisco::Sky sky(nside);
    for (std::size_t i = 0; i < sky.npix(); ++i) sky.I()[i] = 1.0;
    const Healpix_Base base(nside, RING, SET_NSIDE);
    for (double rho_deg : {0.5, 5.0, 7.5, 20.0, 30.0, 60.0}) {
      if (nside == 512 && rho_deg > 7.5) continue;  // keeps the test short
      const double rho = rho_deg * deg;
      // The engine refuses discs narrower than the sky's largest pixel radius (they may hold no pixel).
      if (rho < base.max_pixrad()) continue;
      std::vector<pisco::Beamsor> beams{pisco::Beamsor::from_field(
          [](double, double) {
            pisco::Mueller m{};
            m[0][0] = 1;
            return m;
          },
          rho, rho / 8, "top hat", rho, true)};
      pisco::FocalPlane fp;
      fp.add({"d", 0, 0, 1, 0});
      pisco::Pointing p = random_pointing(200, 100 + nside);
      for (int i = 0; i < 40; ++i) {  // pixel centres: the Table 1 pointing
        const pointing c = base.pix2ang(int((i * 7919ull) % base.Npix()));
        p.push_back(c.theta, c.phi, 0.3 * i);
      }
      // The disc selection itself: samples near the poles stay on the sky (their polar copy's discs
      // are other pixels, docs/physics.md, "The quadrature").
      pisco::EngineOptions o = options(backend);
      o.quadrature = pisco::Quadrature::plain;
      pisco::Engine dev(sky, beams, fp, o);
      const std::vector<double> tod = run(dev, 0, p);
      // The weight of one pixel: the sum over a disc with a known count.
      std::vector<int> pix;
      base.query_disc(pointing(p.theta[0], p.phi[0]), rho).toVector(pix);
      const double w = tod[0] / double(pix.size());
      int mismatches = 0, ties = 0;
      for (std::size_t i = 0; i < p.size(); ++i) {
        base.query_disc(pointing(p.theta[i], p.phi[i]), rho).toVector(pix);
        const double count = tod[i] / w;
        // A pixel centre on the disc's edge itself (a tie that float64 decides by its own rounding, as at
        // rho = 30 deg from a pixel centre) may fall either way where the device's arithmetic is not the
        // host's: float-float resolves the edge to about 1e-15, and on an H200 both CUDA and NVIDIA's
        // Vulkan float64 put one such centre (NSIDE 16, rho 30 and 60 deg) outside, lavapipe inside.
        // Anything else must be query_disc's.
        if (std::abs(count - double(pix.size())) > 0.01) {
          std::vector<int> inner, outer;
          base.query_disc(pointing(p.theta[i], p.phi[i]), rho - 1e-13, inner);
          base.query_disc(pointing(p.theta[i], p.phi[i]), rho + 1e-13, outer);
          if (count > double(inner.size()) - 0.01 && count < double(outer.size()) + 0.01) {
            ++ties;
            continue;
          }
        }
        if (std::abs(count - double(pix.size())) > 0.01 && ++mismatches <= 3)
          ADD_FAILURE() << "NSIDE " << nside << ", rho " << rho_deg << " deg, sample " << i << " (theta "
                        << p.theta[i] << ", phi " << p.phi[i] << "): device disc " << count
                        << " pixels, query_disc " << pix.size();
      }
      if (ties) std::cout << "NSIDE " << nside << ", rho " << rho_deg << " deg: " << ties << " discs differ from query_disc by pixel centres on their edge\n";
    }
  }
}

// Out of memory and a lost device, injected through PISCO_VK_TEST_FAULT (vulkan only).
class FaultInjection {
 public:
  explicit FaultInjection(const char* fault) { ::setenv("PISCO_VK_TEST_FAULT", fault, 1); }
  ~FaultInjection() { ::unsetenv("PISCO_VK_TEST_FAULT"); }
};

TEST(BackendParity, OutOfMemoryFallsBackToSmallerChunks) {
  SKIP_WITHOUT_DEVICE();
  if (backend != "vulkan") GTEST_SKIP() << "fault injection is the vulkan backend's";
  const Scene s = scene(32);
  const pisco::Pointing p = random_pointing(700, 15);
  pisco::Engine cpu(s.sky, s.beams, s.focal_plane, options("cpu"));
  const std::vector<double> ref = run(cpu, 0, p);
  {
    FaultInjection f("oom-above:5000");  // 156 samples of pointing (32 bytes each): chunks of 128
    pisco::Engine dev(s.sky, s.beams, s.focal_plane, options(backend));
    std::cout << dev.device_name() << "\n";
    EXPECT_TRUE(pisco_test::contains(dev.device_name(), "chunks of 128 samples")) << dev.device_name();
    const Stats st = compare(ref, run(dev, 0, p));
    EXPECT_EQ(st.non_finite, 0u);
    EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref);
  }
  FaultInjection f("oom-above:1");
  pisco_test::expect_error([&] { pisco::Engine(s.sky, s.beams, s.focal_plane, options(backend)); },
                           "even for one-sample chunks");
}

// Tables larger than the device binds in one texel buffer are a clear error at set-up, naming the
// NSIDE (or the grids), the texels needed and the limit.
TEST(BackendParity, TablesBeyondTheTexelLimitAreAClearError) {
  SKIP_WITHOUT_DEVICE();
  if (backend != "vulkan") GTEST_SKIP() << "fault injection is the vulkan backend's";
  const Scene s = scene(32);  // 12,288 pixels: 24,576 sky texels
  {
    FaultInjection f("texels-max:24575");
    pisco_test::expect_error([&] { pisco::Engine(s.sky, s.beams, s.focal_plane, options(backend)); },
                             "an NSIDE 32 sky needs 24576 texels in one texel buffer, but");
    pisco_test::expect_error([&] { pisco::Engine(s.sky, s.beams, s.focal_plane, options(backend)); },
                             "binds at most 24575 (maxTexelBufferElements)");
  }
  FaultInjection f("texels-max:24576");  // the sky fits, the five detectors' grids do not
  pisco_test::expect_error([&] { pisco::Engine(s.sky, s.beams, s.focal_plane, options(backend)); },
                           "the beam grids need");
}

TEST(BackendParity, LostDeviceIsAClearError) {
  SKIP_WITHOUT_DEVICE();
  if (backend != "vulkan") GTEST_SKIP() << "fault injection is the vulkan backend's";
  const Scene s = scene(32);
  const pisco::Pointing p = random_pointing(517, 16);
  FaultInjection f("lose-device-after:2");
  pisco::Engine dev(s.sky, s.beams, s.focal_plane, options(backend, 100));
  std::vector<double> tod(p.size());
  const std::string e = pisco_test::error_of([&] { dev.convolve(1, p, tod); });
  std::cout << e << "\n";
  EXPECT_TRUE(pisco_test::contains(e, "device was lost")) << e;
  EXPECT_TRUE(pisco_test::contains(e, "detector 1")) << e;
  EXPECT_EQ(pisco_test::kind_of([&] {
              pisco::Engine again(s.sky, s.beams, s.focal_plane, options(backend, 100));
              again.convolve(1, p, tod);
            }),
            pisco::ErrorKind::device);
}

TEST(BackendParity, UnknownDeviceIsAClearError) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(16);
  pisco::EngineOptions o = options(backend);
  o.set("device", "no-such-device");
  pisco_test::expect_error([&] { pisco::Engine(s.sky, s.beams, s.focal_plane, o); }, "no-such-device");
  o.set("device", "99");
  pisco_test::expect_error([&] { pisco::Engine(s.sky, s.beams, s.focal_plane, o); }, "99");
}

// Detectors off the boresight, the pointing given as boresight angles and as boresight quaternions:
// the device composes and applies the offsets itself (B bars against the reference, whose own
// agreement with the host-expanded pointing test_engine checks); the results are added into a TOD
// that holds data already (accumulate), and streamed through many small submissions in flight.
TEST(BackendParity, OffsetsQuaternionsAccumulateAndSubmissionsInFlight) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(64);
  std::vector<pisco::Detector> dets = s.focal_plane.detectors();
  const double offsets[][3] = {{2 * deg, -1 * deg, 0.3}, {-4 * deg, 3 * deg, -1.2}, {0, 6 * deg, 0}, {1 * deg, 0, 2.5}};
  for (std::size_t i = 0; i < dets.size(); ++i) dets[i].set_offset(offsets[i % 4][0], offsets[i % 4][1], offsets[i % 4][2]);
  const pisco::FocalPlane fp(dets);
  const pisco::Pointing p = random_pointing(1200, 31);
  std::vector<pisco::Quat> q;
  for (std::size_t i = 0; i < p.size(); ++i) q.push_back(pisco::quat_from_pointing(p.theta[i], p.phi[i], p.psi[i]));
  const pisco::QuatPointingView qv{q};
  pisco::Engine cpu(s.sky, s.beams, fp, options("cpu"));
  pisco::Engine dev(s.sky, s.beams, fp, options(backend, 100));  // device chunks of 100 samples
  std::vector<std::vector<double>> queued(fp.size());
  for (std::size_t d = 0; d < fp.size(); ++d) queued[d].assign(p.size(), 1.0);  // accumulated into
  std::uint64_t last = 0;
  for (std::size_t off = 0; off < p.size(); off += 77)  // caller chunks of 77, every detector in flight
    for (std::size_t d = 0; d < fp.size(); ++d) {
      const std::size_t n = std::min<std::size_t>(77, p.size() - off);
      last = dev.submit(d, qv.subspan(off, n), std::span<double>(queued[d]).subspan(off, n), true);
    }
  dev.wait(last);
  for (std::size_t d = 0; d < fp.size(); ++d) {
    std::vector<double> ref(p.size(), NAN), from_angles(p.size(), NAN), ref_q(p.size(), NAN);
    cpu.convolve(d, p, ref);
    cpu.convolve(d, qv, ref_q);
    dev.convolve(d, p, from_angles);
    std::vector<double> from_quats(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) from_quats[i] = queued[d][i] - 1.0;
    const Stats sa = compare(ref, from_angles), sq = compare(ref_q, from_quats);
    std::cout << fp[d].name << " (offset): angles relative rms " << sa.rms_err / sa.rms_ref << ", quaternions "
              << sq.rms_err / sq.rms_ref << ", max/rms " << sq.max_err / sq.rms_ref << "\n";
    for (const Stats& st : {sa, sq}) {
      EXPECT_EQ(st.non_finite, 0u);
      EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref) << fp[d].name;
      EXPECT_LE(st.max_err, 1e-4 * st.rms_ref) << fp[d].name;
    }
  }
}

// Half-wave plates (docs/validation.md, "H"): a generic plate (all 16 entries non-zero) at the
// aperture and between the optics and the detector, continuous angles, on a plain sky and on a sky
// with a 2.725 K monopole (the plate's M_QI turns the monopole into a polarized signal, which the
// float64 path must carry): B bars against the reference.
TEST(BackendParity, HalfWavePlatesMatchTheReference) {
  SKIP_WITHOUT_DEVICE();
  const pisco::Mueller m0 = pisco_test::generic_plate();
  for (const double monopole : {0.0, 2.725}) {
    const Scene s = scene(64, monopole);
    std::vector<pisco::Detector> dets = s.focal_plane.detectors();
    for (std::size_t i = 0; i < dets.size(); ++i)
      dets[i].hwp = pisco::HalfWavePlate{m0, i % 2 ? pisco::HwpPlacement::detector : pisco::HwpPlacement::aperture,
                                         0.2 * double(i)};
    const pisco::FocalPlane fp(dets);
    const pisco::Pointing p = random_pointing(1000, 41);
    std::vector<double> h(p.size());
    for (std::size_t i = 0; i < h.size(); ++i) h[i] = 0.113 * double(i);
    pisco::Engine cpu(s.sky, s.beams, fp, options("cpu"));
    pisco::Engine dev(s.sky, s.beams, fp, options(backend));
    // The plate's effect alone: the same detectors without a plate, for the anisotropy scale.
    const Scene aniso = scene(64, 0.0);
    pisco::Engine cpu_aniso(aniso.sky, aniso.beams, fp, options("cpu"));
    for (std::size_t d = 0; d < fp.size(); ++d) {
      std::vector<double> ref(p.size(), NAN), got(p.size(), NAN), a(p.size(), NAN);
      cpu.convolve(d, p, ref, false, h);
      dev.convolve(d, p, got, false, h);
      cpu_aniso.convolve(d, p, a, false, h);
      const Stats st = compare(ref, got);
      const double scale = compare(a, a).rms_ref;
      std::cout << fp[d].name << (fp[d].hwp->placement == pisco::HwpPlacement::aperture ? " (aperture" : " (detector")
                << (monopole ? ", monopole sky)" : ")") << ": relative rms error " << st.rms_err / scale
                << ", max error / rms " << st.max_err / scale << "\n";
      EXPECT_EQ(st.non_finite, 0u);
      EXPECT_LE(st.rms_err, 1e-5 * scale) << fp[d].name;
      EXPECT_LE(st.max_err, 1e-4 * scale) << fp[d].name;
    }
  }
}

// Several detectors on one boresight chunk (docs/library.md, "Several detectors on one chunk"), as
// submit() of a list of detectors and as submit() of parts of one share(): each detector's TOD has the
// bits of its own submit(), over pointing that reaches both poles (the polar
// copy's samples, submitted apart) and pointing that stays away from them, from angles and from
// quaternions, written and accumulated, with offsets, a plate at the aperture (its angles the
// detector's own) and one between the optics and the detector (four row detectors on one pointing).
// A device backend stages each chunk's pointing once a slot instead of once a detector: counted exactly
// on the pointing away from the poles, where every submission takes one device chunk (a detector's
// samples near the poles go to the polar copy, and the sky's samples around them into pointing of
// their own).
TEST(BackendParity, SeveralDetectorsOnOneChunkGiveEachDetectorsBits) {
  SKIP_WITHOUT_DEVICE();
  const Scene s = scene(64, 2.725);
  std::vector<pisco::Detector> dets = s.focal_plane.detectors();
  const double offsets[][3] = {{2 * deg, -1 * deg, 0.3}, {-4 * deg, 3 * deg, -1.2}, {0, 6 * deg, 0}, {1 * deg, 0, 2.5}};
  for (std::size_t i = 0; i < dets.size(); ++i) dets[i].set_offset(offsets[i % 4][0], offsets[i % 4][1], offsets[i % 4][2]);
  dets[1].hwp = pisco::HalfWavePlate{pisco_test::generic_plate(), pisco::HwpPlacement::aperture, 0.4};
  dets[3].hwp = pisco::HalfWavePlate{pisco_test::generic_plate(), pisco::HwpPlacement::detector, -0.3};
  const pisco::FocalPlane fp(dets);
  std::vector<std::size_t> all(fp.size());
  for (std::size_t d = 0; d < fp.size(); ++d) all[d] = d;
  // Pointing across both poles, and pointing between colatitudes 60 and 120 deg.
  const pisco::Pointing polar = random_pointing(1000, 53);
  pisco::Pointing belt;
  std::mt19937_64 rng(59);
  std::uniform_real_distribution<double> u(0, 1);
  for (std::size_t i = 0; i < 900; ++i) belt.push_back((60 + 60 * u(rng)) * deg, 2 * pi * u(rng), 2 * pi * u(rng));
  // The caller's chunks within the device's of 100 samples, and across them.
  for (const std::size_t chunk : {std::size_t(90), std::size_t(250)})
  for (const pisco::Pointing* p : std::array<const pisco::Pointing*, 2>{&polar, &belt}) {
    std::vector<double> h(p->size());
    for (std::size_t i = 0; i < h.size(); ++i) h[i] = 0.071 * double(i);
    std::vector<pisco::Quat> q;
    for (std::size_t i = 0; i < p->size(); ++i) q.push_back(pisco::quat_from_pointing(p->theta[i], p->phi[i], p->psi[i]));
    for (const bool quats : {false, true})
      for (const bool accumulate : {false, true}) {
        pisco::Engine one(s.sky, s.beams, fp, options(backend, 100)), many(s.sky, s.beams, fp, options(backend, 100)),
            shared(s.sky, s.beams, fp, options(backend, 100));
        std::vector<std::vector<double>> a(fp.size(), std::vector<double>(p->size(), accumulate ? 0.5 : NAN)), b = a,
                                         c = a;
        const pisco::SharedPointing whole = quats ? shared.share(pisco::QuatPointingView{q}) : shared.share(p->view());
        for (std::size_t off = 0; off < p->size(); off += chunk) {
          const std::size_t n = std::min(chunk, p->size() - off);
          const std::span<const double> hc = std::span<const double>(h).subspan(off, n);
          std::vector<std::span<double>> tods;
          for (std::size_t d = 0; d < fp.size(); ++d) {
            const std::span<double> ta = std::span<double>(a[d]).subspan(off, n);
            const std::span<const double> hd = fp[d].hwp ? hc : std::span<const double>();
            if (quats) one.submit(d, pisco::QuatPointingView{q}.subspan(off, n), ta, accumulate, hd);
            else one.submit(d, p->view().subspan(off, n), ta, accumulate, hd);
            shared.submit(d, whole.subspan(off, n), std::span<double>(c[d]).subspan(off, n), accumulate, hd);
            tods.push_back(std::span<double>(b[d]).subspan(off, n));
          }
          if (quats) many.submit(all, pisco::QuatPointingView{q}.subspan(off, n), tods, accumulate, hc);
          else many.submit(all, p->view().subspan(off, n), tods, accumulate, hc);
        }
        one.wait();
        many.wait();
        shared.wait();
        for (std::size_t d = 0; d < fp.size(); ++d)
          for (std::size_t i = 0; i < p->size(); ++i)
            for (const auto* other : {&b, &c})
            ASSERT_EQ(std::bit_cast<std::uint64_t>(a[d][i]), std::bit_cast<std::uint64_t>((*other)[d][i]))
                << (other == &b ? "a list of detectors: " : "parts of one share(): ")
                << fp[d].name << ", sample " << i << (quats ? ", quaternions" : ", angles")
                << (p == &polar ? ", across the poles" : ", away from the poles") << ", chunks of " << chunk;
        std::cout << "chunks of " << chunk << ", " << (p == &polar ? "across the poles" : "away from the poles") << (quats ? ", quaternions" : ", angles")
                  << ": pointing samples staged " << one.staged_samples() << " one detector a call, "
                  << many.staged_samples() << " a list of detectors, " << shared.staged_samples()
                  << " parts of one share()\n";
        if (backend == "simd") {
          EXPECT_EQ(one.staged_samples(), 0u);
          EXPECT_EQ(many.staged_samples(), 0u);
          EXPECT_EQ(shared.staged_samples(), 0u);
        } else if (p == &belt && chunk == 90) {
          // A detector a call: each detector's chunk staged once, the plate's rows in both slots;
          // all at once: each chunk once in each of the two slots.
          EXPECT_EQ(one.staged_samples(), p->size() * (fp.size() + 1));
          EXPECT_EQ(many.staged_samples(), p->size() * 2);
          EXPECT_EQ(shared.staged_samples(), p->size() * 2);
        } else if (chunk == 90) {
          // Across the poles each chunk holds polar samples alone among the sky's, so that each detector's
          // sky samples are gathered into pointing of its own (SkyPass): little is shared there.
          EXPECT_LE(many.staged_samples(), one.staged_samples());
          EXPECT_EQ(shared.staged_samples(), many.staged_samples());
        }
      }
  }
  // The arguments are checked before anything is queued.
  pisco::Engine e(s.sky, s.beams, fp, options(backend, 100));
  std::vector<double> t0(10), t1(10), t2(9);
  const std::vector<std::span<double>> two{t0, t1}, short_one{t0, t2};
  const std::vector<std::size_t> bad{0, fp.size()};
  const pisco::PointingView v = belt.view().subspan(0, 10);
  pisco_test::expect_error([&] { e.submit(all, v, two); }, "TOD buffers (expected one a detector)");
  pisco_test::expect_error([&] { e.submit(bad, v, two); }, "detector index " + std::to_string(fp.size()));
  pisco_test::expect_error([&] { e.submit(std::vector<std::size_t>{0, 2}, v, short_one); },
                                    "has 9 samples but the pointing has 10");
  pisco_test::expect_error([&] { e.submit(std::vector<std::size_t>{0, 1}, v, two); },
                                    "has a half-wave plate: expected 10 plate angles");
  pisco::Pointing nan = belt;
  nan.theta[3] = NAN;
  pisco_test::expect_error([&] { e.submit(std::vector<std::size_t>{0, 2}, nan.view().subspan(0, 10), two); },
                                    "the shared boresight pointing: sample 3 has a non-finite theta");
  pisco_test::expect_error([&] { e.submit(0, pisco::SharedPointing{}, t0); }, "was not made by Engine::share()");
  const pisco::SharedPointing sv = e.share(v);
  pisco_test::expect_error([&] { (void)sv.subspan(5, 6); }, "samples 5 to 11 (exclusive) of a chunk of 10");
  EXPECT_EQ(e.submit(std::vector<std::size_t>{}, v, std::vector<std::span<double>>{}), 0u);  // nothing queued
}

}  // namespace
