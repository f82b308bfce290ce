// One sky summed by one backend with its polar copy, as a part of its own (core/sky_pass.hpp): the
// engine's sky and a split beam's coarse sky are each one. Its forward pass and its adjoint are
// transposes of each other on their own (<A s, d> = <s, A^T d>), over samples that cross both poles
// in long runs and alone, on a detector at the boresight and one 6 deg off it; its accumulating
// forward adds onto what the buffer holds at every sample, the polar ones included; and it sums each
// sample once.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include "backend_fixtures.hpp"
#include "core/backend.hpp"
#include "core/poles.hpp"
#include "core/prepared.hpp"
#include "core/sky_pass.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/quaternion.hpp"

namespace {

using pisco::deg;
constexpr double pi = std::numbers::pi;

const pisco::detail::BackendEntry* entry_of(const std::string& name) {
  for (const auto& e : pisco::detail::backend_registry())
    if (e.name == name) return &e;
  return nullptr;
}

// A scan through the north pole (a long run of polar samples), then random samples over the sphere
// (most alone), then a scan through the south pole.
pisco::Pointing crossing_pointing() {
  pisco::Pointing p;
  for (int i = 0; i < 200; ++i) {
    const double t = -20 * deg + 40 * deg * i / 199.0;
    p.push_back(std::abs(t), t < 0 ? 0.3 + pi : 0.3, 0.1 * i);
  }
  const pisco::Pointing r = pisco_test::random_pointing(300, 9);
  for (std::size_t i = 0; i < r.size(); ++i) p.push_back(r.theta[i], r.phi[i], r.psi[i]);
  for (int i = 0; i < 150; ++i) {
    const double t = -15 * deg + 30 * deg * i / 149.0;
    p.push_back(pi - std::abs(t), t < 0 ? 2.0 + pi : 2.0, -0.2 * i);
  }
  return p;
}

struct PassSetup {
  pisco::Sky sky, summed;
  std::vector<pisco::Beamsor> beams;
  pisco::FocalPlane fp;
  pisco::EngineOptions options;
  std::shared_ptr<const pisco::detail::EngineInputs> inputs;

  PassSetup(const std::string& backend, int nside) : sky(pisco_test::cmb_like_sky(nside, 4, 2.0)), summed(sky) {
    for (std::size_t p = 0; p < sky.npix(); ++p) sky.V()[p] = 1e-7 * std::sin(double(p));
    summed = sky;
    pisco::detail::weigh_cap_boundaries(summed);
    pisco::BeamOptions o;
    o.rho_max = 12 * deg;
    o.cross_polar = 0.02;
    beams.push_back(pisco::Beamsor::elliptical_gaussian(6 * deg, 4 * deg, 0.3, o));
    pisco::Detector a;
    a.name = "a";
    a.zeta = 0.2;
    fp.add(a);
    pisco::Detector b;
    b.name = "b";
    b.zeta = -0.7;
    b.set_offset(6 * deg, -2 * deg, 0.4);
    fp.add(b);
    options.backend = backend;
    pisco_test::set_taken(options, "threads", 2LL);
    pisco::detail::EngineInputs in = pisco::detail::prepare_inputs(summed, beams, fp, options.normalization);
    in.quadrature = pisco::Quadrature::corrected;
    inputs = std::make_shared<const pisco::detail::EngineInputs>(std::move(in));
  }
  std::unique_ptr<pisco::detail::SkyPass> pass(const pisco::SkyView& s, const pisco::SkyView& w) const {
    return std::make_unique<pisco::detail::SkyPass>(*entry_of(options.backend), inputs, w, s, options, true, true);
  }
};

pisco::detail::PointingInput input_of(const pisco::Pointing& p) {
  pisco::detail::PointingInput in;
  in.angles = p;
  return in;
}

// crossing_pointing() through a pass on `backend`, with what it needs: used in place (the input views p).
struct Crossing {
  PassSetup s;
  pisco::Pointing p = crossing_pointing();
  pisco::detail::PointingInput input = input_of(p);
  std::unique_ptr<pisco::detail::SkyPass> pass = s.pass(s.sky, s.summed);
  explicit Crossing(const std::string& backend) : s(backend, 32) {}
  Crossing(const Crossing&) = delete;
  Crossing& operator=(const Crossing&) = delete;
};

class SkyPassTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    const std::string why = pisco_test::backend_unavailable(GetParam());
    if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
  }
  double bar() const { return GetParam() == "cpu" ? 1e-12 : 1e-5; }
};

