// The simd backend's disc walk (src/simd/simd_kernel.cpp, DiscRanges) against the reference's
// for_each_disc_range (kernel/disc.hpp, itself held to HEALPix query_disc by test_disc): the same
// ranges, in the same order, on every instruction set this machine runs, for random discs, discs
// centred on pixel centres with the radii of docs/validation.md's Table 1 workload, discs through the
// poles and across phi = 0; and with every ring sent through the scalar fallback.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "kernel/disc.hpp"
#include "pisco/error.hpp"
#include "pisco/units.hpp"
#include "simd/simd_kernel.hpp"
#include "simd_targets.hpp"

namespace {

using pisco::deg;
namespace detail = pisco::detail;
constexpr double pi = std::numbers::pi;

std::vector<std::uint32_t> reference(const std::vector<detail::RingEntry>& rings, std::int64_t nside, double theta,
                                     double phi, double rho) {
  std::vector<std::uint32_t> out;
  detail::for_each_disc_range(rings.data(), nside, theta, phi, rho, std::cos(rho), [&](std::uint32_t b, std::uint32_t e) {
    if (e <= b) return;
    out.push_back(b);
    out.push_back(e);
  });
  return out;
}

// The instruction sets this machine runs (Highway's names), best first.
std::vector<detail::simd::Kernel> kernels() {
  std::vector<detail::simd::Kernel> out;
  for (const auto& named : pisco_test::simd_kernels()) out.push_back(named.second);
  if (out.empty()) out.push_back(detail::simd::choose_kernel("auto"));
  return out;
}

struct Tally {
  std::size_t discs = 0, rings = 0, redone = 0;
};

// A ring table and its columns, as the simd backend holds them.
struct Rings {
  std::vector<detail::RingEntry> table;
  detail::simd::RingColumns columns;
  explicit Rings(std::int64_t nside) : table(detail::make_ring_table(int(nside))), columns(table) {}
};

void compare(const detail::simd::Kernel& k, const Rings& rings, std::int64_t nside,
             double theta, double phi, double rho, Tally& tally, double margin = 1e-9) {
  phi = detail::wrap_phi(phi);
  const std::vector<std::uint32_t> want = reference(rings.table, nside, theta, phi, rho);
  std::vector<std::uint32_t> got;
  std::size_t redone = 0;
  got.assign(3, 7u);  // a buffer with something in it: disc_ranges writes from its start
  got.resize(detail::simd::disc_ranges(k, rings.table.data(), rings.columns, nside, theta, phi, rho, std::cos(rho), got,
                                       &redone, margin));
  ASSERT_EQ(got, want) << k.description << ": NSIDE " << nside << " theta " << theta << " phi " << phi << " rho "
                       << rho / deg << " deg";
  const detail::DiscRings d = detail::disc_rings(nside, theta, rho);
  tally.discs += 1;
  tally.rings += std::size_t(std::max<std::int64_t>(0, d.last - d.first + 1));
  tally.redone += redone;
}

TEST(SimdDisc, RandomDiscsAreTheReferencesOnEveryInstructionSet) {
  for (const auto& k : kernels()) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    Tally tally;
    for (std::int64_t nside : {1, 2, 16, 64, 512, 2048}) {
      const Rings rings(nside);
      for (int n = 0; n < 400; ++n) {
        const double theta = std::acos(1.0 - 2.0 * u(rng));
        const double phi = 2.0 * pi * u(rng);
        const double rho = (n % 4 == 0 ? 90.0 : 20.0) * deg * std::max(u(rng), 1e-4);
        compare(k, rings, nside, theta, phi, rho, tally);
      }
      // Poles inside, discs grazing the poles, phi across 0.
      for (double theta : {0.0, 1e-9, 0.5 * deg, 3.0 * deg, pi - 3.0 * deg, pi - 1e-9, pi})
        for (double phi : {0.0, 1e-12, 2.0 * pi - 1e-12, 1.0})
          for (double rho : {0.1 * deg, 3.0 * deg, 5.0 * deg, 45.0 * deg, 90.0 * deg})
            compare(k, rings, nside, theta, phi, rho, tally);
    }
    // The vector arithmetic decides nearly every ring: the scalar fallback is the exception.
    EXPECT_GT(tally.rings, 100000u);
    EXPECT_LT(double(tally.redone), 1e-4 * double(tally.rings)) << k.description << ": " << tally.redone << " of "
                                                                << tally.rings << " rings redone";
    std::printf("%s: %zu discs, %zu rings, %zu redone in scalar arithmetic\n", k.description.c_str(), tally.discs,
                tally.rings, tally.redone);
  }
}

// Discs centred on pixel centres with Table 1's radii: the bounds of rings of the pointing's own
// count fall on pixel centres' longitudes plus a common offset, where ties are likeliest.
TEST(SimdDisc, DiscsAtPixelCentresAreTheReferences) {
  for (const auto& k : kernels()) {
    Tally tally;
    for (std::int64_t nside : {128, 256, 1024}) {
      const Rings rings(nside);
      for (std::size_t ring = 1; ring <= rings.table.size(); ring += std::size_t(nside / 16)) {
        const detail::RingEntry& r = rings.table[ring - 1];
        const double theta = std::acos(r.z);
        for (std::uint32_t j = 0; j < r.count; j += std::max(1u, r.count / 7)) {
          const double phi = (j + (r.shifted ? 0.5 : 0.0)) * 2.0 * pi / r.count;
          for (double rho : {5.0 * deg, 10.0 * deg}) compare(k, rings, nside, theta, phi, rho, tally);
        }
      }
    }
    EXPECT_GT(tally.discs, 1000u);
  }
}

// A margin wider than any fraction sends every ring through the reference's scalar arithmetic.
TEST(SimdDisc, TheScalarFallbackIsTheReference) {
  const auto k = detail::simd::choose_kernel("auto");
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Tally tally;
  for (std::int64_t nside : {4, 64, 1024}) {
    const Rings rings(nside);
    for (int n = 0; n < 200; ++n)
      compare(k, rings, nside, std::acos(1.0 - 2.0 * u(rng)), 2.0 * pi * u(rng), 30.0 * deg * u(rng) + 1e-3, tally,
              0.5);
  }
  EXPECT_GT(tally.redone, tally.rings / 2);
}

}  // namespace
