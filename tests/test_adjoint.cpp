// The adjoint (docs/physics.md, "The adjoint"; docs/validation.md, "M"): Engine::adjoint is the exact
// transpose of convolve, tested as ducc0 tests its own operators, <s, A^T d> = <A s, d>, on random
// skies with a monopole and a dipole, beams with cross-polar terms, detector offsets, both half-wave
// plate placements, pointing across both poles as angles and as quaternions, both normalizations and
// both quadratures; against a brute-force transpose (A^T d)_k = <A e_k, d> with one-pixel skies; and
// across backends.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <tuple>

#include "backend_fixtures.hpp"
#include "core/prepared.hpp"
#include "core/ring_slices.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/quaternion.hpp"
#include "support.hpp"

namespace {

using pisco::deg;
constexpr double pi = std::numbers::pi;

// A random sky: white noise on I, Q, U, V, on a monopole and a dipole.
pisco::Sky random_sky(int nside, std::uint64_t seed) {
  pisco::Sky sky = pisco_test::cmb_like_sky(nside, seed, 2.725);
  const Healpix_Base base(nside, RING, SET_NSIDE);
  std::mt19937_64 rng(seed + 1);
  std::normal_distribution<double> g(0, 1);
  for (std::size_t p = 0; p < sky.npix(); ++p) {
    const pointing a = base.pix2ang(int(p));
    sky.I()[p] += 3e-3 * std::cos(a.theta) + 1e-6 * g(rng);
    sky.Q()[p] += 1e-6 * g(rng);
    sky.U()[p] += 1e-6 * g(rng);
    sky.V()[p] += 1e-7 * g(rng);
  }
  return sky;
}

// The backend scene's detectors, with offsets, and two more behind a generic plate (one at the
// aperture, one between the optics and the detector), both off the boresight.
pisco_test::Scene adjoint_scene(int nside) {
  pisco_test::Scene s = pisco_test::backend_scene(nside);
  s.sky = random_sky(nside, 11);
  pisco::FocalPlane fp;
  for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
    pisco::Detector det = s.focal_plane[d];
    det.set_offset(0.02 * double(d), -0.015 * double(d), 0.3 * double(d));
    fp.add(det);
  }
  for (const pisco::HwpPlacement placement : {pisco::HwpPlacement::aperture, pisco::HwpPlacement::detector}) {
    pisco::Detector det{placement == pisco::HwpPlacement::aperture ? "plate_aperture" : "plate_detector",
                        15 * deg, 0.01, 1.0, 0};
    det.set_offset(-0.03, 0.02, 0.4);
    det.hwp = pisco::HalfWavePlate{pisco_test::generic_plate(), placement, 0.2};
    fp.add(det);
  }
  s.focal_plane = fp;
  return s;
}

std::vector<double> gaussian_tod(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  std::vector<double> d(n);
  for (double& x : d) x = g(rng);
  return d;
}

std::vector<double> plate_angles(std::size_t n) {
  std::vector<double> h(n);
  for (std::size_t i = 0; i < n; ++i) h[i] = 0.37 * double(i);
  return h;
}

double dot(std::span<const double> a, std::span<const double> b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

double norm(std::span<const double> a) { return std::sqrt(dot(a, a)); }

struct DotTest {
  double forward = 0, adjoint = 0;  // <A s, d> and <s, A^T d>
  double scale = 0;                 // ||A s|| ||d||, the size of either side for unrelated vectors
  double relative() const { return std::abs(forward - adjoint) / scale; }
};

// <A s, d> and <s, A^T d> over every detector of `scene` on one engine: angles for even detectors,
// quaternions for odd ones.
DotTest dot_test(const pisco_test::Scene& scene, const pisco::EngineOptions& options, const pisco::Pointing& p) {
  pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane, options);
  std::vector<pisco::Quat> quats;
  for (std::size_t i = 0; i < p.size(); ++i) quats.push_back(pisco::quat_from_pointing(p.theta[i], p.phi[i], p.psi[i]));
  const std::vector<double> h = plate_angles(p.size());
  DotTest t;
  double tod_norm2 = 0, d_norm2 = 0;
  for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
    const bool plate = scene.focal_plane[det].hwp.has_value();
    const std::span<const double> angles = plate ? std::span<const double>(h) : std::span<const double>();
    const std::vector<double> d = gaussian_tod(p.size(), 100 + det);
    std::vector<double> tod(p.size());
    if (det % 2 == 0) {
      engine.convolve(det, p.view(), tod, false, angles);
      engine.adjoint(det, p.view(), d, angles);
    } else {
      engine.convolve(det, pisco::QuatPointingView{quats}, tod, false, angles);
      engine.adjoint(det, pisco::QuatPointingView{quats}, d, angles);
    }
    t.forward += dot(tod, d);
    tod_norm2 += dot(tod, tod);
    d_norm2 += dot(d, d);
  }
  pisco::Sky back(scene.sky.nside());
  engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
  for (int c = 0; c < 4; ++c)
    t.adjoint += dot(scene.sky.stokes(pisco::StokesIndex(c)), back.stokes(pisco::StokesIndex(c)));
  t.scale = std::sqrt(tod_norm2 * d_norm2);
  return t;
}

