// Binned I/Q/U map-maker (docs/physics.md, "Map-making and spectra"): exact round trips, the condition-number cut, streaming.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <numbers>
#include <random>
#include <string>

#include "support.hpp"
#include "core/detector_pointing.hpp"
#include "core/thread_pool.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/hwp.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/scan.hpp"
#include "pisco/units.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;

struct Maps {
  std::vector<double> I, Q, U;
};

Maps random_maps(int nside, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  const std::size_t npix = 12 * std::size_t(nside) * nside;
  Maps m{std::vector<double>(npix), std::vector<double>(npix), std::vector<double>(npix)};
  for (std::size_t p = 0; p < npix; ++p) {
    m.I[p] = 50.0 + 10.0 * n(rng);  // a monopole as well as fluctuations
    m.Q[p] = n(rng);
    m.U[p] = n(rng);
  }
  return m;
}

// The detector model the map-maker inverts, evaluated at pixel centres (the scans used here put
// every sample on the centre of the pixel whose values it reads).
std::vector<double> make_tod(const pisco::Detector& d, const pisco::Pointing& p, const Maps& m,
                             int nside) {
  const std::size_t npix = 12 * std::size_t(nside) * nside;
  std::vector<double> tod(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) {
    const std::size_t pix = k % npix;
    const double g = p.psi[k] + d.zeta;
    tod[k] = 0.5 * d.gain *
             ((1 + d.epsilon) * m.I[pix] +
              (1 - d.epsilon) * (m.Q[pix] * std::cos(2 * g) + m.U[pix] * std::sin(2 * g)));
  }
  return tod;
}

double max_error(const std::vector<double>& a, const std::vector<double>& b) {
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  return worst;
}

using pisco_test::expect_error;

TEST(Mapmaker, ThreeAnglesRoundTripExactly) {
  const int nside = 16;
  const Maps truth = random_maps(nside, 1);
  const pisco::Detector det{"d0", 10 * deg, 0.05, 1.3, 0};
  const pisco::Pointing p = pisco::pixel_centre_scan(nside, {0.0, 45 * deg, 90 * deg});
  const std::vector<double> tod = make_tod(det, p, truth, nside);

  pisco::BinnedMapmaker mm(nside);
  mm.add(det, p, tod);
  const pisco::BinnedMaps out = mm.solve();
  const double eI = max_error(out.I, truth.I), eQ = max_error(out.Q, truth.Q),
               eU = max_error(out.U, truth.U);
  std::cout << "round trip NSIDE 16, eps 0.05, gain 1.3, zeta 10 deg: max |dI| " << eI
            << ", |dQ| " << eQ << ", |dU| " << eU << "\n";
  EXPECT_LT(eI, 1e-12);
  EXPECT_LT(eQ, 1e-12);
  EXPECT_LT(eU, 1e-12);
  for (std::size_t pix = 0; pix < out.hits.size(); ++pix) ASSERT_EQ(out.hits[pix], 3u) << pix;
  EXPECT_EQ(out.nside, nside);
}

TEST(Mapmaker, NormalEquationsOfPartsAddUpToTheWhole) {
  std::cout << "checking: two map-makers, each given half of the TOD, added with add_normal_equations, solve "
               "to the maps of one given all of it (the MPI run's reduction), and mismatched sizes are refused\n";
  const int nside = 8;
  const Maps truth = random_maps(nside, 4);
  const pisco::Detector det{"d0", 10 * deg, 0.05, 1.3, 0};
  const pisco::Pointing p = pisco::pixel_centre_scan(nside, {0.0, 45 * deg, 90 * deg, 135 * deg});
  const std::vector<double> tod = make_tod(det, p, truth, nside);
  const std::size_t half = p.size() / 2;
  pisco::BinnedMapmaker whole(nside), first(nside), second(nside);
  whole.add(det, p, tod);
  first.add(det, p.view().subspan(0, half), std::span(tod).subspan(0, half));
  second.add(det, p.view().subspan(half, p.size() - half), std::span(tod).subspan(half));
  first.add_normal_equations(second);
  EXPECT_EQ(first.normal_matrices().size(), 6 * whole.hits().size());
  EXPECT_EQ(first.normal_vectors().size(), 3 * whole.hits().size());
  const pisco::BinnedMaps a = whole.solve(), b = first.solve();
  EXPECT_EQ(a.hits, b.hits);
  EXPECT_LT(max_error(a.I, b.I), 1e-12);
  EXPECT_LT(max_error(a.Q, b.Q), 1e-12);
  EXPECT_LT(max_error(a.U, b.U), 1e-12);
  pisco::BinnedMapmaker other(2 * nside);
  expect_error([&] { first.add_normal_equations(other); }, "add_normal_equations");
}

