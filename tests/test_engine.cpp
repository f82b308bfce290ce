// The float64 reference backend against a brute-force evaluation of the paper's pixelized equation
// (eq. discrete_beam_conv_tensor): HEALPix query_disc, Appendix A trigonometry and the full 4x4
// product D(chi) Lambda(chi) B Lambda(-chi) S per pixel; plus determinism, chunking and errors.
#include <gtest/gtest.h>

#include <functional>

#include <cmath>
#include <iostream>
#include <numbers>
#include <random>
#include <set>

#include <healpix_base.h>
#include <pointing.h>

#include "backend_fixtures.hpp"
#include "support.hpp"
#include "pisco/engine.hpp"
#include "pisco/hwp.hpp"
#include "pisco/error.hpp"
#include "pisco/units.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;
using Mat = std::array<std::array<double, 4>, 4>;

Mat lambda(double chi) {
  Mat m{};
  m[0][0] = m[3][3] = 1;
  m[1][1] = m[2][2] = std::cos(2 * chi);
  m[1][2] = -std::sin(2 * chi);
  m[2][1] = std::sin(2 * chi);
  return m;
}

// d(q) = sum_k Omega_pix D(chi) Lambda(chi) B(rho, sigma) Lambda(-chi) S_k, with Appendix A angles.
double brute_force(const pisco::Sky& sky, const pisco::Beamsor& beam, const pisco::Detector& det,
                   double theta0, double phi0, double psi0) {
  const Healpix_Base base(sky.nside(), RING, SET_NSIDE);
  std::vector<int> pixels;
  base.query_disc(pointing(theta0, phi0), beam.rho_max()).toVector(pixels);
  double d = 0;
  for (int p : pixels) {
    const pointing ang = base.pix2ang(p);
    const double dphi = ang.phi - phi0;
    const double st = std::sin(ang.theta), ct = std::cos(ang.theta), st0 = std::sin(theta0), ct0 = std::cos(theta0);
    const double cos_rho = ct * ct0 + st * st0 * std::cos(dphi);
    const double sin_rho = std::sqrt(std::max(0.0, 1 - cos_rho * cos_rho));
    const double alpha = std::atan2(st * std::sin(dphi), ct * st0 - st * ct0 * std::cos(dphi));
    const double sigma = pi - psi0 - alpha;
    const double beta = std::atan2(st0 * std::sin(dphi), ct0 * st - st0 * ct * std::cos(dphi));
    const double chi = beta + det.zeta - sigma;
    const auto B = beam.at(sin_rho * std::cos(sigma), sin_rho * std::sin(sigma));
    const double D[4] = {det.gain / 2 * (1 + det.epsilon), det.gain / 2 * (1 - det.epsilon) * std::cos(2 * chi),
                         det.gain / 2 * (1 - det.epsilon) * std::sin(2 * chi), 0};
    const double S[4] = {sky.I()[p], sky.Q()[p], sky.U()[p], sky.V()[p]};
    const Mat L = lambda(chi), Lm = lambda(-chi);
    double rot_s[4] = {}, bs[4] = {}, lbs[4] = {};
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) rot_s[i] += Lm[i][j] * S[j];
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) bs[i] += B[i][j] * rot_s[j];
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) lbs[i] += L[i][j] * bs[j];
    for (int i = 0; i < 4; ++i) d += sky.pixel_area() * D[i] * lbs[i] / beam.omega_tilde();
  }
  return d;
}

pisco::Sky random_sky(int nside, std::uint64_t seed) {
  pisco::Sky sky(nside);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  for (std::size_t i = 0; i < sky.npix(); ++i) {
    sky.I()[i] = 10 + g(rng);
    sky.Q()[i] = g(rng);
    sky.U()[i] = g(rng);
    sky.V()[i] = 0.1 * g(rng);
  }
  return sky;
}

struct Scene {
  pisco::Sky sky = random_sky(64, 11);
  std::vector<pisco::Beamsor> beams;
  pisco::FocalPlane fp;
  pisco::Pointing ptg;
  Scene() {
    pisco::BeamOptions o;
    o.rho_max = 8 * deg;
    o.cross_polar = 0.05;
    o.cross_polar_pattern = pisco::CrossPolarPattern::quadrupole;
    o.mueller[1][0] = 0.003;  // T -> Q leakage
    o.mueller[3][3] = 0.5;
    beams.push_back(pisco::Beamsor::elliptical_gaussian(3.0 * deg, 2.2 * deg, 25 * deg, o));
    o.cross_polar = 0.02;
    o.cross_polar_pattern = pisco::CrossPolarPattern::uniform;
    beams.push_back(pisco::Beamsor::elliptical_gaussian(2.6 * deg, 3.1 * deg, -40 * deg, o));
    o.cross_polar = 0.03;  // a round beam with uniform cross-polar: stored as a radial profile
    beams.push_back(pisco::Beamsor::gaussian(2.5 * deg, o));
    fp.add_pair("p0", 22 * deg, 0, 1, 0.03, 1.1, 0.95);
    fp.add({"single", -63 * deg, 0.2, 0.8, 1});
    fp.add({"round", 141 * deg, 0.05, 1.2, 2});
    std::mt19937_64 rng(21);
    std::uniform_real_distribution<double> u(0, 1);
    for (int i = 0; i < 60; ++i) ptg.push_back(std::acos(1 - 2 * u(rng)), 2 * pi * u(rng), 2 * pi * u(rng) - pi);
    for (int i = 0; i < 20; ++i) {  // near the poles, discs covering a pole
      ptg.push_back(u(rng) * 6 * deg, 2 * pi * u(rng), 2 * pi * u(rng));
      ptg.push_back(pi - u(rng) * 6 * deg, 2 * pi * u(rng), 2 * pi * u(rng));
    }
    ptg.push_back(1.0, -0.3, 0.2);        // phi outside [0, 2 pi) is wrapped
    ptg.push_back(2.0, 2 * pi + 0.1, 0.2);
  }
};

