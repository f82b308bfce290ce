// Scan generators (docs/config.md, "[scan]"): pixel-centre, random-offset and raster scans.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <numbers>
#include <set>
#include <string>

#include <healpix_base.h>
#include <pointing.h>

#include "support.hpp"
#include "pisco/error.hpp"
#include "pisco/scan.hpp"
#include "pisco/units.hpp"
#include "scans/scan_kind.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;

using Base = T_Healpix_Base<std::int64_t>;

Base ring(int nside) { return Base(std::int64_t(nside), RING, SET_NSIDE); }

// Longitude difference folded into (-pi, pi].
double dphi(double a, double b) { return std::remainder(a - b, 2 * pi); }

using pisco_test::expect_error;

TEST(Scan, PixelCentreVisitsEveryPixelAtEveryAngle) {
  const int nside = 16;
  const std::vector<double> psis = {0.0, 45 * deg, 90 * deg};
  const pisco::Pointing p = pisco::pixel_centre_scan(nside, psis);
  const Base base = ring(nside);
  const std::size_t npix = std::size_t(base.Npix());
  std::cout << "pixel_centre_scan NSIDE 16, 3 angles: " << p.size() << " samples (expected "
            << 3 * npix << ")\n";
  ASSERT_EQ(p.size(), 3 * npix);
  ASSERT_EQ(p.phi.size(), p.size());
  ASSERT_EQ(p.psi.size(), p.size());
  for (std::size_t k = 0; k < p.size(); ++k) {
    ASSERT_EQ(base.ang2pix(pointing(p.theta[k], p.phi[k])), std::int64_t(k % npix)) << k;
    ASSERT_EQ(p.psi[k], psis[k / npix]) << k;
  }
}

TEST(Scan, RandomOffsetsAreSharedByEveryAngle) {
  // Paper 6.3: a pixel is seen at the same displaced position at every psi.
  const int nside = 16;
  const std::size_t npix = 12 * nside * nside;
  const pisco::Pointing p = pisco::random_offset_scan(nside, {0.0, 45 * deg, 90 * deg}, 0.1, 5);
  ASSERT_EQ(p.size(), 3 * npix);
  for (std::size_t i = 0; i < npix; ++i)
    for (std::size_t k = 1; k < 3; ++k) {
      EXPECT_EQ(p.theta[i], p.theta[k * npix + i]);
      EXPECT_EQ(p.phi[i], p.phi[k * npix + i]);
      EXPECT_EQ(p.psi[k * npix + i], k * 45 * deg);
    }
}

TEST(Scan, RandomOffsetsStayWithinHalfWidth) {
  const int nside = 32;
  const double f = 0.1;
  const pisco::Pointing p = pisco::random_offset_scan(nside, {0.0, 90 * deg}, f, 42);
  const Base base = ring(nside);
  const std::size_t npix = std::size_t(base.Npix());
  ASSERT_EQ(p.size(), 2 * npix);
  const double half = 0.5 * f * std::sqrt(4 * pi / double(npix));
  double max_dtheta = 0, max_dphi_arc = 0, sum_dtheta = 0;
  for (std::size_t k = 0; k < p.size(); ++k) {
    const pointing c = base.pix2ang(std::int64_t(k % npix));
    ASSERT_GE(p.theta[k], 0.0);
    ASSERT_LE(p.theta[k], pi);
    ASSERT_GE(p.phi[k], 0.0);
    ASSERT_LT(p.phi[k], 2 * pi);
    const double dt = p.theta[k] - c.theta;
    ASSERT_LE(std::abs(dt), half * (1 + 1e-12)) << k;
    max_dtheta = std::max(max_dtheta, std::abs(dt));
    sum_dtheta += dt;
    // Longitude offsets are f Omega / sin(theta) wide; the pole reflections change phi by pi.
    if (c.theta > half && c.theta < pi - half) {
      const double arc = std::abs(dphi(p.phi[k], c.phi)) * std::sin(c.theta);
      ASSERT_LE(arc, half * (1 + 1e-9)) << k;
      max_dphi_arc = std::max(max_dphi_arc, arc);
    }
  }
  std::cout << "random_offset_scan NSIDE 32 f 0.1: half width " << half << " rad, max |dtheta| "
            << max_dtheta << ", max |dphi| sin(theta) " << max_dphi_arc << ", mean dtheta "
            << sum_dtheta / double(p.size()) << "\n";
  // The offsets fill the interval rather than collapsing to a point.
  EXPECT_GT(max_dtheta, 0.99 * half);
  EXPECT_GT(max_dphi_arc, 0.99 * half);
  EXPECT_LT(std::abs(sum_dtheta / double(p.size())), 0.02 * half);
}