TEST(Mapmaker, ConditionNumberOfAnIdealPixel) {
  // Angles 0, 45, 90 deg: 4 A^T A = [[3,0,1],[0,2,0],[1,0,1]], eigenvalues 2 and 2 +- sqrt 2.
  pisco::BinnedMapmaker mm(1);
  const pisco::Detector det{"d", 0.0, 0.0, 1.0, 0};
  const pisco::Pointing p = pisco::pixel_centre_scan(1, {0.0, 45 * deg, 90 * deg});
  mm.add(det, p, std::vector<double>(p.size(), 1.0));
  const pisco::BinnedMaps out = mm.solve();
  const double expected = (2 - std::sqrt(2.0)) / (2 + std::sqrt(2.0));
  std::cout << "rcond at 0/45/90 deg: " << out.rcond[0] << " (expected " << expected << ")\n";
  for (double rc : out.rcond) EXPECT_NEAR(rc, expected, 1e-14);
  // A constant TOD of 1 is I = 2, Q = U = 0 for this detector.
  EXPECT_NEAR(out.I[5], 2.0, 1e-14);
  EXPECT_NEAR(out.Q[5], 0.0, 1e-14);
  EXPECT_NEAR(out.U[5], 0.0, 1e-14);
}

TEST(Mapmaker, PixelsSeenAtOneAngleAreCut) {
  const int nside = 8;
  const std::size_t npix = 12 * nside * nside;
  const Maps truth = random_maps(nside, 2);
  const pisco::Detector det{"d", 0.0, 0.0, 1.0, 0};
  pisco::BinnedMapmaker mm(nside);
  // Every pixel once at psi = 0, three more times at psi = 0 for the second quarter, and the
  // first half also at 45 and 90 deg.
  const pisco::Pointing all0 = pisco::pixel_centre_scan(nside, {0.0});
  mm.add(det, all0, make_tod(det, all0, truth, nside));
  const pisco::Pointing other = pisco::pixel_centre_scan(nside, {45 * deg, 90 * deg});
  const std::vector<double> tod_other = make_tod(det, other, truth, nside);
  for (std::size_t block = 0; block < 2; ++block)
    mm.add(det, other.view().subspan(block * npix, npix / 2),
           std::span<const double>(tod_other).subspan(block * npix, npix / 2));
  for (int rep = 0; rep < 3; ++rep)
    mm.add(det, all0.view().subspan(npix / 4, npix / 4),
           std::span<const double>(make_tod(det, all0, truth, nside)).subspan(npix / 4, npix / 4));

  const pisco::BinnedMaps out = mm.solve();
  std::size_t solved = 0, cut = 0;
  double worst_cut_rcond = 0;
  for (std::size_t pix = 0; pix < npix; ++pix) {
    if (pix < npix / 2) {
      ASSERT_EQ(out.hits[pix], pix < npix / 4 ? 3u : 6u) << pix;
      ASSERT_NEAR(out.Q[pix], truth.Q[pix], 1e-12) << pix;
      ++solved;
    } else {
      ASSERT_EQ(out.hits[pix], 1u) << pix;
      ASSERT_EQ(out.I[pix], pisco::unseen) << pix;
      ASSERT_EQ(out.Q[pix], pisco::unseen) << pix;
      ASSERT_EQ(out.U[pix], pisco::unseen) << pix;
      worst_cut_rcond = std::max(worst_cut_rcond, out.rcond[pix]);
      ++cut;
    }
  }
  std::cout << "single-angle cut: " << solved << " pixels solved, " << cut
            << " cut; largest rcond among the cut " << worst_cut_rcond << "\n";
  EXPECT_LT(worst_cut_rcond, 1e-12);
}