TEST(Engine, ReferenceEqualsBruteForce) {
  Scene s;
  pisco::Engine engine(s.sky, s.beams, s.fp, {.backend = "cpu", .settings = {{"threads", 2LL}}, .quadrature = pisco::Quadrature::plain});
  double worst = 0, rms = 0;
  for (std::size_t det = 0; det < s.fp.size(); ++det) {
    std::vector<double> tod(s.ptg.size(), NAN);
    engine.convolve(det, s.ptg, tod);
    for (std::size_t i = 0; i < s.ptg.size(); ++i) {
      const double ref = brute_force(s.sky, s.beams[s.fp[det].beam], s.fp[det], s.ptg.theta[i], s.ptg.phi[i], s.ptg.psi[i]);
      const double rel = std::abs(tod[i] - ref) / std::abs(ref);
      worst = std::max(worst, rel);
      rms += rel * rel;
    }
  }
  rms = std::sqrt(rms / (s.fp.size() * s.ptg.size()));
  std::cout << "cpu vs brute force (elliptical beams, cross-polar, Mueller leakage, PSB pair, poles): max rel "
            << worst << ", rms rel " << rms << ", mean disc " << engine.mean_disc_pixels() << " pixels\n";
  EXPECT_LT(worst, 1e-11);
}

TEST(Engine, DeterministicAcrossThreadsAndChunks) {
  Scene s;
  pisco::Engine one(s.sky, s.beams, s.fp, {.backend = "cpu", .settings = {{"threads", 1LL}}});
  pisco::Engine two(s.sky, s.beams, s.fp, {.backend = "cpu", .settings = {{"threads", 2LL}}});
  std::vector<double> a(s.ptg.size()), b(s.ptg.size(), NAN), c(s.ptg.size(), NAN);
  one.convolve(1, s.ptg, a);
  two.convolve(1, s.ptg, b);
  const pisco::PointingView v = s.ptg.view();
  for (std::size_t off = 0, step = 1; off < v.size(); off += step, step = step * 2 + 1) {
    const std::size_t n = std::min(step, v.size() - off);
    two.convolve(1, v.subspan(off, n), std::span<double>(c).subspan(off, n));
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i], b[i]) << "sample " << i;
    EXPECT_EQ(a[i], c[i]) << "sample " << i;
  }
}

TEST(Engine, NormalizationModes) {
  // A constant unpolarized sky: per-sample normalization gives s/2 (1 + eps) exactly; the integral
  // normalization differs from it by the discrete-sum error of the pixelized beam only.
  pisco::Sky sky(256);
  for (double& v : sky.I()) v = 1.0;
  pisco::BeamOptions o;
  o.rho_max = 5 * deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::elliptical_gaussian(1.5 * deg, 1.2 * deg, 10 * deg, o)};
  pisco::FocalPlane fp;
  fp.add({"d", 0.4, 0.1, 1.7, 0});
  pisco::Pointing ptg;
  for (int i = 0; i < 50; ++i) ptg.push_back(0.02 + i * 0.06, i * 0.37, i * 0.11);
  std::vector<double> integral(ptg.size()), per_sample(ptg.size());
  pisco::Engine(sky, beams, fp, {.quadrature = pisco::Quadrature::plain}).convolve(0, ptg, integral);
  pisco::Engine(sky, beams, fp, {.normalization = pisco::Normalization::per_sample, .quadrature = pisco::Quadrature::plain})
      .convolve(0, ptg, per_sample);
  const double expected = 1.7 / 2 * 1.1;
  double worst = 0;
  for (std::size_t i = 0; i < ptg.size(); ++i) {
    EXPECT_NEAR(per_sample[i], expected, 1e-13);
    worst = std::max(worst, std::abs(integral[i] / expected - 1));
  }
  std::cout << "integral normalization on a constant sky (NSIDE 256, 1.5 x 1.2 deg beam): max |d/d_exact - 1| "
            << worst << "\n";
  // The quadrature error of a 1.2 deg beam summed over NSIDE 256 pixels (the paper's flux figure).
  EXPECT_LT(worst, 3e-3);
}