class Adjoint : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    const std::string why = pisco_test::backend_unavailable(GetParam());
    if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
    for (const pisco::BackendInfo& b : pisco::Engine::backends())
      if (b.name == GetParam() && !b.capabilities.adjoint)
        GTEST_SKIP() << GetParam() << ": this backend has no adjoint yet (BackendCapabilities::adjoint is false)";
  }
  // The bar of <s, A^T d> = <A s, d>: float64 rounding on the reference, float32 elsewhere.
  double bar() const { return GetParam() == "cpu" ? 1e-12 : 1e-5; }
};

// <s, A^T d> = <A s, d> on every detector kind, both pointing forms, both normalizations and both
// quadratures (the corrected one sums the samples near the poles on the sky's polar copy).
TEST_P(Adjoint, DotProductIdentity) {
  const pisco_test::Scene scene = adjoint_scene(16);
  const pisco::Pointing p = pisco_test::random_pointing(600, 5);
  // vulkan: also its float-float kernel, for devices without float64 (docs/vulkan.md).
  std::vector<std::string> arithmetic{"auto"};
  if (GetParam() == "vulkan") arithmetic.push_back("float-float");
  for (const std::string& a : arithmetic)
  for (const pisco::Normalization n : {pisco::Normalization::integral, pisco::Normalization::per_sample})
    for (const pisco::Quadrature q : {pisco::Quadrature::corrected, pisco::Quadrature::plain}) {
      pisco::EngineOptions o;
      o.backend = GetParam();
      o.normalization = n;
      o.quadrature = q;
      pisco_test::set_taken(o, "threads", 2LL);
      pisco_test::set_taken(o, "arithmetic", std::string(a));
      const DotTest t = dot_test(scene, o, p);
      std::cout << GetParam() << ", " << a << (n == pisco::Normalization::integral ? ", integral" : ", per-sample")
                << (q == pisco::Quadrature::corrected ? ", corrected" : ", plain") << ": <As,d> = " << t.forward
                << ", <s,A^T d> = " << t.adjoint << ", difference / (||As|| ||d||) = " << t.relative() << "\n";
      EXPECT_LT(t.relative(), bar());
      EXPECT_GT(std::abs(t.forward), 1e-3 * t.scale);  // the test is not comparing two zeros
    }
}

// A split beam (docs/beams.md, "Sidelobes"): the outer part on the band-limited coarse sky, whose
// transpose the engine applies too.
TEST_P(Adjoint, DotProductIdentityWithSidelobes) {
  const auto ring_beam = [](double rho, double) {
    const double s = 2.0 * deg / std::sqrt(8 * std::log(2.0)), sr = 3.0 * deg / std::sqrt(8 * std::log(2.0));
    const double b = std::exp(-rho * rho / (2 * s * s)) + 1e-2 * std::exp(-std::pow(rho - 10 * deg, 2) / (2 * sr * sr));
    return pisco::Beamsor::stokes_mueller(b, 0.9 * b, 0.05 * b, 0.0);
  };
  pisco::SidelobeSplit split;
  split.rho_main = 6 * deg;
  pisco_test::Scene scene{random_sky(32, 3), {}, {}};
  scene.beams.push_back(pisco::Beamsor::from_field(ring_beam, 16 * deg, 0.2 * deg, "ring", 0.0, false, split));
  ASSERT_NE(scene.beams[0].sidelobes(), nullptr);
  scene.focal_plane.add_pair("pair", 10 * deg, 0, 0);
  pisco::EngineOptions o;
  o.backend = GetParam();
  pisco_test::set_taken(o, "threads", 2LL);
  const DotTest t = dot_test(scene, o, pisco_test::random_pointing(300, 8));
  std::cout << GetParam() << ", split beam: difference / (||As|| ||d||) = " << t.relative() << "\n";
  EXPECT_LT(t.relative(), bar());
}