TEST(Mapmaker, RepeatedSingleAngleIsStillCut) {
  pisco::BinnedMapmaker mm(2);
  const pisco::Detector det{"d", 0.3, 0.0, 1.0, 0};
  const pisco::Pointing p = pisco::pixel_centre_scan(2, {0.0, 0.0, 0.0, pi});
  mm.add(det, p, std::vector<double>(p.size(), 1.0));
  const pisco::BinnedMaps out = mm.solve();
  std::cout << "four hits at psi 0 and pi (one polarization angle): rcond " << out.rcond[0] << "\n";
  for (std::size_t pix = 0; pix < out.hits.size(); ++pix) {
    EXPECT_EQ(out.hits[pix], 4u);
    EXPECT_EQ(out.I[pix], pisco::unseen);
    EXPECT_LT(out.rcond[pix], 1e-12);
  }
}

TEST(Mapmaker, UnvisitedPixelsAreUnseenWithZeroHits) {
  pisco::BinnedMapmaker mm(4);
  const pisco::Detector det{"d", 0.0, 0.0, 1.0, 0};
  const pisco::Pointing p = pisco::raster_scan(pi / 2, 1.0, 20 * deg, 4, {0.0, 60 * deg, 120 * deg});
  mm.add(det, p, std::vector<double>(p.size(), 2.0));
  const pisco::BinnedMaps out = mm.solve();
  std::size_t visited = 0;
  for (std::size_t pix = 0; pix < out.hits.size(); ++pix) {
    if (out.hits[pix] == 0) {
      EXPECT_EQ(out.I[pix], pisco::unseen);
      EXPECT_EQ(out.rcond[pix], 0.0);
    } else {
      ++visited;
      EXPECT_EQ(out.hits[pix], 3u);
      EXPECT_NEAR(out.I[pix], 4.0, 1e-13);
    }
  }
  std::cout << "raster: " << visited << " of " << out.hits.size() << " pixels visited\n";
  EXPECT_EQ(visited * 3, p.size());
}

TEST(Mapmaker, ChunkedAddEqualsOneAdd) {
  const int nside = 8;
  const Maps truth = random_maps(nside, 3);
  const pisco::Detector det{"d", -20 * deg, 0.01, 0.9, 0};
  const pisco::Pointing p = pisco::random_offset_scan(nside, {0.0, 30 * deg, 100 * deg}, 0.2, 9);
  std::vector<double> tod(p.size());
  for (std::size_t k = 0; k < tod.size(); ++k) tod[k] = std::sin(0.01 * double(k));

  pisco::BinnedMapmaker whole(nside), chunked(nside);
  whole.add(det, p, tod);
  const std::size_t chunk = 97;  // does not divide the stream evenly
  std::size_t chunks = 0;
  for (std::size_t first = 0; first < p.size(); first += chunk, ++chunks) {
    const std::size_t n = std::min(chunk, p.size() - first);
    chunked.add(det, p.view().subspan(first, n), std::span<const double>(tod).subspan(first, n));
  }
  const pisco::BinnedMaps a = whole.solve(), b = chunked.solve();
  std::cout << "chunked add: " << chunks << " chunks of " << chunk << " samples\n";
  EXPECT_EQ(a.I, b.I);
  EXPECT_EQ(a.Q, b.Q);
  EXPECT_EQ(a.U, b.U);
  EXPECT_EQ(a.hits, b.hits);
  EXPECT_EQ(a.rcond, b.rcond);
}