TEST(Engine, BackendsAndErrors) {
  Scene s;
  const auto backends = pisco::Engine::backends();
  ASSERT_FALSE(backends.empty());
  EXPECT_EQ(backends[0].name, "cpu");
  EXPECT_TRUE(backends[0].available);
  const auto message = pisco_test::error_of;
  EXPECT_NE(message([&] { pisco::Engine(s.sky, s.beams, s.fp, {.backend = "opencl"}); }).find("unknown"), std::string::npos);
  // Error kinds (pisco/error.hpp): a caller can tell a bad request from a backend this machine lacks.
  EXPECT_EQ(pisco_test::kind_of([&] { pisco::Engine(s.sky, s.beams, s.fp, {.backend = "opencl"}); }),
            pisco::ErrorKind::input);
  for (const auto& b : backends)
    if (!b.available)
      EXPECT_EQ(pisco_test::kind_of([&] { pisco::Engine(s.sky, s.beams, s.fp, {.backend = b.name}); }),
                pisco::ErrorKind::unavailable)
          << b.name;
  EXPECT_STREQ(pisco::error_kind_name(pisco::ErrorKind::unavailable), "unavailable");
  // A file that cannot be created: io; a file that is not a map: input.
  EXPECT_EQ(pisco_test::kind_of([&] { s.sky.write_fits("/proc/no-such-directory/sky.fits"); }), pisco::ErrorKind::io);
  EXPECT_EQ(pisco_test::kind_of([&] { pisco::Sky::read_fits("/proc/self/status"); }), pisco::ErrorKind::input);
  pisco::FocalPlane bad;
  bad.add({"lost", 0, 0, 1, 7});
  EXPECT_NE(message([&] { pisco::Engine(s.sky, s.beams, bad); }).find("beam index 7"), std::string::npos);
  pisco::Sky nan_sky = s.sky;
  nan_sky.Q()[5] = NAN;
  EXPECT_NE(message([&] { pisco::Engine(nan_sky, s.beams, s.fp); }).find("5"), std::string::npos);

  pisco::Engine engine(s.sky, s.beams, s.fp, {.backend = "auto"});
  // "auto" ranks by measured speed (src/core/backend.hpp): the float64 reference only where nothing
  // else runs, cuda wherever it runs, simd above vulkan on a CPU device.
  std::set<std::string> available;
  for (const auto& b : backends)
    if (b.available) available.insert(b.name);
  EXPECT_TRUE(available.count(engine.backend_name())) << engine.backend_name();
  if (available.size() > 1) EXPECT_NE(engine.backend_name(), "cpu");
  if (available.count("cuda")) EXPECT_EQ(engine.backend_name(), "cuda");
  for (const auto& b : backends)
    if (b.name == "vulkan" && b.available && available.count("simd") && pisco_test::contains(b.detail, "(auto: ") &&
        pisco_test::contains(b.detail.substr(b.detail.find("(auto: ")), "[cpu"))
      EXPECT_EQ(engine.backend_name(), available.count("cuda") ? "cuda" : "simd") << "simd ranks above lavapipe";
  pisco::Pointing p = s.ptg;
  std::vector<double> tod(p.size());
  p.theta[17] = 3.5;
  EXPECT_NE(message([&] { engine.convolve(0, p, tod); }).find("sample 17"), std::string::npos);
  p.theta[17] = 1.0;
  p.phi[3] = INFINITY;
  EXPECT_NE(message([&] { engine.convolve(0, p, tod); }).find("sample 3"), std::string::npos);
  std::vector<double> short_tod(3);
  EXPECT_NE(message([&] { engine.convolve(0, s.ptg, short_tod); }).find("3 samples"), std::string::npos);
  EXPECT_NE(message([&] { engine.convolve(9, s.ptg, tod); }).find("detector index 9"), std::string::npos);
}

// The scene's detectors moved off the boresight: every offset spelling, gamma included.
pisco::FocalPlane offset_focal_plane(const pisco::FocalPlane& fp) {
  std::vector<pisco::Detector> dets = fp.detectors();
  const double offsets[][3] = {{2 * deg, -1 * deg, 0.3}, {-4 * deg, 3 * deg, -1.2}, {0, 6 * deg, 0}, {1 * deg, 0, 2.5}};
  for (std::size_t i = 0; i < dets.size(); ++i) dets[i].set_offset(offsets[i % 4][0], offsets[i % 4][1], offsets[i % 4][2]);
  return pisco::FocalPlane(dets);
}

double rms_of(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / double(v.size()));
}

double max_abs_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}