TEST(Scan, ZeroOffsetIsThePixelCentreScan) {
  const std::vector<double> psis = {0.0, 1.0};
  const pisco::Pointing a = pisco::random_offset_scan(8, psis, 0.0, 7);
  const pisco::Pointing b = pisco::pixel_centre_scan(8, psis);
  EXPECT_EQ(a.theta, b.theta);
  EXPECT_EQ(a.phi, b.phi);
  EXPECT_EQ(a.psi, b.psi);
}

TEST(Scan, SymmetricPairsAverageToThePixelCentre) {
  const int nside = 32;
  const pisco::Pointing p = pisco::random_offset_scan(nside, {0.0, 45 * deg}, 0.1, 3, true);
  const Base base = ring(nside);
  const std::size_t npix = std::size_t(base.Npix());
  ASSERT_EQ(p.size(), 2 * 2 * npix);
  double worst_theta = 0, worst_phi = 0;
  std::size_t pairs = 0;
  for (std::size_t k = 0; k + 1 < p.size(); k += 2) {
    const pointing c = base.pix2ang(std::int64_t((k / 2) % npix));
    ASSERT_EQ(p.psi[k], p.psi[k + 1]);
    if (c.theta < 0.1 || c.theta > pi - 0.1) continue;  // away from the pole reflections
    ++pairs;
    worst_theta = std::max(worst_theta, std::abs(0.5 * (p.theta[k] + p.theta[k + 1]) - c.theta));
    worst_phi = std::max(worst_phi, std::abs(dphi(p.phi[k], c.phi) + dphi(p.phi[k + 1], c.phi)));
    // Each pair is a genuine offset, not the centre twice.
    ASSERT_NE(p.theta[k], p.theta[k + 1]);
  }
  std::cout << "symmetric offsets: " << pairs << " pairs, worst |mean theta - centre| "
            << worst_theta << ", worst |dphi1 + dphi2| " << worst_phi << " rad\n";
  EXPECT_LT(worst_theta, 1e-15);
  EXPECT_LT(worst_phi, 1e-14);
}

TEST(Scan, SeedDeterminesTheStream) {
  const std::vector<double> psis = {0.0};
  const pisco::Pointing a = pisco::random_offset_scan(16, psis, 0.2, 123);
  const pisco::Pointing b = pisco::random_offset_scan(16, psis, 0.2, 123);
  const pisco::Pointing c = pisco::random_offset_scan(16, psis, 0.2, 124);
  EXPECT_EQ(a.theta, b.theta);
  EXPECT_EQ(a.phi, b.phi);
  std::size_t differ = 0;
  for (std::size_t k = 0; k < a.size(); ++k) differ += a.theta[k] != c.theta[k];
  std::cout << "seed 123 vs 124: " << differ << " of " << a.size() << " theta values differ\n";
  EXPECT_GT(differ, a.size() * 99 / 100);
}

TEST(Scan, RasterIsTheQueryDiscSetAtEachAngle) {
  const int nside = 64;
  const double theta0 = 60 * deg, phi0 = 350 * deg, radius = 3 * deg;
  const std::vector<double> psis = {0.0, 45 * deg, 90 * deg};
  const pisco::Pointing p = pisco::raster_scan(theta0, phi0, radius, nside, psis);
  const Base base = ring(nside);
  const std::vector<std::int64_t> disc = base.query_disc(pointing(theta0, phi0), radius).toVector();
  std::cout << "raster 3 deg at NSIDE 64: " << disc.size() << " pixels x " << psis.size()
            << " angles = " << p.size() << " samples\n";
  ASSERT_FALSE(disc.empty());
  ASSERT_EQ(p.size(), disc.size() * psis.size());
  const vec3 centre = pointing(theta0, phi0).to_vec3();
  for (std::size_t j = 0; j < psis.size(); ++j) {
    std::set<std::int64_t> seen;
    for (std::size_t i = 0; i < disc.size(); ++i) {
      const std::size_t k = j * disc.size() + i;
      EXPECT_EQ(p.psi[k], psis[j]);
      const pointing s(p.theta[k], p.phi[k]);
      seen.insert(base.ang2pix(s));
      EXPECT_LE(std::acos(std::min(1.0, dotprod(s.to_vec3(), centre))), radius + 1e-12);
    }
    EXPECT_EQ(seen, std::set<std::int64_t>(disc.begin(), disc.end()));
  }
}