// (A^T d)_k = <A e_k, d>: the adjoint at a pixel against convolutions of a sky that is 1 in that
// pixel's Stokes parameter and 0 elsewhere, at a pixel next to the north pole, one on a cap-boundary
// ring and one near the equator, with samples whose discs cover them.
TEST_P(Adjoint, MatchesTheTransposeColumnByColumn) {
  const int nside = 16;
  const pisco_test::Scene scene = adjoint_scene(nside);
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const std::vector<int> pixels{1, 2 * nside * (nside - 1) + 5, 6 * nside * nside + 3};
  pisco::Pointing p;
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1, 1);
  for (const int k : pixels) {
    const pointing c = base.pix2ang(k);
    for (int j = 0; j < 40; ++j)
      p.push_back(std::clamp(c.theta + 3 * deg * u(rng), 0.0, pi), c.phi + 3 * deg * u(rng), pi * u(rng));
  }
  const std::vector<double> h = plate_angles(p.size());
  pisco::EngineOptions o;
  o.backend = GetParam();
  pisco_test::set_taken(o, "threads", 2LL);
  // A^T d over every detector.
  pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane, o);
  std::vector<std::vector<double>> d;
  for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
    d.push_back(gaussian_tod(p.size(), 7 + det));
    engine.adjoint(det, p.view(), d.back(), scene.focal_plane[det].hwp ? std::span<const double>(h) : std::span<const double>());
  }
  pisco::Sky back(nside);
  engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
  double largest = 0;
  for (int c = 0; c < 4; ++c)
    for (double x : back.stokes(pisco::StokesIndex(c))) largest = std::max(largest, std::abs(x));
  for (const int k : pixels)
    for (int c = 0; c < 4; ++c) {
      pisco::Sky e(nside);
      e.stokes(pisco::StokesIndex(c))[std::size_t(k)] = 1.0;
      pisco::Engine column(e, scene.beams, scene.focal_plane, o);
      double want = 0;
      for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
        std::vector<double> tod(p.size());
        column.convolve(det, p.view(), tod, false,
                        scene.focal_plane[det].hwp ? std::span<const double>(h) : std::span<const double>());
        want += dot(tod, d[det]);
      }
      const double got = back.stokes(pisco::StokesIndex(c))[std::size_t(k)];
      EXPECT_NEAR(got, want, bar() * largest) << "pixel " << k << ", Stokes " << "IQUV"[c];
      if (c < 3) EXPECT_GT(std::abs(want), 1e-3 * largest) << "pixel " << k << " is not covered";
    }
}