// The engine owns the offsets: a detector off the boresight, given the boresight's pointing (as
// angles or as quaternions), gets the TOD of its own pointing (expanded on the host and given to a
// detector on the boresight), not the boresight's.
// Every setting by name through the one table (pisco::set_engine_option), as simulation files,
// pisco-vk and Python set them; each error carries the setting's name as its key, and its message does
// not repeat it (the caller names it as its own key, keyword or flag).
TEST(EngineOptions, EverySettingByNameThroughOneTable) {
  const auto key_of = [](const std::function<void()>& f) {
    try {
      f();
    } catch (const pisco::Error& e) {
      EXPECT_EQ(e.kind(), pisco::ErrorKind::input);
      return e.key() + " | " + e.what();
    }
    return std::string("no error");
  };
  pisco::EngineOptions o;
  std::vector<std::string> names;
  for (const pisco::EngineSetting& s : pisco::engine_settings()) names.push_back(s.name);
  EXPECT_EQ(names, (std::vector<std::string>{"backend", "threads", "device", "chunk_samples", "arithmetic",
                                              "normalization", "unseen", "quadrature"}));
  pisco::set_engine_option(o, "backend", std::string("auto"));
  pisco::set_engine_option(o, "device", std::string("1"));
  pisco::set_engine_option(o, "threads", 3LL);
  pisco::set_engine_option(o, "chunk_samples", 4096LL);
  pisco::set_engine_option(o, "arithmetic", std::string("float-float"));
  pisco::set_engine_option(o, "normalization", std::string("per_sample"));
  pisco::set_engine_option(o, "unseen", std::string("flag"));
  pisco::set_engine_option(o, "quadrature", std::string("plain"));
  EXPECT_EQ(o.backend, "auto");
  EXPECT_EQ(o.text("device"), "1");
  EXPECT_EQ(o.number("threads"), 3u);
  EXPECT_EQ(o.number("chunk_samples"), 4096u);
  EXPECT_EQ(o.text("arithmetic"), "float-float");
  EXPECT_EQ(o.settings.size(), 4u);
  EXPECT_EQ(o.normalization, pisco::Normalization::per_sample);
  EXPECT_EQ(o.unseen, pisco::UnseenPolicy::flag);
  EXPECT_EQ(o.quadrature, pisco::Quadrature::plain);
  // Every value's name and back.
  for (auto v : {pisco::Normalization::integral, pisco::Normalization::per_sample})
    EXPECT_EQ(pisco::normalization_from(pisco::normalization_name(v)), v);
  for (auto v : {pisco::Quadrature::corrected, pisco::Quadrature::plain})
    EXPECT_EQ(pisco::quadrature_from(pisco::quadrature_name(v)), v);
  for (auto v : {pisco::UnseenPolicy::error, pisco::UnseenPolicy::zero, pisco::UnseenPolicy::flag})
    EXPECT_EQ(pisco::unseen_policy_from(pisco::unseen_policy_name(v)), v);
  // What each takes, and the backends it applies to, as their entries declare them.
  for (const pisco::EngineSetting& s : pisco::engine_settings()) {
    const std::string n = s.name;
    if (n == "threads") EXPECT_STREQ(s.backends, "cpu and simd");
    if (n == "chunk_samples") EXPECT_STREQ(s.backends, "vulkan and cuda");
    if (n == "arithmetic") EXPECT_STREQ(s.takes, "\"auto\", \"float64\" or \"float-float\"");
    if (n == "device") {
      EXPECT_STREQ(s.backends, "simd, vulkan and cuda");
      EXPECT_STREQ(s.takes, "an instruction set (\"AVX3\", \"AVX2\", \"SSE4\", \"NEON\", ...) or \"auto\" (simd); \"auto\", "
                            "a device's index or part of its name (vulkan and cuda)");
    }
    EXPECT_EQ(s.number, n == "threads" || n == "chunk_samples") << n;
  }

  EXPECT_EQ(key_of([&] { pisco::set_engine_option(o, "normalisation", std::string("integral")); }),
            "normalisation | not a setting of the engine (expected one of backend, threads, device, chunk_samples, "
            "arithmetic, normalization, unseen, quadrature)");
  EXPECT_EQ(key_of([&] { pisco::set_engine_option(o, "threads", std::string("4")); }), "threads | expected a number, got \"4\"");
  EXPECT_EQ(key_of([&] { pisco::set_engine_option(o, "chunk_samples", -1LL); }),
            "chunk_samples | expected a number of zero or more, got -1");
  EXPECT_EQ(key_of([&] { pisco::set_engine_option(o, "quadrature", 1LL); }),
            "quadrature | expected \"corrected\" or \"plain\", got the number 1");
  EXPECT_EQ(key_of([&] { pisco::set_engine_option(o, "unseen", std::string("mask")); }),
            "unseen | expected \"error\", \"zero\" or \"flag\", got \"mask\"");
  EXPECT_EQ(key_of([&] { pisco::set_engine_option(o, "arithmetic", std::string("double")); }),
            "arithmetic | expected \"auto\", \"float64\" or \"float-float\", got \"double\"");
  EXPECT_EQ(key_of([&] {
              pisco::set_engine_option(o, "threads", static_cast<long long>(pisco::Engine::max_threads()) + 1);
            }).substr(0, 40),
            "threads | expected 0 (all hardware threa");
  EXPECT_EQ(o.number("threads"), 3u);  // a refused value leaves the options as they were
  pisco::EngineOptions cpu;
  pisco::set_engine_option(cpu, "backend", std::string("cpu"));
  EXPECT_EQ(key_of([&] { pisco::set_engine_option(cpu, "arithmetic", std::string("float64")); }),
            "arithmetic | the cpu backend has no arithmetic setting (it applies to vulkan)");
  // The error named as a caller names it.
  try {
    pisco::set_engine_option(cpu, "device", std::string("0"));
    ADD_FAILURE() << "no error";
  } catch (const pisco::Error& e) {
    EXPECT_EQ(e.named("[engine] "), "[engine] device: the cpu backend has no device setting (it applies to simd, vulkan and cuda)");
  }
}