TEST(Scan, BadInputsNameTheArgument) {
  const std::vector<double> ok = {0.0};
  expect_error([&] { pisco::pixel_centre_scan(3, ok); }, "NSIDE =");
  expect_error([&] { pisco::pixel_centre_scan(0, ok); }, "NSIDE =");
  expect_error([&] { pisco::pixel_centre_scan(-4, ok); }, "NSIDE =");
  expect_error([&] { pisco::pixel_centre_scan(8, {}); }, "psis");
  expect_error([&] { pisco::pixel_centre_scan(8, {0.0, std::nan("")}); }, "psis[1]");
  expect_error([&] { pisco::random_offset_scan(8, ok, -0.1, 1); }, "f =");
  expect_error([&] { pisco::random_offset_scan(8, ok, INFINITY, 1); }, "f =");
  expect_error([&] { pisco::random_offset_scan(12, ok, 0.1, 1); }, "NSIDE =");
  expect_error([&] { pisco::raster_scan(1.0, 0.0, 0.0, 8, ok); }, "radius");
  expect_error([&] { pisco::raster_scan(1.0, 0.0, pi, 8, ok); }, "radius");
  expect_error([&] { pisco::raster_scan(1.0, 0.0, std::nan(""), 8, ok); }, "radius");
  expect_error([&] { pisco::raster_scan(-0.1, 0.0, 0.1, 8, ok); }, "theta0");
  expect_error([&] { pisco::raster_scan(1.0, INFINITY, 0.1, 8, ok); }, "phi0");
  expect_error([&] { pisco::raster_scan(1.0, 0.0, 0.1, 6, ok); }, "NSIDE =");
  expect_error([&] { pisco::raster_scan(1.0, 0.0, 0.1, 8, {}); }, "psis");
}

}  // namespace

// Every kind of [scan] is registered once (scans/scan_kinds.cpp) under its ScanKind and name, and its
// generator gives the pointing of any range of samples as the scan's own functions give it.
TEST(ScanKinds, EveryKindIsRegisteredOnceAndGivesAnyRange) {
  using namespace pisco::detail;
  std::set<std::string> names;
  for (const ScanKindEntry* k : scan_kinds()) {
    EXPECT_TRUE(names.insert(k->name).second) << k->name;
    EXPECT_EQ(&scan_kind(k->kind), k);
    EXPECT_EQ(scan_kind_named(k->name), k);
    EXPECT_STREQ(pisco::scan_kind_name(k->kind), k->name);
  }
  EXPECT_EQ(names, (std::set<std::string>{"pixel_centres", "random_offsets", "raster", "ces", "satellite", "file"}));
  EXPECT_EQ(scan_kind_named("spiral"), nullptr);

  pisco::ScanConfig c;
  c.kind = pisco::ScanKind::ces;
  c.ces.samples = 5000;
  c.ces.az_throw = 20 * pisco::deg;
  c.ces.boresight_angles = {0.0, 0.5};
  c.ces.boresight_period = 60.0;
  pisco::ScanConfig sat;
  sat.kind = pisco::ScanKind::satellite;
  sat.satellite.samples = 5000;
  pisco::ScanConfig pix;
  pix.kind = pisco::ScanKind::random_offsets;
  pix.nside = 8;
  pix.psi = {0.0, 1.0};
  for (const pisco::ScanConfig* s : {&c, &sat, &pix}) {
    SCOPED_TRACE(pisco::scan_kind_name(s->kind));
    const auto g = scan_kind(s->kind).make(*s);
    EXPECT_EQ(g->samples(), s == &pix ? 2 * 768u : 5000u);
    EXPECT_EQ(g->quaternions(), s == &sat);
    EXPECT_EQ(scan_kind(s->kind).sample_rate(*s), s == &c ? c.ces.sample_rate : s == &sat ? sat.satellite.sample_rate : 0.0);
    pisco::Pointing all, part, direct;
    std::vector<pisco::Quat> qall, qpart, qdirect;
    g->generate(0, g->samples(), all, qall);
    const std::size_t first = g->samples() / 4, count = g->samples() / 3;
    g->generate(first, count, part, qpart);
    if (s == &c) c.ces.generate(first, count, direct);
    if (s == &sat) sat.satellite.generate(first, count, qdirect);
    if (s == &pix) {
      const pisco::Pointing p = pisco::random_offset_scan(8, pix.psi, pix.f, pix.seed, pix.symmetric);
      const pisco::PointingView v = p.view().subspan(first, count);
      direct.theta.assign(v.theta.begin(), v.theta.end());
      direct.phi.assign(v.phi.begin(), v.phi.end());
      direct.psi.assign(v.psi.begin(), v.psi.end());
    }
    ASSERT_EQ(g->quaternions() ? qpart.size() : part.size(), count);
    for (std::size_t i = 0; i < count; ++i) {
      if (g->quaternions()) {
        for (const pisco::Quat& q : {qall[first + i], qdirect[i]}) {
          EXPECT_EQ(qpart[i].x, q.x);
          EXPECT_EQ(qpart[i].y, q.y);
          EXPECT_EQ(qpart[i].z, q.z);
          EXPECT_EQ(qpart[i].w, q.w);
        }
      } else {
        EXPECT_EQ(part.theta[i], all.theta[first + i]);
        EXPECT_EQ(part.psi[i], all.psi[first + i]);
        EXPECT_EQ(part.theta[i], direct.theta[i]);
        EXPECT_EQ(part.phi[i], direct.phi[i]);
        EXPECT_EQ(part.psi[i], direct.psi[i]);
      }
    }
  }
}