TEST(Mapmaker, BadInputsAreReportedAndLeaveTheMapsIntact) {
  expect_error([] { pisco::BinnedMapmaker(12); }, "BinnedMapmaker: NSIDE = 12 is not a power of two");
  expect_error([] { pisco::BinnedMapmaker(0); }, "NSIDE = 0");
  expect_error([] { pisco::BinnedMapmaker(8, -1.0); }, "rcond_min");
  expect_error([] { pisco::BinnedMapmaker(8, std::nan("")); }, "rcond_min");

  pisco::BinnedMapmaker mm(4);
  const pisco::Detector det{"det7", 0.0, 0.0, 1.0, 0};
  const pisco::Pointing p = pisco::pixel_centre_scan(4, {0.0, 45 * deg, 90 * deg});
  std::vector<double> tod(p.size(), 1.0);
  mm.add(det, p, tod);
  const pisco::BinnedMaps before = mm.solve();

  expect_error([&] { mm.add(det, p, std::span<const double>(tod).first(10)); }, "10 TOD samples");
  std::vector<double> bad = tod;
  bad[5] = std::nan("");
  expect_error([&] { mm.add(det, p, bad); }, "sample 5");
  bad[5] = 1.0;
  bad.back() = INFINITY;
  expect_error([&] { mm.add(det, p, bad); }, "sample " + std::to_string(bad.size() - 1));
  pisco::Pointing off = p;
  off.theta[3] = 4.0;
  expect_error([&] { mm.add(det, off, tod); }, "sample 3");
  pisco::Detector nan_gain = det;
  nan_gain.gain = std::nan("");
  expect_error([&] { mm.add(nan_gain, p, tod); }, "det7");

  const pisco::BinnedMaps after = mm.solve();
  EXPECT_EQ(before.I, after.I);
  EXPECT_EQ(before.hits, after.hits);
}



// add() on several threads: every pixel's sums the same bits as on one thread (each pixel's samples
// added in the order given), with samples across both poles, many samples in a few pixels, flags and
// a half-wave plate; and the detector pointing of the stream, on a pool, the same bits as in one pass.
TEST(BinnedMapmakerThreads, SameBitsWhateverTheThreads) {
  const int nside = 16;
  const std::size_t n = 50000;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  pisco::Pointing boresight;
  for (std::size_t i = 0; i < n; ++i) {
    // A third near the poles (within 3 deg), a third in a small patch (many samples a pixel), the rest
    // anywhere on the sphere.
    double theta = std::acos(1.0 - 2.0 * u(rng)), phi = 2 * pi * u(rng);
    if (i % 3 == 0) theta = i % 2 ? 3 * deg * u(rng) : pi - 3 * deg * u(rng);
    if (i % 3 == 1) {
      theta = 60 * deg + 2 * deg * u(rng);
      phi = 1.0 + 2 * deg * u(rng);
    }
    boresight.push_back(theta, phi, 2 * pi * u(rng) - pi);
  }
  std::vector<double> tod(n), hwp(n);
  std::vector<std::uint8_t> flags(n);
  for (std::size_t i = 0; i < n; ++i) {
    tod[i] = 2.7e6 + 100 * (u(rng) - 0.5);
    hwp[i] = 2 * pi * u(rng);
    flags[i] = i % 17 == 0;
  }
  pisco::FocalPlane fp;
  fp.add_pair("a", 10 * deg, 0, 0, 0.01, 1.0, 0.9);
  std::vector<pisco::Detector> dets = fp.detectors();
  dets[0].set_offset(1 * deg, -2 * deg, 0.3);
  dets[1].hwp = pisco::HalfWavePlate{pisco::ideal_hwp_mueller(), pisco::HwpPlacement::aperture, dets[1].zeta};
  const auto run = [&](unsigned threads) {
    pisco::BinnedMapmaker mm(nside);
    mm.set_threads(threads);
    pisco::Pointing own;
    for (std::size_t chunk = 0; chunk < 2; ++chunk)  // two calls: the threads and their scratch kept
      for (std::size_t d = 0; d < dets.size(); ++d) {
        pisco::detector_pointing(boresight, dets[d].offset, own);
        mm.add(dets[d], own, tod, dets[d].hwp ? std::span<const double>(hwp) : std::span<const double>(),
               chunk ? std::span<const std::uint8_t>(flags) : std::span<const std::uint8_t>());
      }
    return mm;
  };
  const pisco::BinnedMapmaker one = run(1);
  for (const unsigned threads : {2u, 3u, 5u, 0u}) {
    const pisco::BinnedMapmaker many = run(threads);
    EXPECT_GE(many.threads(), 1u);
    const auto same = [](auto a, auto b) { return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin()); };
    EXPECT_TRUE(same(one.normal_matrices(), many.normal_matrices())) << threads << " threads";
    EXPECT_TRUE(same(one.normal_vectors(), many.normal_vectors())) << threads << " threads";
    EXPECT_TRUE(same(one.hits(), many.hits())) << threads << " threads";
  }
  // Copies keep the maps and the number of threads.
  pisco::BinnedMapmaker three = run(3);
  const pisco::BinnedMapmaker copy = three;
  EXPECT_EQ(copy.threads(), 3u);
  EXPECT_TRUE(std::equal(copy.normal_vectors().begin(), copy.normal_vectors().end(), one.normal_vectors().begin()));
  expect_error([] { pisco::BinnedMapmaker(4).set_threads(1u << 30); }, "BinnedMapmaker: threads");
}