// The same calls give the same bits whatever the number of threads and the device backends' chunk
// size (their fixed-point sums, docs/vulkan.md, "The adjoint"); cutting the TOD into other calls
// changes only the order in which a plate's four row detectors meet in a pixel (rounding).
TEST_P(Adjoint, DeterministicAcrossThreadsAndChunks) {
  const pisco_test::Scene scene = adjoint_scene(16);
  const pisco::Pointing p = pisco_test::random_pointing(400, 9);
  const std::vector<double> h = plate_angles(p.size());
  const auto run = [&](unsigned threads, std::size_t chunk, std::size_t device_chunk = 0) {
    pisco::EngineOptions o;
    o.backend = GetParam();
    pisco_test::set_taken(o, "threads", (long long)threads);
    pisco_test::set_taken(o, "chunk_samples", (long long)device_chunk);
    pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane, o);
    for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
      const std::vector<double> d = gaussian_tod(p.size(), det);
      for (std::size_t first = 0; first < p.size(); first += chunk) {
        const std::size_t n = std::min(chunk, p.size() - first);
        engine.adjoint(det, p.view().subspan(first, n), std::span<const double>(d).subspan(first, n),
                       scene.focal_plane[det].hwp ? std::span<const double>(h).subspan(first, n)
                                                  : std::span<const double>());
      }
    }
    pisco::Sky back(16);
    engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
    return back;
  };
  double largest = 0;
  const pisco::Sky one = run(1, p.size());
  for (int c = 0; c < 4; ++c)
    for (double x : one.stokes(pisco::StokesIndex(c))) largest = std::max(largest, std::abs(x));
  for (const auto& [threads, chunk, device_chunk] :
       {std::tuple{2u, p.size(), std::size_t(0)}, {3u, p.size(), std::size_t(0)}, {1u, p.size(), std::size_t(7)},
        {1u, std::size_t(37), std::size_t(0)}, {2u, std::size_t(1), std::size_t(0)}}) {
    const pisco::Sky other = run(threads, chunk, device_chunk);
    for (int c = 0; c < 4; ++c)
      for (std::size_t k = 0; k < one.npix(); ++k) {
        const double a = one.stokes(pisco::StokesIndex(c))[k], b = other.stokes(pisco::StokesIndex(c))[k];
        if (chunk == p.size()) ASSERT_EQ(a, b) << threads << " threads, device chunks of " << device_chunk << ", pixel " << k;
        else ASSERT_NEAR(a, b, 1e-14 * largest) << threads << " threads, chunks of " << chunk << ", pixel " << k;
      }
  }
}

// The adjoint maps are added into the caller's and the engine's are cleared; V may be left out.
TEST_P(Adjoint, TakeAddsAndClears) {
  const pisco_test::Scene scene = adjoint_scene(16);
  const pisco::Pointing p = pisco_test::random_pointing(50, 2);
  pisco::EngineOptions o;
  o.backend = GetParam();
  pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane, o);
  const std::vector<double> d = gaussian_tod(p.size(), 1);
  engine.adjoint(2, p.view(), d);
  pisco::Sky first(16);
  engine.take_adjoint({first.I(), first.Q(), first.U(), first.V()});
  engine.adjoint(2, p.view(), d);
  pisco::Sky twice(first);
  engine.take_adjoint({twice.I(), twice.Q(), twice.U(), {}});
  double largest = 0;
  for (double x : first.I()) largest = std::max(largest, std::abs(x));
  ASSERT_GT(largest, 0.0);
  for (std::size_t k = 0; k < first.npix(); ++k) {
    ASSERT_NEAR(twice.I()[k], 2 * first.I()[k], 1e-15 * largest);
    ASSERT_EQ(twice.V()[k], first.V()[k]);
  }
  pisco::Sky none(16);
  engine.take_adjoint({none.I(), none.Q(), none.U(), none.V()});
  for (double x : none.I()) ASSERT_EQ(x, 0.0);
}

// Parity: the adjoint maps of a float32 backend against the reference's, on a sky-wide scan whose
// TOD carries a 2.725 K-like offset (as a monopole sky's would), at the float32 bars.
TEST_P(Adjoint, MatchesTheReference) {
  if (GetParam() == "cpu") GTEST_SKIP() << "cpu is the reference";
  const pisco_test::Scene scene = adjoint_scene(16);
  const pisco::Pointing p = pisco_test::random_pointing(2000, 12);
  const std::vector<double> h = plate_angles(p.size());
  const auto run = [&](const std::string& backend, const std::string& arithmetic) {
    pisco::EngineOptions o;
    o.backend = backend;
    pisco_test::set_taken(o, "arithmetic", arithmetic);
    pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane, o);
    for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
      std::vector<double> d = gaussian_tod(p.size(), 40 + det);
      for (double& x : d) x = 2.725 + 1e-4 * x;
      engine.adjoint(det, p.view(), d, scene.focal_plane[det].hwp ? std::span<const double>(h) : std::span<const double>());
    }
    pisco::Sky back(16);
    engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
    return back;
  };
  const pisco::Sky ref = run("cpu", "auto");
  std::vector<std::string> arithmetic{"auto"};
  if (GetParam() == "vulkan") arithmetic.push_back("float-float");
  for (const std::string& arith : arithmetic) {
  const pisco::Sky got = run(GetParam(), arith);
  for (int c = 0; c < 4; ++c) {
    const auto a = ref.stokes(pisco::StokesIndex(c)), b = got.stokes(pisco::StokesIndex(c));
    const pisco_test::Stats st = pisco_test::compare(std::vector<double>(a.begin(), a.end()), std::vector<double>(b.begin(), b.end()));
    double largest = 0;
    for (double x : a) largest = std::max(largest, std::abs(x));
    std::cout << GetParam() << " (" << arith << ") " << "IQUV"[c] << ": relative RMS " << st.rms_err / st.rms_ref
              << ", max / max " << st.max_err / largest << "\n";
    EXPECT_LT(st.rms_err, 1e-5 * st.rms_ref) << arith << " " << "IQUV"[c];
    EXPECT_LT(st.max_err, 1e-4 * largest) << arith << " " << "IQUV"[c];
    EXPECT_EQ(st.non_finite, 0u);
  }
  }
}

