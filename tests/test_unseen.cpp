// Masked skies (docs/physics.md, "Masked skies"): UNSEEN pixels are an error by default, naming the file,
// column, count and first pixel; taken as 0 on request; or taken as 0 with the samples whose disc holds
// one flagged, exactly: the flags equal HEALPix C++ query_disc against the mask, and the unflagged
// samples do not depend on what the masked pixels hold.
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <filesystem>
#include <numbers>
#include <random>
#include <thread>
#include <vector>

#include <healpix_base.h>
#include <pointing.h>
#include <rangeset.h>

#include "backend_fixtures.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/pisco.hpp"
#include "pisco/scan.hpp"
#include "pisco/tod_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::deg;
using pisco_test::contains;
using pisco_test::error_of;

constexpr int nside = 32;

fs::path scratch(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("pisco-unseen-" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d / name;
}

// A point-source-like mask: the pixels within 3 deg of (60 deg, 40 deg), and two single pixels.
std::vector<std::size_t> mask_pixels() {
  const Healpix_Base base(nside, RING, SET_NSIDE);
  std::vector<int> disc;
  base.query_disc(pointing(60 * deg, 40 * deg), 3 * deg, disc);
  std::vector<std::size_t> out(disc.begin(), disc.end());
  out.push_back(base.ang2pix(pointing(100 * deg, 200 * deg)));
  out.push_back(base.ang2pix(pointing(2 * deg, 10 * deg)));
  std::sort(out.begin(), out.end());
  return out;
}

pisco::Sky masked_sky(const std::vector<std::size_t>& mask, double masked_value) {
  pisco::Sky sky = pisco_test::cmb_like_sky(nside, 5);
  for (std::size_t p : mask) {
    sky.I()[p] = masked_value;
    sky.Q()[p] = p % 2 ? masked_value : 0.0;  // some pixels UNSEEN in one map only
  }
  return sky;
}

// Pointings near the mask and everywhere else: pixel centres around the source and random ones.
pisco::Pointing pointings() {
  pisco::Pointing p;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 600; ++i) p.push_back(std::acos(1 - 2 * u(rng)), 2 * std::numbers::pi * u(rng), 2 * std::numbers::pi * u(rng));
  for (int i = 0; i < 600; ++i) p.push_back((45 + 30 * u(rng)) * deg, (25 + 30 * u(rng)) * deg, u(rng));
  for (int i = 0; i < 60; ++i) p.push_back(u(rng) * 15 * deg, 2 * std::numbers::pi * u(rng), u(rng));
  return p;
}

std::vector<pisco::Beamsor> beams() {
  pisco::BeamOptions o;
  o.rho_max = 6 * deg;
  return {pisco::Beamsor::gaussian(2.5 * deg, o)};
}

TEST(Unseen, SkyFindsZeroesAndReportsUnseenPixels) {
  const auto mask = mask_pixels();
  pisco::Sky sky = masked_sky(mask, pisco::unseen);
  EXPECT_EQ(sky.unseen_pixels(), mask);
  const std::string e = error_of([&] { sky.check_unseen("masked.fits"); });
  EXPECT_TRUE(contains(e, "masked.fits: the Stokes I map has " + std::to_string(mask.size()) + " UNSEEN pixels")) << e;
  EXPECT_TRUE(contains(e, "the first at pixel " + std::to_string(mask.front()))) << e;
  EXPECT_EQ(sky.zero_unseen(), mask.size());
  EXPECT_TRUE(sky.unseen_pixels().empty());
  EXPECT_EQ(sky.I()[mask[0]], 0.0);
  EXPECT_EQ(error_of([&] { sky.check_unseen("x"); }), "no error");
}