TEST(BinnedMapmakerThreads, DetectorPointingOnAPoolIsTheSameBits) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  pisco::Pointing angles;
  std::vector<pisco::Quat> quats;
  for (std::size_t i = 0; i < 20000; ++i) {
    const double theta = i % 4 == 0 ? 0.5 * deg * u(rng) : std::acos(1.0 - 2.0 * u(rng));
    angles.push_back(theta, 2 * pi * u(rng), 2 * pi * u(rng) - pi);
    quats.push_back(pisco::quat_from_pointing(angles.theta[i], angles.phi[i], angles.psi[i]));
  }
  pisco::detail::ThreadPool pool(3);
  for (const pisco::Quat& offset : {pisco::Quat{0, 0, 0, 1}, pisco::offset_quat(2 * deg, -1 * deg, 30 * deg)}) {
    pisco::Pointing serial, parallel;
    pisco::detector_pointing(angles, offset, serial);
    pisco::detail::detector_pointing(angles.view(), offset, parallel, pool);
    EXPECT_EQ(serial.theta, parallel.theta);
    EXPECT_EQ(serial.phi, parallel.phi);
    EXPECT_EQ(serial.psi, parallel.psi);
    pisco::detector_pointing(pisco::QuatPointingView{quats}, offset, serial);
    pisco::detail::detector_pointing(pisco::QuatPointingView{quats}, offset, parallel, pool);
    EXPECT_EQ(serial.theta, parallel.theta);
    EXPECT_EQ(serial.psi, parallel.psi);
  }
}