// Engine::normal is convolve followed by adjoint of the same TOD, bit for bit: where it runs the two
// passes (the reference and the device backends; simd on its float64 path, a sky whose monopole it
// takes out; plates between the optics and the detector) and where the simd backend evaluates each
// disc once (its scatter kernel sums the forward's response as the forward kernel does). Every
// detector kind of adjoint_scene, samples across both poles (the corrected quadrature's polar copy),
// angles and quaternions; a sky with a monopole and a dipole, and the same sky with the monopole
// removed (the dipole kept), which simd sums in float32.
TEST_P(Adjoint, NormalIsConvolveThenAdjoint) {
  const pisco_test::Scene scene = adjoint_scene(16);
  const pisco::Pointing p = pisco_test::random_pointing(500, 13);
  std::vector<pisco::Quat> quats;
  for (std::size_t i = 0; i < p.size(); ++i) quats.push_back(pisco::quat_from_pointing(p.theta[i], p.phi[i], p.psi[i]));
  const std::vector<double> h = plate_angles(p.size());
  pisco::Sky no_monopole = scene.sky;
  double mean = 0;
  for (double x : no_monopole.I()) mean += x / double(no_monopole.npix());
  for (double& x : no_monopole.I()) x -= mean;
  for (const bool monopole : {true, false}) {
    const pisco::Sky& sky = monopole ? scene.sky : no_monopole;
    const auto run = [&](bool fused, unsigned threads) {
      pisco::EngineOptions o;
      o.backend = GetParam();
      pisco_test::set_taken(o, "threads", (long long)threads);
      pisco::Engine engine(sky, scene.beams, scene.focal_plane, o);
      for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
        const std::span<const double> angles =
            scene.focal_plane[det].hwp ? std::span<const double>(h) : std::span<const double>();
        const auto each = [&](const auto& view) {
          if (fused) {
            engine.normal(det, view, angles);
          } else {
            std::vector<double> tod(p.size());
            engine.convolve(det, view, tod, false, angles);
            engine.adjoint(det, view, tod, angles);
          }
        };
        if (det % 2 == 0) each(p.view());
        else each(pisco::QuatPointingView{quats});
      }
      pisco::Sky back(16);
      engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
      return back;
    };
    const pisco::Sky two = run(false, 2), one = run(true, 2), again = run(true, 3);
    for (int c = 0; c < 4; ++c) {
      const auto a = two.stokes(pisco::StokesIndex(c)), b = one.stokes(pisco::StokesIndex(c)),
                 t = again.stokes(pisco::StokesIndex(c));
      double largest = 0, worst = 0;
      for (std::size_t k = 0; k < a.size(); ++k) {
        ASSERT_EQ(b[k], t[k]) << (monopole ? "monopole sky, " : "") << "IQUV"[c] << " pixel " << k << ", 2 and 3 threads";
        ASSERT_EQ(a[k], b[k]) << (monopole ? "monopole sky, " : "") << "IQUV"[c] << " pixel " << k;
        largest = std::max(largest, std::abs(a[k]));
        worst = std::max(worst, std::abs(a[k] - b[k]));
      }
      std::cout << GetParam() << (monopole ? ", monopole sky, " : ", no monopole, ") << "IQUV"[c]
                << ": largest |A^T A s| " << largest << ", normal - two passes at most " << worst << "\n";
      EXPECT_GT(largest, 0.0);
    }
  }
}


