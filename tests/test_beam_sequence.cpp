// Beams that change with time (Detector::beam_sequence; docs/beams.md, "Beams that change with
// time"): the detector's TOD between two nodes is the two beams' responses linearly interpolated.
// Checked against the interpolated beam built directly, per sample time, as a field of its own (the
// two nodes' fields, each divided by its own Omega~, weighted by 1 - w and w) and convolved as a fixed
// beam: the same sky, the same samples, across both poles, with a monopole and a dipole. Then the
// adjoint's dot-product identity, accumulation, and the errors.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "backend_fixtures.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace {

using pisco::Beamsor;
using pisco::deg;
constexpr double pi = std::numbers::pi;

// An elliptical Gaussian of FWHMs fx x fy with its major axis at `angle`, polarized along x with a
// cross-polar term u (its Stokes response), as a field.
pisco::Mueller node_field(double rho, double sigma, double fx, double fy, double angle, double u) {
  const double k = std::sqrt(8 * std::log(2.0));
  const double sx = fx / k, sy = fy / k;
  const double x = std::sin(rho) * std::cos(sigma - angle), y = std::sin(rho) * std::sin(sigma - angle);
  const double b = std::exp(-(x * x / (2 * sx * sx) + y * y / (2 * sy * sy)));
  return Beamsor::stokes_mueller(b, 0.97 * b, u * b, 0.0);
}

struct Node {
  double fx, fy, angle, u;
  pisco::Mueller at(double rho, double sigma) const { return node_field(rho, sigma, fx, fy, angle, u); }
};

// A focus drift and a turn: three nodes at 0, 100 and 300 s.
const Node nodes[3] = {{2.0 * deg, 1.5 * deg, 0.3, 0.05}, {2.4 * deg, 1.6 * deg, 0.9, -0.03}, {2.2 * deg, 2.2 * deg, 0.0, 0.0}};
const double node_times[3] = {0.0, 100.0, 300.0};
constexpr double rho_max = 6 * deg, step = 0.1 * deg;

Beamsor node_beam(int k) {
  const Node n = nodes[k];
  return Beamsor::from_field([n](double r, double s) { return n.at(r, s); }, rho_max, step, "node " + std::to_string(k));
}

pisco::FocalPlane sequence_plane() {
  pisco::FocalPlane fp;
  pisco::Detector d;
  d.name = "drifting";
  d.zeta = 0.4;
  d.set_offset(2 * deg, -1 * deg, 0.2);
  for (int k = 0; k < 3; ++k) d.beam_sequence.push_back({node_times[k], std::size_t(k)});
  fp.add(d);
  pisco::Detector fixed;
  fixed.name = "fixed";
  fixed.beam = 1;
  fp.add(fixed);
  // With a half-wave plate between the optics and the detector: four row detectors per node.
  pisco::Detector plated = d;
  plated.name = "plated";
  plated.hwp = pisco::HalfWavePlate::ideal(0.3, pisco::HwpPlacement::detector);
  fp.add(plated);
  return fp;
}

class BeamSequence : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    const std::string why = pisco_test::backend_unavailable(GetParam());
    if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
    options.backend = GetParam();
    pisco_test::set_taken(options, "threads", 2LL);
  }
  double bar() const { return GetParam() == "cpu" ? 1e-11 : 1e-7; }
  pisco::EngineOptions options;
};

// Per time: the interpolated beam as a field, each node divided by its own Omega~, and its TOD as a
// fixed beam; the sequence's TOD at those times.
TEST_P(BeamSequence, EqualsTheInterpolatedBeamBuiltDirectly) {
  const int nside = 64;
  const pisco::Sky sky = pisco_test::cmb_like_sky(nside, 3, 10.0);
  std::vector<Beamsor> beams;
  for (int k = 0; k < 3; ++k) beams.push_back(node_beam(k));
  pisco::Engine engine(sky, beams, sequence_plane(), options);
  // Times at the nodes (w = 0 and 1) and between them; each time's samples across the sphere and
  // both poles.
  const double times[] = {0.0, 37.5, 100.0, 180.0, 299.0, 300.0};
  const pisco::Pointing p = pisco_test::random_pointing(120, 7);
  for (const double t : times) {
    const std::size_t k = t < 100.0 ? 0 : 1;
    const double w = (t - node_times[k]) / (node_times[k + 1] - node_times[k]);
    const Node a = nodes[k], b = nodes[k + 1];
    const double oa = beams[k].omega_tilde(), ob = beams[k + 1].omega_tilde();
    const Beamsor direct = Beamsor::from_field(
        [&](double r, double s) {
          pisco::Mueller m{}, ma = a.at(r, s), mb = b.at(r, s);
          for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) m[i][j] = (1 - w) * ma[i][j] / oa + w * mb[i][j] / ob;
          return m;
        },
        rho_max, step, "interpolated");
    pisco::FocalPlane fp;
    pisco::Detector d = sequence_plane()[0];
    d.beam_sequence.clear();
    fp.add(d);
    std::vector<double> want(p.size()), got(p.size());
    pisco::Engine(sky, {direct}, fp, options).convolve(0, p, want);
    const std::vector<double> time(p.size(), t);
    engine.convolve(0, p, got, false, {}, time);
    double worst = 0, norm = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      worst = std::max(worst, std::abs(got[i] - want[i]));
      norm += want[i] * want[i];
    }
    norm = std::sqrt(norm / double(p.size()));
    std::printf("%s, t = %5.1f s (nodes %zu, %zu, w = %.3f): worst difference %.2e of the TOD's RMS\n",
                GetParam().c_str(), t, k, k + 1, w, worst / norm);
    EXPECT_LE(worst, bar() * norm) << "t = " << t;
  }
}