TEST(Unseen, ReadFitsRejectsZeroesOrKeeps) {
  const auto mask = mask_pixels();
  const fs::path file = scratch("masked.fits");
  masked_sky(mask, pisco::unseen).write_fits(file);
  // Default: one error naming the file, the column, the count and the first pixel.
  const std::string e = error_of([&] { pisco::Sky::read_fits(file); });
  std::cout << e << "\n";
  EXPECT_TRUE(contains(e, file.string() + ": column 1 (I_STOKES) has " + std::to_string(mask.size()) +
                              " UNSEEN pixels")) << e;
  EXPECT_TRUE(contains(e, "the first at pixel " + std::to_string(mask.front()) + " (RING)")) << e;
  const pisco::Sky zero = pisco::Sky::read_fits(file, pisco::UnseenPolicy::zero);
  EXPECT_TRUE(zero.unseen_pixels().empty());
  EXPECT_EQ(zero.I()[mask.back()], 0.0);
  const pisco::Sky kept = pisco::Sky::read_fits(file, pisco::UnseenPolicy::flag);
  EXPECT_EQ(kept.unseen_pixels(), mask);
  fs::remove_all(file.parent_path());
}

TEST(Unseen, EngineRejectsAMaskedSkyByDefault) {
  const pisco::Sky sky = masked_sky(mask_pixels(), pisco::unseen);
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  const std::string e = error_of([&] { pisco::Engine(sky, beams(), fp); });
  EXPECT_TRUE(contains(e, "sky: the Stokes I map has")) << e;
  EXPECT_TRUE(contains(e, "UNSEEN")) << e;
}

// Flags against HEALPix C++: a sample is flagged exactly when query_disc (inclusive = false) around its
// line of sight meets the mask; for angles, quaternions, and a detector with an offset.
TEST(Unseen, FlagsAreQueryDiscAgainstTheMask) {
  const auto mask = mask_pixels();
  const pisco::Sky sky = masked_sky(mask, pisco::unseen);
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  pisco::Detector off{"off", 0.3, 0.0, 1.0, 0};
  off.set_offset(2 * deg, -1.5 * deg, 10 * deg);
  fp.add(off);
  const auto bs = beams();
  pisco::Engine engine(sky, bs, fp, {.backend = "cpu", .unseen = pisco::UnseenPolicy::flag});
  EXPECT_EQ(engine.unseen_pixels(), mask.size());
  const pisco::Pointing b = pointings();
  std::vector<pisco::Quat> q;
  for (std::size_t i = 0; i < b.size(); ++i) q.push_back(pisco::quat_from_pointing(b.theta[i], b.phi[i], b.psi[i]));
  const Healpix_Base base(nside, RING, SET_NSIDE);
  std::size_t flagged_total = 0;
  for (std::size_t d = 0; d < fp.size(); ++d) {
    pisco::Pointing los;  // the detector's own line of sight
    pisco::detector_pointing(b.view(), fp[d].offset, los);
    std::vector<std::uint8_t> fa(b.size()), fq(b.size());
    const std::size_t na = engine.flag_samples(d, b.view(), fa);
    engine.flag_samples(d, pisco::QuatPointingView{q}, fq);
    std::size_t nref = 0, disagree_q = 0;
    for (std::size_t i = 0; i < b.size(); ++i) {
      std::vector<int> disc;
      base.query_disc(pointing(los.theta[i], los.phi[i]), bs[0].rho_max(), disc);
      bool hit = false;
      for (int p : disc) hit = hit || std::binary_search(mask.begin(), mask.end(), std::size_t(p));
      nref += hit;
      EXPECT_EQ(fa[i], hit ? 1 : 0) << "detector " << fp[d].name << ", sample " << i;
      disagree_q += fq[i] != fa[i];
    }
    EXPECT_EQ(na, nref);
    // Quaternion and angle pointing agree to rounding: a disc edge may fall either way.
    EXPECT_LE(disagree_q, 2u) << fp[d].name;
    std::cout << "detector " << fp[d].name << ": " << na << " of " << b.size() << " samples flagged\n";
    flagged_total += na;
  }
  EXPECT_GT(flagged_total, 300u);
  // Without UNSEEN pixels, or another policy, nothing is flagged.
  pisco::Engine plain(pisco_test::cmb_like_sky(nside, 5), bs, fp, {.unseen = pisco::UnseenPolicy::flag, .quadrature = pisco::Quadrature::plain});
  std::vector<std::uint8_t> f(b.size(), 7);
  EXPECT_EQ(plain.flag_samples(0, b.view(), f), 0u);
  EXPECT_EQ(std::count(f.begin(), f.end(), 0), std::ptrdiff_t(f.size()));
  EXPECT_TRUE(contains(error_of([&] { std::vector<std::uint8_t> g(3); plain.flag_samples(0, b.view(), g); }),
                       "3 flags for"));
}