// Wide discs at a high enough NSIDE make the simd backend's tasks smaller than 1024 samples (60 deg at
// NSIDE 64: 815), so that a task's plan stays near 2 MiB: their maps are still the same bits on any
// number of threads, and the reference's to the float32 bars.
TEST(SimdAdjointWideDiscs, SmallerTasksKeepTheBitsAndTheReference) {
  const std::string why = pisco_test::backend_unavailable("simd");
  if (!why.empty()) GTEST_SKIP() << "simd: " << why;
  const int nside = 64;
  pisco::BeamOptions wide;
  wide.rho_max = 60 * deg;
  wide.cross_polar = 0.03;
  wide.cross_polar_pattern = pisco::CrossPolarPattern::uniform;
  pisco::FocalPlane fp;
  fp.add({"wide", 10 * deg, 0.01, 1.0, 0});
  pisco::Detector plate{"wide_plate", 35 * deg, 0.0, 1.0, 0};
  plate.hwp = pisco::HalfWavePlate{pisco_test::generic_plate(), pisco::HwpPlacement::aperture, 0.2};
  fp.add(plate);
  const pisco::Sky sky = random_sky(nside, 5);
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(20 * deg, wide)};
  const pisco::Pointing p = pisco_test::random_pointing(1500, 21);
  const std::vector<double> h = plate_angles(p.size());
  const auto run = [&](const std::string& backend, unsigned threads) {
    pisco::EngineOptions o;
    o.backend = backend;
    pisco_test::set_taken(o, "threads", (long long)threads);
    pisco::Engine engine(sky, beams, fp, o);
    for (std::size_t det = 0; det < fp.size(); ++det)
      engine.adjoint(det, p.view(), gaussian_tod(p.size(), 60 + det),
                     fp[det].hwp ? std::span<const double>(h) : std::span<const double>());
    pisco::Sky back(nside);
    engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
    return back;
  };
  const pisco::Sky one = run("simd", 1), three = run("simd", 3), ref = run("cpu", 2);
  for (int c = 0; c < 4; ++c) {
    const auto a = one.stokes(pisco::StokesIndex(c)), b = three.stokes(pisco::StokesIndex(c)),
               r = ref.stokes(pisco::StokesIndex(c));
    for (std::size_t k = 0; k < a.size(); ++k) ASSERT_EQ(a[k], b[k]) << "IQUV"[c] << " pixel " << k;
    const pisco_test::Stats st =
        pisco_test::compare(std::vector<double>(r.begin(), r.end()), std::vector<double>(a.begin(), a.end()));
    EXPECT_GT(st.rms_ref, 0.0) << "IQUV"[c];
    EXPECT_LT(st.rms_err, 1e-5 * st.rms_ref) << "IQUV"[c];
    EXPECT_EQ(st.non_finite, 0u);
  }
  // The normal pass keeps a whole disc's weights (12,000 pixels here) before it scatters, and sums
  // the discs that hold a pole with the forward kernel (their polar cap is one range there, split by
  // ring here): the same maps as convolve then adjoint, bit for bit, on a sky without a monopole (the
  // pass the float32 path runs), with both quadratures.
  pisco::Sky flat = sky;
  double mean = 0;
  for (double x : flat.I()) mean += x / double(flat.npix());
  for (double& x : flat.I()) x -= mean;
  for (const pisco::Quadrature q : {pisco::Quadrature::corrected, pisco::Quadrature::plain}) {
    pisco::EngineOptions o;
    o.backend = "simd";
    o.set("threads", 2LL);
    o.quadrature = q;
    pisco::Engine engine(flat, beams, fp, o);
    pisco::Sky two(nside), fused(nside);
    for (std::size_t det = 0; det < fp.size(); ++det) {
      const std::span<const double> angles = fp[det].hwp ? std::span<const double>(h) : std::span<const double>();
      std::vector<double> tod(p.size());
      engine.convolve(det, p.view(), tod, false, angles);
      engine.adjoint(det, p.view(), tod, angles);
      engine.take_adjoint({two.I(), two.Q(), two.U(), two.V()});
      engine.normal(det, p.view(), angles);
      engine.take_adjoint({fused.I(), fused.Q(), fused.U(), fused.V()});
    }
    for (int c = 0; c < 4; ++c) {
      const auto a = two.stokes(pisco::StokesIndex(c)), b = fused.stokes(pisco::StokesIndex(c));
      double largest = 0, worst = 0;
      for (std::size_t k = 0; k < a.size(); ++k) {
        largest = std::max(largest, std::abs(a[k]));
        worst = std::max(worst, std::abs(a[k] - b[k]));
      }
      std::cout << "wide discs, normal pass, " << "IQUV"[c] << ": largest " << largest << ", difference at most " << worst
                << "\n";
      EXPECT_GT(largest, 0.0);
      EXPECT_EQ(worst, 0.0) << "IQUV"[c];
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, Adjoint, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

TEST(AdjointErrors, BadArgumentsNameTheProblem) {
  const pisco_test::Scene scene = adjoint_scene(16);
  pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane);
  const pisco::Pointing p = pisco_test::random_pointing(10, 1);
  std::vector<double> d(10, 1.0);
  pisco_test::expect_error([&] { engine.adjoint(99, p.view(), d); }, "detector index 99");
  pisco_test::expect_error([&] { engine.normal(99, p.view()); }, "detector index 99");
  pisco_test::expect_error([&] { engine.adjoint(0, p.view(), std::span<const double>(d).first(5)); },
                           "has 5 samples but the pointing has 10");
  d[3] = NAN;
  pisco_test::expect_error([&] { engine.adjoint(0, p.view(), d); }, "TOD sample 3 is nan");
  d[3] = 1.0;
  pisco_test::expect_error([&] { engine.adjoint(5, p.view(), d); }, "has a half-wave plate");
  std::vector<double> small(10);
  pisco::Sky back(16);
  pisco_test::expect_error([&] { engine.take_adjoint({small, back.Q(), back.U(), back.V()}); },
                           "the I map has 10 pixels; the engine's NSIDE 16 has 3072");
  EXPECT_EQ(pisco_test::kind_of([&] { engine.take_adjoint({back.I(), back.Q(), back.U(), small}); }),
            pisco::ErrorKind::input);
}

}  // namespace