// Binning from the boresight (the detector's offset applied in the map-maker, its angle from the
// rotation's columns): the maps of detector_pointing then add() to rounding, with samples across both
// poles and exactly on them, offsets, a plate and flags; the same bits whatever the threads.
TEST(BinnedMapmakerThreads, FromTheBoresightEqualsThePointingThenAdd) {
  const int nside = 32;
  const std::size_t n = 30000;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<pisco::Quat> quats;
  for (std::size_t i = 0; i < n; ++i) {
    double theta = std::acos(1.0 - 2.0 * u(rng));
    if (i % 4 == 0) theta = i % 8 ? 5 * deg * u(rng) : pi - 5 * deg * u(rng);
    if (i < 4) theta = i % 2 ? 0.0 : pi;  // on the poles themselves
    quats.push_back(pisco::quat_from_pointing(theta, 2 * pi * u(rng), 2 * pi * u(rng) - pi));
  }
  std::vector<double> tod(n), hwp(n);
  std::vector<std::uint8_t> flags(n);
  for (std::size_t i = 0; i < n; ++i) {
    tod[i] = 2.7 + 1e-3 * (u(rng) - 0.5);
    hwp[i] = 2 * pi * u(rng);
    flags[i] = i % 13 == 5;
  }
  pisco::FocalPlane fp;
  fp.add_pair("a", 30 * deg, 0, 0, 0.02, 1.0, 0.95);
  std::vector<pisco::Detector> dets = fp.detectors();
  dets[0].set_offset(2 * deg, -1.5 * deg, 0.4);
  dets.push_back(dets[1]);
  dets.back().name = "plated";
  dets.back().set_offset(-3 * deg, 0.5 * deg, -0.2);
  dets.back().hwp = pisco::HalfWavePlate{pisco::ideal_hwp_mueller(), pisco::HwpPlacement::aperture, 0.1};
  const pisco::QuatPointingView view{quats};
  const auto run = [&](bool from_boresight, unsigned threads) {
    pisco::BinnedMapmaker mm(nside);
    mm.set_threads(threads);
    pisco::Pointing own;
    for (const pisco::Detector& d : dets) {
      const std::span<const double> h = d.hwp ? std::span<const double>(hwp) : std::span<const double>();
      if (from_boresight) {
        mm.add_from_boresight(d, view, tod, h, flags);
      } else {
        pisco::detector_pointing(view, d.offset, own);
        mm.add(d, own, tod, h, flags);
      }
    }
    return mm;
  };
  const pisco::BinnedMapmaker before = run(false, 1), after = run(true, 1);
  EXPECT_TRUE(std::equal(before.hits().begin(), before.hits().end(), after.hits().begin()));
  double worst = 0.0;
  for (const auto& [a, b] : {std::pair{before.normal_matrices(), after.normal_matrices()},
                             {before.normal_vectors(), after.normal_vectors()}})
    for (std::size_t k = 0; k < a.size(); ++k) worst = std::max(worst, std::abs(a[k] - b[k]) / (1.0 + std::abs(a[k])));
  std::cout << "from the boresight against the pointing then add: largest difference " << worst << "\n";
  EXPECT_LT(worst, 1e-12);
  const pisco::BinnedMaps m0 = before.solve(), m1 = after.solve();
  EXPECT_GT(std::count_if(m0.I.begin(), m0.I.end(), [](double v) { return v != pisco::unseen; }), 1000);
  for (std::size_t p = 0; p < m0.I.size(); ++p)
    if (m0.I[p] != pisco::unseen) {
      ASSERT_NE(m1.I[p], pisco::unseen) << p;
      EXPECT_NEAR(m0.Q[p], m1.Q[p], 1e-9) << p;
    }
  const pisco::BinnedMapmaker three = run(true, 3);
  EXPECT_TRUE(std::equal(after.normal_vectors().begin(), after.normal_vectors().end(), three.normal_vectors().begin()));
  EXPECT_TRUE(std::equal(after.normal_matrices().begin(), after.normal_matrices().end(), three.normal_matrices().begin()));
  // Checked as add() is: a bad quaternion and a short TOD are named.
  std::vector<pisco::Quat> bad = quats;
  bad[7] = {0.0, 0.0, 0.0, 2.0};
  expect_error([&] { pisco::BinnedMapmaker(4).add_from_boresight(dets[0], pisco::QuatPointingView{bad}, tod); },
               "BinnedMapmaker::add_from_boresight: quaternion of sample 7");
  expect_error([&] { pisco::BinnedMapmaker(4).add_from_boresight(dets[0], view, std::span<const double>(tod).first(3)); },
               "3 TOD samples for 30000 pointing samples");
}

}  // namespace