// The flags are exact for the convolution itself: unflagged samples are the same whatever the masked
// pixels hold (0, as taken, or a huge value), and flagged ones are not.
void check_unflagged_independent_of_mask(const std::string& backend, double tolerance) {
  const auto mask = mask_pixels();
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  const auto bs = beams();
  pisco::EngineOptions o{.backend = backend, .unseen = pisco::UnseenPolicy::flag, .quadrature = pisco::Quadrature::plain};
  pisco::Engine masked(masked_sky(mask, pisco::unseen), bs, fp, o);
  pisco::Engine bright(masked_sky(mask, 1e3), bs, fp, {.backend = backend, .quadrature = pisco::Quadrature::plain});
  const pisco::Pointing b = pointings();
  std::vector<double> t0(b.size()), t1(b.size());
  std::vector<std::uint8_t> flags(b.size());
  masked.convolve(0, b.view(), t0);
  bright.convolve(0, b.view(), t1);
  masked.flag_samples(0, b.view(), flags);
  double worst_unflagged = 0, least_flagged = 1e300;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double d = std::abs(t1[i] - t0[i]);
    if (flags[i]) least_flagged = std::min(least_flagged, d);
    else worst_unflagged = std::max(worst_unflagged, d);
  }
  std::cout << backend << ": unflagged samples change by at most " << worst_unflagged
            << " when the masked pixels go from 0 to 1e3; flagged ones by at least " << least_flagged << "\n";
  EXPECT_LE(worst_unflagged, tolerance);
  EXPECT_GT(least_flagged, 0.0);
}

TEST(Unseen, UnflaggedSamplesDoNotSeeTheMaskCpu) { check_unflagged_independent_of_mask("cpu", 0.0); }

TEST(Unseen, UnflaggedSamplesDoNotSeeTheMaskVulkan) {
  if (const std::string why = pisco_test::backend_unavailable("vulkan"); !why.empty())
    GTEST_SKIP() << "vulkan backend unavailable: " << why;
  // float32 sums (docs/vulkan.md): a masked pixel in a disc would change the sample by ~1e3 x its weight.
  check_unflagged_independent_of_mask("vulkan", 1e-9);
}

TEST(Unseen, ZeroPolicyEqualsTheZeroedSky) {
  const auto mask = mask_pixels();
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  const auto bs = beams();
  pisco::Sky zeroed = masked_sky(mask, pisco::unseen);
  zeroed.zero_unseen();
  pisco::Engine a(masked_sky(mask, pisco::unseen), bs, fp, {.unseen = pisco::UnseenPolicy::zero, .quadrature = pisco::Quadrature::plain});
  pisco::Engine b(zeroed, bs, fp, {.quadrature = pisco::Quadrature::plain});
  EXPECT_EQ(a.unseen_pixels(), mask.size());
  const pisco::Pointing p = pointings();
  std::vector<double> ta(p.size()), tb(p.size());
  a.convolve(1, p.view(), ta);
  b.convolve(1, p.view(), tb);
  EXPECT_EQ(ta, tb);
  std::vector<std::uint8_t> f(p.size());
  EXPECT_EQ(a.flag_samples(1, p.view(), f), 0u) << "only UnseenPolicy::flag flags";
}