namespace {
// set_sky: the TOD of a new sky equals that of an engine made with it, bit for bit, on every backend
// present (the polar copy and a split beam's coarse sky remade too).
TEST(EngineSetSky, GivesTheTodOfANewEngine) {
  const pisco_test::Scene scene = adjoint_scene(16);
  const pisco::Sky other = random_sky(16, 99);
  const pisco::Pointing p = pisco_test::random_pointing(200, 4);
  const std::vector<double> h = plate_angles(p.size());
  for (const pisco::BackendInfo& b : pisco::Engine::backends()) {
    if (!b.available) continue;
    pisco::EngineOptions o;
    o.backend = b.name;
    pisco::Engine engine(scene.sky, scene.beams, scene.focal_plane, o);
    std::vector<double> tod(p.size()), want(p.size());
    engine.convolve(0, p.view(), tod);
    engine.set_sky(other);
    pisco::Engine fresh(other, scene.beams, scene.focal_plane, o);
    for (std::size_t det = 0; det < scene.focal_plane.size(); ++det) {
      const std::span<const double> angles = scene.focal_plane[det].hwp ? std::span<const double>(h) : std::span<const double>();
      engine.convolve(det, p.view(), tod, false, angles);
      fresh.convolve(det, p.view(), want, false, angles);
      for (std::size_t i = 0; i < p.size(); ++i) ASSERT_EQ(tod[i], want[i]) << b.name << ", detector " << det << ", sample " << i;
    }
    pisco_test::expect_error([&] { engine.set_sky(pisco::Sky(8)); }, "the sky has NSIDE 8; the engine was made for NSIDE 16");
  }
}
}  // namespace

// The ring of a pixel (core/ring_slices.hpp), which the simd adjoint's windows are laid out by, at
// both ends of every ring, the poles included.
TEST(RingSlices, RingOfEveryRingsFirstAndLastPixel) {
  pisco::Sky sky(16);
  const pisco::detail::PreparedSky prepared = pisco::detail::prepare_sky(sky);
  const auto& rings = prepared.rings;
  for (std::uint32_t k = 0; k < rings.size(); ++k) {
    EXPECT_EQ(pisco::detail::ring_of(prepared, rings[k].first), k);
    EXPECT_EQ(pisco::detail::ring_of(prepared, rings[k].first + rings[k].count - 1), k);
  }
}