// <A s, d> = <s, A^T d> for the sequence detectors (one with a plate between the optics and the
// detector), their samples' times spread over all three nodes' in no order (the samples between two
// nodes gathered).
TEST_P(BeamSequence, ItsAdjointIsItsTranspose) {
  const int nside = 32;
  const pisco::Sky sky = pisco_test::cmb_like_sky(nside, 4, 5.0);
  std::vector<Beamsor> beams;
  for (int k = 0; k < 3; ++k) beams.push_back(node_beam(k));
  const pisco::Pointing p = pisco_test::random_pointing(400, 3);
  std::vector<double> time(p.size()), plate(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    time[i] = 300.0 * double((i * 37) % p.size()) / double(p.size() - 1);
    plate[i] = 0.05 * double(i);
  }
  pisco::Engine engine(sky, beams, sequence_plane(), options);
  std::mt19937 g(2);
  std::normal_distribution<double> n(0, 1);
  double forward = 0, t2 = 0, d2 = 0;
  pisco::Sky at(nside);
  for (const std::size_t det : {std::size_t(0), std::size_t(2)}) {
    const std::span<const double> h = det == 2 ? std::span<const double>(plate) : std::span<const double>();
    std::vector<double> tod(p.size()), d(p.size());
    engine.convolve(det, p, tod, false, h, time);
    for (std::size_t i = 0; i < p.size(); ++i) {
      d[i] = n(g);
      forward += tod[i] * d[i];
      t2 += tod[i] * tod[i];
      d2 += d[i] * d[i];
    }
    engine.adjoint(det, p, d, h, time);
  }
  engine.take_adjoint({at.I(), at.Q(), at.U(), at.V()});
  double back = 0;
  for (int c = 0; c < 4; ++c)
    for (std::size_t q = 0; q < sky.npix(); ++q)
      back += sky.stokes(pisco::StokesIndex(c))[q] * at.stokes(pisco::StokesIndex(c))[q];
  const double scale = std::sqrt(t2 * d2);
  std::printf("%s: <A s, d> = %.15e, <s, A^T d> = %.15e, difference / (|A s| |d|) = %.2e\n", GetParam().c_str(),
              forward, back, std::abs(forward - back) / scale);
  EXPECT_LT(std::abs(forward - back) / scale, GetParam() == "cpu" ? 1e-12 : 1e-5);
  EXPECT_GT(std::abs(forward), 1e-3 * scale);
  // Each sample counted once, its two nodes' pixels both.
  EXPECT_GT(engine.mean_disc_pixels(), 0.0);
}