TEST(Unseen, MapmakerLeavesFlaggedSamplesOut) {
  pisco::Detector d{"d", 0.0, 0.0, 1.0, 0};
  const pisco::Pointing centres = pisco::pixel_centre_scan(4, {0.0, 60 * deg, 120 * deg});
  std::vector<double> tod(centres.size(), 1.0);
  std::vector<std::uint8_t> flags(centres.size(), 0);
  for (std::size_t i = 0; i < flags.size(); i += 2) {
    flags[i] = 1;
    tod[i] = 1e30;  // would spoil the maps if binned
  }
  pisco::BinnedMapmaker m(4);
  m.add(d, centres.view(), tod, {}, flags);
  const pisco::BinnedMaps maps = m.solve();
  std::uint64_t hits = 0;
  for (auto h : maps.hits) hits += h;
  EXPECT_EQ(hits, centres.size() / 2);
  for (double v : maps.I)
    if (v != pisco::unseen) EXPECT_NEAR(v, 2.0, 1e-9);
  EXPECT_TRUE(contains(error_of([&] { std::vector<std::uint8_t> g(2); m.add(d, centres.view(), tod, {}, g); }),
                       "2 flags for"));
}

TEST(Unseen, TodFilesKeepFlags) {
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  const fs::path file = scratch("flags.h5");
  {
    pisco::TodWriter w(file, fp, 10, pisco::TodPrecision::float64, false, {}, true);
    const std::vector<double> s(10, 1.0);
    const std::vector<std::uint8_t> f{0, 1, 0, 0, 1, 1, 0, 0, 0, 1};
    w.write(0, 0, s, nullptr, f);
    w.write(1, 0, s);  // no flags: all 0
    EXPECT_TRUE(contains(error_of([&] { w.write(1, 0, s, nullptr, std::span(f).first(3)); }), "3 flags for 10"));
    w.commit();
  }
  EXPECT_EQ(pisco::read_tod_flags(file, "pa"), (std::vector<std::uint8_t>{0, 1, 0, 0, 1, 1, 0, 0, 0, 1}));
  EXPECT_EQ(pisco::read_tod_flags(file, "pb"), std::vector<std::uint8_t>(10, 0));
  {
    pisco::TodWriter w(file, fp, 2, pisco::TodPrecision::float64, false, {});
    const std::vector<double> s(2, 1.0);
    const std::vector<std::uint8_t> f(2, 1);
    EXPECT_TRUE(contains(error_of([&] { w.write(0, 0, s, nullptr, f); }), "written without flags"));
    w.write(0, 0, s);
    w.write(1, 0, s);
    w.commit();
  }
  EXPECT_TRUE(pisco::read_tod_flags(file, "pa").empty());
  fs::remove_all(file.parent_path());
}

TEST(EngineLimits, ThreadsAndEfficiencies) {
  const pisco::Sky sky(8);
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  const auto bs = beams();
  EXPECT_EQ(pisco::Engine::max_threads(), 64 * std::max(1u, std::thread::hardware_concurrency()));
  EXPECT_TRUE(contains(error_of([&] { pisco::Engine(sky, bs, fp, {.settings = {{"threads", (long long)pisco::Engine::max_threads() + 1}}}); }),
                       "threads: expected 0 (all hardware threads) or a number of threads up to "));
  EXPECT_TRUE(contains(error_of([&] {
                         pisco::Engine(sky, bs, fp, {.backend = "simd", .settings = {{"threads", (long long)pisco::Engine::max_threads() + 1}}});
                       }),
                       "threads: expected 0 (all hardware threads) or a number of threads up to "));
  for (double eps : {-0.01, 1.5}) {
    pisco::FocalPlane bad;
    bad.add({"leaky", 0.0, eps, 1.0, 0});
    const std::string e = error_of([&] { pisco::Engine(sky, bs, bad); });
    EXPECT_TRUE(contains(e, "detector 'leaky': epsilon")) << e;
    EXPECT_TRUE(contains(e, "outside [0, 1]")) << e;
  }
}

}  // namespace