// Under "auto" a setting goes to every backend that takes it; a named backend takes its own, the
// default of one it lacks says nothing, and another value is an error naming the backends that have
// it, also when the backend is named after the setting, and when the engine is given the options.
TEST(EngineOptions, SettingsGoToTheBackendsThatTakeThem) {
  EXPECT_TRUE(pisco::backend_has_setting("simd", "device"));
  EXPECT_TRUE(pisco::backend_has_setting("cpu", "threads"));
  EXPECT_FALSE(pisco::backend_has_setting("cpu", "device"));
  EXPECT_FALSE(pisco::backend_has_setting("vulkan", "threads"));
  EXPECT_FALSE(pisco::backend_has_setting("no-such-backend", "threads"));
  EXPECT_EQ(pisco::Engine::backend_names(), (std::vector<std::string>{"cpu", "simd", "vulkan", "cuda"}));

  pisco::EngineOptions vulkan{.backend = "vulkan"};
  vulkan.set("device", "0").set("threads", 0LL).set("device", "");  // the default: nothing to say
  EXPECT_EQ(vulkan.text("device"), "auto");
  pisco_test::expect_error([&] { vulkan.set("threads", 2LL); },
                           "the vulkan backend has no threads setting (it applies to cpu and simd)");
  EXPECT_EQ(vulkan.number("threads"), 0u);

  pisco::EngineOptions cpu{.backend = "cpu"};
  cpu.set("device", "auto").set("chunk_samples", 0LL).set("arithmetic", "auto");
  pisco_test::expect_error([&] { cpu.set("device", "0"); },
                           "the cpu backend has no device setting (it applies to simd, vulkan and cuda)");
  pisco_test::expect_error([&] { cpu.set("chunk_samples", 10LL); },
                           "the cpu backend has no chunk_samples setting (it applies to vulkan and cuda)");

  // Named afterwards: the settings given are checked against it, and a refusal leaves the options.
  pisco::EngineOptions later{.backend = "auto"};
  later.set("threads", 4LL);
  later.set("backend", "simd");
  pisco_test::expect_error([&] { later.set("backend", "cuda"); },
                           "the cuda backend has no threads setting (it applies to cpu and simd)");
  EXPECT_EQ(later.backend, "simd");

  // Options for another backend (the one "auto" chose, [ground]'s): its own settings kept, the others
  // dropped, and a device given for another named backend left with it; the engine-wide ones kept.
  pisco::EngineOptions simd_options{.backend = "simd", .quadrature = pisco::Quadrature::plain};
  simd_options.set("threads", 2LL).set("device", "AVX2");
  const pisco::EngineOptions for_vulkan = pisco::options_for_backend(simd_options, "vulkan");
  EXPECT_EQ(for_vulkan.backend, "vulkan");
  EXPECT_TRUE(for_vulkan.settings.empty());
  EXPECT_EQ(for_vulkan.quadrature, pisco::Quadrature::plain);
  const pisco::EngineOptions for_cpu = pisco::options_for_backend(simd_options, "cpu");
  EXPECT_EQ(for_cpu.number("threads"), 2u);
  EXPECT_EQ(for_cpu.settings.size(), 1u);
  pisco::EngineOptions any{.backend = "auto"};
  any.set("threads", 3LL).set("device", "1").set("arithmetic", "float-float");
  const pisco::EngineOptions for_cuda = pisco::options_for_backend(any, "cuda");
  EXPECT_EQ(for_cuda.text("device"), "1");
  EXPECT_EQ(for_cuda.settings.size(), 1u);
  EXPECT_EQ(pisco::options_for_backend(any, "vulkan").text("arithmetic"), "float-float");

  // A setting read as a backend reads it: of the wrong type, an error naming it.
  pisco::EngineOptions typed{.settings = {{"threads", std::string("two")}}};
  pisco_test::expect_error([&] { typed.number("threads"); }, "expected a number, got \"two\"");

  const pisco::Sky sky(8);
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  pisco::BeamOptions o;
  o.rho_max = 10 * pisco::deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(4 * pisco::deg, o)};
  // The engine checks options made by hand as set() does.
  EXPECT_EQ(pisco_test::error_of([&] { pisco::Engine(sky, beams, fp, {.backend = "cpu", .settings = {{"device", "1"}}}); }),
            "device: the cpu backend has no device setting (it applies to simd, vulkan and cuda)");
  EXPECT_EQ(pisco_test::error_of([&] { pisco::Engine(sky, beams, fp, {.settings = {{"thread", 2LL}}}); }).substr(0, 51),
            "thread: not a setting of the engine (expected one o");
  EXPECT_NO_THROW(pisco::Engine(sky, beams, fp, {.backend = "cpu", .settings = {{"chunk_samples", 0LL}}}));
  // The simd backend's device is its instruction set.
  if (pisco_test::backend_unavailable("simd").empty())
    pisco_test::expect_error([&] { pisco::Engine(sky, beams, fp, {.backend = "simd", .settings = {{"device", "no-such-set"}}}); },
                             "no-such-set");
}

TEST(Engine, OffsetDetectorsGetTheirOwnPointingInEveryForm) {
  Scene s;
  const pisco::FocalPlane moved = offset_focal_plane(s.fp);
  pisco::Engine on_boresight(s.sky, s.beams, s.fp, {.backend = "cpu", .settings = {{"threads", 2LL}}});
  pisco::Engine offset(s.sky, s.beams, moved, {.backend = "cpu", .settings = {{"threads", 2LL}}});
  std::vector<pisco::Quat> quats;
  for (std::size_t i = 0; i < s.ptg.size(); ++i)
    quats.push_back(pisco::quat_from_pointing(s.ptg.theta[i], s.ptg.phi[i], s.ptg.psi[i]));
  double worst_angles = 0, worst_quats = 0;
  for (std::size_t det = 0; det < s.fp.size(); ++det) {
    pisco::Pointing own;
    pisco::detector_pointing(s.ptg.view(), moved[det].offset, own);
    std::vector<double> expected(s.ptg.size(), NAN), boresight(s.ptg.size(), NAN), from_angles(s.ptg.size(), NAN),
        from_quats(s.ptg.size(), NAN);
    on_boresight.convolve(det, own, expected);
    on_boresight.convolve(det, s.ptg, boresight);
    offset.convolve(det, s.ptg, from_angles);
    offset.convolve(det, pisco::QuatPointingView{quats}, from_quats);
    const double scale = rms_of(expected);
    worst_angles = std::max(worst_angles, max_abs_diff(from_angles, expected) / scale);
    worst_quats = std::max(worst_quats, max_abs_diff(from_quats, expected) / scale);
    EXPECT_GT(max_abs_diff(from_angles, boresight) / scale, 1e-3) << "detector " << det << " got the boresight's TOD";
  }
  std::cout << "offset detectors: boresight angles vs expanded pointing, max |diff|/rms " << worst_angles
            << "; boresight quaternions " << worst_quats << "\n";
  EXPECT_LT(worst_angles, 1e-12);
  EXPECT_LT(worst_quats, 1e-12);
}