// Accumulating adds the interpolated TOD onto what the buffer holds; submissions queue and complete
// in order; the fixed detector beside it ignores the times.
TEST_P(BeamSequence, AccumulatesAndQueues) {
  const pisco::Sky sky = pisco_test::cmb_like_sky(32, 5, 1.0);
  std::vector<Beamsor> beams;
  for (int k = 0; k < 3; ++k) beams.push_back(node_beam(k));
  const pisco::Pointing p = pisco_test::random_pointing(200, 8);
  std::vector<double> time(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) time[i] = 50.0 + 200.0 * double(i % 7) / 6.0;  // runs of one
  pisco::Engine engine(sky, beams, sequence_plane(), options);
  std::vector<double> once(p.size()), added(p.size(), 2.5), fixed(p.size()), fixed_timed(p.size());
  engine.convolve(0, p, once, false, {}, time);
  const std::uint64_t a = engine.submit(0, p, added, true, {}, time);
  const std::uint64_t b = engine.submit(1, p, fixed_timed, false, {}, time);
  engine.wait(b);
  EXPECT_LT(a, b);
  engine.convolve(1, p, fixed);
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_NEAR(added[i] - 2.5, once[i], 1e-12 * std::max(1.0, std::abs(once[i]))) << i;
    EXPECT_EQ(fixed[i], fixed_timed[i]) << i;
  }
  // The plated detector, its samples between two nodes gathered with their plate angles: the nodes'
  // beams as fixed detectors with the same plate, combined by hand.
  std::vector<double> plate(p.size()), plated(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) plate[i] = 0.07 * double(i);
  engine.convolve(2, p, plated, false, plate, time);
  pisco::FocalPlane nodes_fp;
  for (int k = 0; k < 3; ++k) {
    pisco::Detector d = sequence_plane()[2];
    d.name = "node" + std::to_string(k);
    d.beam_sequence.clear();
    d.beam = std::size_t(k);
    nodes_fp.add(d);
  }
  pisco::Engine fixed_engine(sky, beams, nodes_fp, options);
  std::array<std::vector<double>, 3> node_tod;
  for (int k = 0; k < 3; ++k) {
    node_tod[k].resize(p.size());
    fixed_engine.convolve(std::size_t(k), p, node_tod[k], false, plate);
  }
  double worst = 0, norm = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const std::size_t k = time[i] < 100.0 ? 0 : 1;
    const double w = (time[i] - node_times[k]) / (node_times[k + 1] - node_times[k]);
    const double want = (1 - w) * node_tod[k][i] + w * node_tod[k + 1][i];
    worst = std::max(worst, std::abs(plated[i] - want));
    norm = std::max(norm, std::abs(want));
  }
  EXPECT_LE(worst, 1e-12 * norm);
  EXPECT_GT(norm, 0.0);
}

INSTANTIATE_TEST_SUITE_P(Backends, BeamSequence, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

TEST(BeamSequenceErrors, NameTheDetectorTheNodeAndTheSample) {
  const pisco::Sky sky = pisco_test::cmb_like_sky(16, 1, 0.0);
  std::vector<Beamsor> beams{Beamsor::gaussian(5 * deg), Beamsor::gaussian(6 * deg)};
  const auto message = [&](pisco::FocalPlane fp) {
    try {
      pisco::Engine(sky, beams, fp, {});
    } catch (const pisco::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  pisco::Detector d;
  d.name = "drift";
  d.beam_sequence = {{0.0, 0}};
  EXPECT_NE(message(pisco::FocalPlane({d})).find("detector 'drift': its beam_sequence has one node"), std::string::npos);
  d.beam_sequence = {{0.0, 0}, {0.0, 1}};
  EXPECT_NE(message(pisco::FocalPlane({d})).find("beam_sequence node 1: time = 0 s is not after node 0's 0 s"),
            std::string::npos)
      << message(pisco::FocalPlane({d}));
  d.beam_sequence = {{0.0, 0}, {10.0, 2}};
  EXPECT_NE(message(pisco::FocalPlane({d})).find("beam_sequence node 1: beam index 2 but only 2 beamsors"),
            std::string::npos);
  d.beam_sequence = {{0.0, 0}, {std::nan(""), 1}};
  EXPECT_NE(message(pisco::FocalPlane({d})).find("node 1: time = nan is not finite"), std::string::npos)
      << message(pisco::FocalPlane({d}));

  d.beam_sequence = {{0.0, 0}, {10.0, 1}};
  pisco::Engine engine(sky, beams, pisco::FocalPlane({d}), {});
  const pisco::Pointing p = pisco_test::random_pointing(5, 1);
  std::vector<double> tod(5, 7.0);
  const auto error = [&](std::vector<double> time) {
    try {
      engine.convolve(0, p, tod, false, {}, time);
    } catch (const pisco::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error({}).find("detector 'drift' has a beam that changes with time (beam_sequence): expected 5 sample times"),
            std::string::npos)
      << error({});
  EXPECT_NE(error({0, 1, std::nan(""), 3, 4}).find("the time of sample 2 is nan"), std::string::npos);
  EXPECT_NE(error({0, 1, 2, 10.5, 4}).find("sample 3 is at time 10.5 s, outside its beam_sequence's nodes (0 to 10 s)"),
            std::string::npos)
      << error({0, 1, 2, 10.5, 4});
  for (const double v : tod) EXPECT_EQ(v, 7.0);  // nothing written
  // The engine goes on after the errors.
  EXPECT_EQ(error({0, 2.5, 5, 7.5, 10}), "no error");
  pisco::Sky at(16);
  EXPECT_THROW(engine.adjoint(0, p, tod, {}, std::vector<double>{0, 1, 2, 3, -1}), pisco::Error);
}

}  // namespace
