// A3 (docs/validation.md, "A"): the ring-table disc selection returns exactly HEALPix query_disc's pixel set.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>
#include <random>

#include <healpix_base.h>
#include <pointing.h>
#include <rangeset.h>

#include "kernel/disc.hpp"
#include "core/prepared.hpp"
#include "pisco/units.hpp"

namespace {

constexpr double pi = std::numbers::pi;
using pisco::deg;

rangeset<std::int64_t> ours(const std::vector<pisco::detail::RingEntry>& rings, int nside, double theta,
                            double phi, double rho) {
  std::vector<std::pair<std::int64_t, std::int64_t>> ranges;
  pisco::detail::for_each_disc_range(rings.data(), nside, theta, pisco::detail::wrap_phi(phi), rho,
                                     std::cos(rho), [&](std::uint32_t b, std::uint32_t e) {
                                       EXPECT_LT(b, e);
                                       ranges.emplace_back(b, e);
                                     });
  rangeset<std::int64_t> set;
  for (auto [b, e] : ranges) set.add(b, e);
  // Ranges never overlap: the total pixel count equals the merged set's.
  std::int64_t total = 0;
  for (auto [b, e] : ranges) total += e - b;
  EXPECT_EQ(total, set.nval());
  return set;
}

bool same(const rangeset<std::int64_t>& a, const rangeset<std::int64_t>& b) {
  if (a.nranges() != b.nranges()) return false;
  for (std::size_t i = 0; i < a.nranges(); ++i)
    if (a.ivbegin(i) != b.ivbegin(i) || a.ivend(i) != b.ivend(i)) return false;
  return true;
}

// Compares our set with query_disc for one pointing; returns the number of pixels.
std::int64_t compare(const Healpix_Base2& base, const std::vector<pisco::detail::RingEntry>& rings,
                     double theta, double phi, double rho) {
  const rangeset<std::int64_t> ref = base.query_disc(pointing(theta, phi), rho);
  const rangeset<std::int64_t> got = ours(rings, base.Nside(), theta, phi, rho);
  EXPECT_TRUE(same(ref, got)) << "NSIDE " << base.Nside() << " theta " << theta << " phi " << phi
                          << " rho " << rho / deg << " deg: query_disc " << ref.nval()
                          << " pixels, ring table " << got.nval();
  return ref.nval();
}

TEST(Disc, RingTableMatchesHealpix) {
  for (int nside : {1, 2, 16, 256}) {
    const auto rings = pisco::detail::make_ring_table(nside);
    const Healpix_Base base(nside, RING, SET_NSIDE);
    ASSERT_EQ(rings.size(), std::size_t(4 * nside - 1));
    for (int r = 1; r < 4 * nside; ++r) {
      int first, count;
      bool shifted;
      base.get_ring_info_small(r, first, count, shifted);
      EXPECT_EQ(rings[r - 1].first, std::uint32_t(first));
      EXPECT_EQ(rings[r - 1].count, std::uint32_t(count));
      EXPECT_EQ(rings[r - 1].shifted, shifted ? 1u : 0u);
      // z of the ring equals the colatitude of its pixel centres.
      EXPECT_NEAR(rings[r - 1].z, std::cos(base.pix2ang(first).theta), 1e-15);
    }
  }
}

TEST(Disc, RandomPointingsEqualQueryDisc) {
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::int64_t pixels = 0, cases = 0;
  for (int nside : {16, 64, 256, 1024, 2048}) {
    const Healpix_Base2 base(nside, RING, SET_NSIDE);
    const auto rings = pisco::detail::make_ring_table(nside);
    const int n = nside >= 1024 ? 40 : 150;
    for (int i = 0; i < n; ++i) {
      const double theta = std::acos(1 - 2 * u(rng));
      const double phi = 2 * pi * u(rng);
      // rho in 0.5 .. 60 deg
      const double rho_max_deg = 60.0;
      const double rho = (0.5 + (rho_max_deg - 0.5) * u(rng)) * deg;
      pixels += compare(base, rings, theta, phi, rho);
      ++cases;
    }
  }
  std::cout << "A3 random: " << cases << " discs, " << pixels << " pixels, all equal to query_disc\n";
}

TEST(Disc, PolesAndPhiZeroEqualQueryDisc) {
  std::mt19937_64 rng(777);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int cases = 0;
  for (int nside : {16, 128, 2048}) {
    const Healpix_Base2 base(nside, RING, SET_NSIDE);
    const auto rings = pisco::detail::make_ring_table(nside);
    for (double rho_deg : {0.5, 1.5, 5.0, 20.0, 60.0}) {
      const double rho = rho_deg * deg;
      for (int i = 0; i < 12; ++i) {
        const double near = u(rng) * 1.0 * deg;  // within 1 deg of a pole
        const double phi = 2 * pi * u(rng);
        compare(base, rings, near, phi, rho);
        compare(base, rings, pi - near, phi, rho);
        // across phi = 0: just above 0 and just below 2 pi
        const double theta = std::acos(1 - 2 * u(rng));
        compare(base, rings, theta, 1e-9 + 0.01 * u(rng), rho);
        compare(base, rings, theta, 2 * pi - 1e-9 - 0.01 * u(rng), rho);
        cases += 4;
      }
      // a pole inside the disc, and the pixel centres nearest the poles
      compare(base, rings, rho * 0.5, 0.3, rho);
      compare(base, rings, pi - rho * 0.5, 5.9, rho);
      compare(base, rings, base.pix2ang(0).theta, base.pix2ang(0).phi, rho);
      cases += 3;
    }
  }
  std::cout << "A3 poles and phi = 0: " << cases << " discs equal to query_disc\n";
}

TEST(Disc, PixelCentrePointingsEqualQueryDisc) {
  // Pointing exactly at pixel centres (the paper's scans) with the Table 1 radii.
  const int nside = 128;
  const Healpix_Base2 base(nside, RING, SET_NSIDE);
  const auto rings = pisco::detail::make_ring_table(nside);
  int cases = 0;
  for (double rho_deg : {5.0, 7.5, 10.0, 15.0, 20.0, 25.0, 30.0}) {
    std::int64_t max_pixels = 0;
    for (std::int64_t p = 0; p < base.Npix(); p += 997) {
      const pointing ptg = base.pix2ang(p);
      max_pixels = std::max(max_pixels, compare(base, rings, ptg.theta, ptg.phi, rho_deg * deg));
      ++cases;
    }
    std::cout << "A3 NSIDE 128 pixel centres, rho_max " << rho_deg << " deg: up to " << max_pixels
              << " pixels per disc\n";
  }
  std::cout << "A3 pixel centres: " << cases << " discs equal to query_disc\n";
}

}  // namespace