TEST(Engine, AccumulateAddsIntoTheTod) {
  Scene s;
  pisco::Engine engine(s.sky, s.beams, s.fp, {.backend = "cpu", .settings = {{"threads", 2LL}}});
  std::vector<double> d(s.ptg.size()), sum(s.ptg.size());
  engine.convolve(2, s.ptg, d);
  for (std::size_t i = 0; i < sum.size(); ++i) sum[i] = 0.25 * double(i) - 3;
  std::vector<double> expected(sum.size());
  for (std::size_t i = 0; i < sum.size(); ++i) expected[i] = sum[i] + d[i];
  engine.convolve(2, s.ptg, sum, /*accumulate=*/true);
  EXPECT_EQ(sum, expected);
}

// submit() and wait(): several submissions in flight, for several detectors, give what convolve()
// gives, bit for bit.
TEST(Engine, SubmitThenWaitEqualsConvolve) {
  Scene s;
  const pisco::FocalPlane moved = offset_focal_plane(s.fp);
  pisco::Engine engine(s.sky, s.beams, moved, {.backend = "cpu", .settings = {{"threads", 2LL}}});
  std::vector<std::vector<double>> direct(moved.size()), queued(moved.size());
  for (std::size_t det = 0; det < moved.size(); ++det) {
    direct[det].assign(s.ptg.size(), NAN);
    queued[det].assign(s.ptg.size(), NAN);
    engine.convolve(det, s.ptg, direct[det]);
  }
  std::uint64_t last = 0;
  for (std::size_t off = 0; off < s.ptg.size(); off += 37)
    for (std::size_t det = 0; det < moved.size(); ++det) {
      const std::size_t n = std::min<std::size_t>(37, s.ptg.size() - off);
      last = engine.submit(det, s.ptg.view().subspan(off, n), std::span<double>(queued[det]).subspan(off, n));
    }
  engine.wait(last);
  for (std::size_t det = 0; det < moved.size(); ++det) EXPECT_EQ(queued[det], direct[det]) << "detector " << det;
}

// Every part of a submission (the main sum, the polar copy's samples, a split beam's outer part, a
// plate's row detectors) is queued before any wait, and the polar copy is made at set-up
// (Engine::prepare) or, without it, by the first submission that needs it: the same bits as
// convolving detector by detector, on every backend here.
TEST(Engine, EveryPartQueuedBeforeAnyWaitAndPreparedAtSetUp) {
  Scene s;
  pisco::BeamOptions o;
  o.rho_max = 12 * deg;
  o.split.rho_main = 6 * deg;
  s.beams.push_back(pisco::Beamsor::gaussian(2.5 * deg, o));
  std::vector<pisco::Detector> dets = offset_focal_plane(s.fp).detectors();
  dets.push_back({"split", 30 * deg, 0.02, 1.0, 3});
  dets.push_back({"plated", -20 * deg, 0.01, 0.9, 0});
  dets.back().hwp = pisco::HalfWavePlate{pisco::ideal_hwp_mueller(), pisco::HwpPlacement::detector, dets.back().zeta};
  const pisco::FocalPlane fp(dets);
  std::vector<double> hwp(s.ptg.size());
  for (std::size_t i = 0; i < hwp.size(); ++i) hwp[i] = 0.37 * double(i);
  const auto angles = [&](std::size_t det) { return dets[det].hwp ? std::span<const double>(hwp) : std::span<const double>(); };
  for (const std::string backend : {"cpu", "simd", "vulkan"}) {
    if (const std::string why = pisco_test::backend_unavailable(backend); !why.empty()) {
      ADD_FAILURE() << backend << " is not available: " << why;
      continue;
    }
    const pisco::EngineOptions options{.backend = backend};
    std::vector<std::vector<double>> direct(fp.size(), std::vector<double>(s.ptg.size(), NAN));
    pisco::Engine one_by_one(s.sky, s.beams, fp, options);
    for (std::size_t det = 0; det < fp.size(); ++det) one_by_one.convolve(det, s.ptg, direct[det], false, angles(det));
    for (const bool prepare : {true, false}) {
      pisco::Engine engine(s.sky, s.beams, fp, options);
      EXPECT_TRUE(engine.polar_copy());
      EXPECT_GT(engine.sidelobe_nside(), 0);
      if (prepare) engine.prepare();
      std::vector<std::vector<double>> queued(fp.size(), std::vector<double>(s.ptg.size(), NAN));
      for (std::size_t det = 0; det < fp.size(); ++det) engine.submit(det, s.ptg, queued[det], false, angles(det));
      engine.wait();
      for (std::size_t det = 0; det < fp.size(); ++det)
        EXPECT_EQ(queued[det], direct[det]) << backend << ", detector " << fp[det].name << (prepare ? ", prepared" : "");
      EXPECT_GT(engine.polar_samples(), 0u) << backend;
      EXPECT_EQ(engine.polar_samples(), one_by_one.polar_samples()) << backend;
    }
    {  // an engine let go with every part of every detector in flight: its backends finish first
      std::vector<std::vector<double>> queued(fp.size(), std::vector<double>(s.ptg.size(), NAN));
      pisco::Engine engine(s.sky, s.beams, fp, options);
      for (std::size_t det = 0; det < fp.size(); ++det) engine.submit(det, s.ptg, queued[det], false, angles(det));
    }
  }
}