TEST_P(SkyPassTest, ItsAdjointIsItsTranspose) {
  const PassSetup s(GetParam(), 32);
  const pisco::Pointing p = crossing_pointing();
  const pisco::detail::PointingInput input = input_of(p);
  std::mt19937 g(5);
  std::normal_distribution<double> n(0, 1);
  double forward = 0, tod_norm2 = 0, d_norm2 = 0;
  const auto pass = s.pass(s.sky, s.summed);
  pass->prepare();
  ASSERT_TRUE(pass->polar_copy());
  const auto adjoint = s.pass(s.sky, s.summed);
  for (std::size_t det = 0; det < s.fp.size(); ++det) {
    pisco::detail::SkyPass::Work w;
    pass->begin(det, input, w, true);
    ASSERT_TRUE(w.polar);
    // Some polar samples in runs of their own (the scans), some inside the sky's runs (alone).
    EXPECT_GE(w.runs.size(), 2u);
    std::vector<double> tod(p.size());
    pass->submit(w, det, input, tod, false);
    pass->wait(pass->last_ticket());
    pisco::detail::SkyPass::finish(w);
    std::vector<double> d(p.size());
    for (std::size_t i = 0; i < d.size(); ++i) {
      d[i] = n(g);
      forward += tod[i] * d[i];
      tod_norm2 += tod[i] * tod[i];
      d_norm2 += d[i] * d[i];
    }
    pisco::detail::SkyPass::Work wa;
    adjoint->begin(det, input, wa, false);
    adjoint->adjoint(wa, det, input, d, false);
    EXPECT_TRUE(adjoint->holds_adjoint());
  }
  std::uint64_t pixels = 0;
  const std::optional<pisco::Sky> at = adjoint->take_adjoint(pixels);
  ASSERT_TRUE(at);
  EXPECT_FALSE(adjoint->holds_adjoint());
  EXPECT_GT(pixels, 0u);  // the polar samples, scattered at take_adjoint
  double back = 0;
  for (int c = 0; c < 4; ++c)
    for (std::size_t q = 0; q < s.sky.npix(); ++q)
      back += s.sky.stokes(pisco::StokesIndex(c))[q] * at->stokes(pisco::StokesIndex(c))[q];
  const double scale = std::sqrt(tod_norm2 * d_norm2);
  std::printf("%s: <A s, d> = %.15e, <s, A^T d> = %.15e, difference / (|A s| |d|) = %.2e\n", GetParam().c_str(), forward,
              back, std::abs(forward - back) / scale);
  EXPECT_LT(std::abs(forward - back) / scale, bar());
  EXPECT_GT(std::abs(forward), 1e-3 * scale);  // not two zeros
}

TEST_P(SkyPassTest, AccumulatingAddsAtEverySample) {
  const Crossing c(GetParam());
  std::vector<double> once(c.p.size()), added(c.p.size());
  for (std::size_t i = 0; i < added.size(); ++i) added[i] = 1000.0 + double(i);
  for (const bool accumulate : {false, true}) {
    pisco::detail::SkyPass::Work w;
    c.pass->begin(1, c.input, w, true);
    ASSERT_TRUE(w.polar);
    c.pass->prepare();
    c.pass->submit(w, 1, c.input, accumulate ? added : once, accumulate);
    c.pass->wait(c.pass->last_ticket());
    pisco::detail::SkyPass::finish(w);
  }
  for (std::size_t i = 0; i < c.p.size(); ++i)
    EXPECT_NEAR(added[i] - (1000.0 + double(i)), once[i], 1e-9 * (1000.0 + double(i))) << "sample " << i;
}

// Each sample is summed once, on the sky or on its polar copy: crossing_pointing's random samples
// near the poles lie alone among the sky's (runs shorter than the adjoint keeps apart), and the
// pass evaluates the pixels of the sky's samples on the sky and of the polar samples on the copy, no
// more, with each sample's value what those two sets give submitted alone, bit for bit, written or
// added.
TEST_P(SkyPassTest, EachSampleIsSummedOnce) {
  const Crossing c(GetParam());
  const pisco::Pointing& p = c.p;
  for (const bool accumulate : {false, true}) {
    pisco::detail::SkyPass::Work w;
    c.pass->begin(1, c.input, w, true);
    ASSERT_TRUE(w.polar);
    ASSERT_NE(pisco::detail::sky_runs(w.polar->index, p.size(), 1), w.runs) << "no short run of polar samples";
    c.pass->prepare();
    std::vector<double> tod(p.size(), accumulate ? 0.25 : 0.0);
    c.pass->submit(w, 1, c.input, tod, accumulate);
    const std::uint64_t pixels = c.pass->wait(c.pass->last_ticket());
    pisco::detail::SkyPass::finish(w);
    // The two sets alone, straight through the pass's backend.
    std::vector<bool> near(p.size(), false);
    for (const std::size_t i : w.polar->index) near[i] = true;
    pisco::Pointing away;
    for (std::size_t i = 0; i < p.size(); ++i)
      if (!near[i]) away.push_back(p.theta[i], p.phi[i], p.psi[i]);
    std::vector<double> sky_values(away.size()), polar_values(w.polar->index.size());
    pisco::detail::Backend& b = c.pass->backend();
    const std::uint64_t t = c.pass->last_ticket();
    b.submit(1, input_of(away), sky_values, false, t + 1);
    const std::uint64_t sky_pixels = b.wait(t + 1);
    b.submit(1, w.polar->input(), polar_values, false, t + 2);
    const std::uint64_t polar_pixels = b.wait(t + 2);
    EXPECT_EQ(pixels, sky_pixels + polar_pixels) << (accumulate ? "accumulating" : "writing");
    for (std::size_t i = 0, a = 0, k = 0; i < p.size(); ++i) {
      const double v = near[i] ? polar_values[k++] : sky_values[a++];
      EXPECT_EQ(tod[i], accumulate ? 0.25 + v : v) << "sample " << i << (near[i] ? " (polar)" : "");
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, SkyPassTest, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

}  // namespace