// A scan across the north pole: the samples within the polar cut are summed once, on the polar copy
// that the sky's own backend holds, and the others once on the sky. The pixels the engine reports are
// exactly those of each sample's disc where it is summed (HEALPix's query_disc around its line of
// sight, turned by R for the polar ones), on every backend here; the TOD is that of an engine given
// the samples one by one (every one in a run of its own, short runs summed on both).
TEST(Engine, PolarSamplesAreSummedOnceBesideTheSky) {
  Scene s;
  const int nside = s.sky.nside();
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const std::size_t det = 3;  // "round": on the boresight
  const double rho = 8 * deg, cut = rho + 4.0 * std::sqrt(pi / 3) / nside;
  pisco::Pointing ptg;
  for (int i = 0; i < 300; ++i) ptg.push_back(pi / 2 + 0.2 * std::sin(i), 0.01 * i, 0.3);
  for (int i = 0; i <= 1000; ++i) {  // colatitude 25 deg, across the pole, 25 deg on the other side
    const double t = (-25.0 + 0.05 * i) * deg;
    ptg.push_back(std::abs(t), t < 0 ? 0.3 + pi : 0.3, 0.1 * i);
  }
  std::uint64_t expected = 0;
  std::size_t polar = 0;
  std::vector<int> pix;
  for (std::size_t i = 0; i < ptg.size(); ++i) {
    const double th = ptg.theta[i], ph = ptg.phi[i];
    const vec3 v(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
    const bool near = th < cut || th > pi - cut;
    polar += near;
    base.query_disc(near ? pointing(vec3(v.z, v.y, -v.x)) : pointing(v), rho, pix);
    expected += pix.size();
  }
  ASSERT_GT(polar, 400u);
  for (const std::string backend : {"cpu", "simd", "vulkan"}) {
    if (const std::string why = pisco_test::backend_unavailable(backend); !why.empty()) {
      ADD_FAILURE() << backend << " is not available: " << why;
      continue;
    }
    pisco::Engine engine(s.sky, s.beams, s.fp, {.backend = backend});
    std::vector<double> tod(ptg.size()), one(ptg.size());
    engine.convolve(det, ptg, tod);
    EXPECT_EQ(engine.polar_samples(), polar) << backend;
    EXPECT_EQ(std::llround(engine.mean_disc_pixels() * double(ptg.size())), std::int64_t(expected)) << backend;
    pisco::Engine by_sample(s.sky, s.beams, s.fp, {.backend = backend});
    for (std::size_t i = 0; i < ptg.size(); ++i) by_sample.convolve(det, ptg.view().subspan(i, 1), std::span(one).subspan(i, 1));
    EXPECT_EQ(tod, one) << backend;
  }
}

TEST(Engine, BadQuaternionsAndOffsetsAreNamed) {
  Scene s;
  const auto message = pisco_test::error_of;
  pisco::Engine engine(s.sky, s.beams, s.fp, {.backend = "cpu"});
  std::vector<pisco::Quat> q(20);
  std::vector<double> tod(q.size());
  q[7] = {0.1, 0, 0, 1};
  std::string m = message([&] { engine.convolve(1, pisco::QuatPointingView{q}, tod); });
  EXPECT_NE(m.find("sample 7"), std::string::npos) << m;
  EXPECT_NE(m.find("'p0b'"), std::string::npos) << m;
  q[7] = {0, 0, NAN, 1};
  EXPECT_NE(message([&] { engine.convolve(1, pisco::QuatPointingView{q}, tod); }).find("sample 7"), std::string::npos);
  std::vector<pisco::Detector> dets = s.fp.detectors();
  dets[2].offset = {0, 0, 0, 2};
  m = message([&] { pisco::Engine(s.sky, s.beams, pisco::FocalPlane(dets)); });
  EXPECT_NE(m.find("'single'"), std::string::npos) << m;
  EXPECT_NE(m.find("unit quaternion"), std::string::npos) << m;
}

}  // namespace

namespace {

// A sky the caller holds (pisco::SkyView over its own arrays): the engine reads it without a Sky,
// gives the TOD of the same maps as a Sky bit for bit, and keeps what it needs, so the arrays may
// change once it is made. A view checks its maps' sizes; without V, V is zero.
TEST(Engine, SkyViewOfTheCallersArrays) {
  Scene s;
  std::vector<double> I(s.sky.I().begin(), s.sky.I().end()), Q(s.sky.Q().begin(), s.sky.Q().end()),
      U(s.sky.U().begin(), s.sky.U().end()), V(s.sky.V().begin(), s.sky.V().end());
  pisco::Engine from_sky(s.sky, s.beams, s.fp, {.settings = {{"threads", 2LL}}});
  std::vector<double> want(s.ptg.size()), got(s.ptg.size());
  from_sky.convolve(1, s.ptg, want);
  for (const char* backend : {"cpu", "simd"}) {
    if (std::string(backend) == "simd" && !pisco_test::backend_unavailable("simd").empty()) continue;
    std::vector<double> i2 = I, q2 = Q, u2 = U, v2 = V;
    pisco::Engine from_view(pisco::SkyView(s.sky.nside(), i2, q2, u2, v2), s.beams, s.fp,
                            {.backend = backend, .settings = {{"threads", 2LL}}});
    std::fill(i2.begin(), i2.end(), 1e30);  // the engine holds its own copy
    std::fill(q2.begin(), q2.end(), 1e30);
    from_view.convolve(1, s.ptg, got);
    if (std::string(backend) == "cpu") {
      EXPECT_EQ(got, want);
    } else {
      pisco::Engine simd_sky(s.sky, s.beams, s.fp, {.backend = "simd", .settings = {{"threads", 2LL}}});
      std::vector<double> simd_want(s.ptg.size());
      simd_sky.convolve(1, s.ptg, simd_want);
      EXPECT_EQ(got, simd_want);
    }
  }
  // No V: zero, as a Sky's V of zeros.
  pisco::Sky no_v = s.sky;
  std::fill(no_v.V().begin(), no_v.V().end(), 0.0);
  pisco::Engine a(no_v, s.beams, s.fp, {.settings = {{"threads", 2LL}}});
  pisco::Engine b(pisco::SkyView(s.sky.nside(), I, Q, U), s.beams, s.fp, {.settings = {{"threads", 2LL}}});
  std::vector<double> ta(s.ptg.size()), tb(s.ptg.size());
  a.convolve(0, s.ptg, ta);
  b.convolve(0, s.ptg, tb);
  EXPECT_EQ(ta, tb);
  // A Sky made from a view is a copy of its maps.
  const pisco::Sky copy(pisco::SkyView(s.sky.nside(), I, Q, U, V, "uK_CMB"));
  EXPECT_TRUE(std::equal(copy.Q().begin(), copy.Q().end(), Q.begin()));
  EXPECT_EQ(copy.units(), "uK_CMB");
  // Sizes and NSIDE checked, naming the map.
  std::vector<double> short_map(I.begin(), I.end() - 1);
  pisco_test::expect_error([&] { pisco::SkyView(s.sky.nside(), I, short_map, U); }, "Stokes Q map has");
  pisco_test::expect_error([&] { pisco::SkyView(3, I, Q, U); }, "NSIDE = 3");
  // Its checks are the Sky's.
  std::vector<double> bad = U;
  bad[7] = NAN;
  pisco_test::expect_error([&] { pisco::Engine(pisco::SkyView(s.sky.nside(), I, Q, bad), s.beams, s.fp); }, "pixel 7");
}

}  // namespace

namespace {

// Backends say what they can do (BackendCapabilities): the reference alone is float64 throughout,
// the host backends run their own threads, a GPU backend reports its device's memory.
TEST(Engine, BackendsReportCapabilities) {
  for (const auto& b : pisco::Engine::backends()) {
    if (!b.available) continue;
    EXPECT_EQ(b.capabilities.float64, b.name == "cpu") << b.name;
    EXPECT_EQ(b.capabilities.worker_threads, b.name == "cpu" || b.name == "simd") << b.name;
    EXPECT_EQ(b.capabilities.worker_threads, pisco::backend_has_setting(b.name, "threads")) << b.name;
    EXPECT_EQ(b.capabilities.normal, b.name == "simd") << b.name;
    EXPECT_TRUE(b.capabilities.plates) << b.name;
    // The adjoint is where a backend says it is, and an error of kind unavailable elsewhere.
    {
      pisco::Sky sky(4);
      pisco::FocalPlane fp;
      fp.add({"d", 0.0, 0.0, 1.0, 0});
      pisco::EngineOptions o;
      o.backend = b.name;
      pisco::BeamOptions wide;
      wide.rho_max = 30 * pisco::deg;
      pisco::Engine engine(sky, {pisco::Beamsor::gaussian(10 * pisco::deg, wide)}, fp, o);
      pisco::Pointing p;
      p.push_back(1.0, 2.0, 0.5);
      const std::vector<double> d{1.0};
      if (b.capabilities.adjoint) {
        pisco::Sky back(4);
        engine.adjoint(0, p, d);
        engine.take_adjoint({back.I(), back.Q(), back.U(), back.V()});
        double sum = 0;
        for (double x : back.I()) sum += x;
        EXPECT_GT(sum, 0.0) << b.name;
      } else {
        EXPECT_EQ(pisco_test::kind_of([&] { engine.adjoint(0, p, d); }), pisco::ErrorKind::unavailable) << b.name;
      }
    }
    // Every backend has it; a Vulkan device only with 64-bit integer atomics (lavapipe has them).
    if (b.name != "vulkan") EXPECT_TRUE(b.capabilities.adjoint) << b.name;
    if (b.name == "vulkan" || b.name == "cuda")
      EXPECT_GT(b.capabilities.device_memory, std::uint64_t(1) << 26) << b.name;  // at least 64 MiB
    else
      EXPECT_EQ(b.capabilities.device_memory, 0u) << b.name;
  }
}

}  // namespace
