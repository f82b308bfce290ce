// The polar copy made around each pole (src/core/polar_copy.hpp, src/core/polar_fit.hpp; docs/physics.md,
// "The quadrature"): against the exact turned sky (the a_lm turned by rotate_alm and synthesized at the
// copy's pixels), for skies band-limited up to 3 NSIDE - 1, with and without a monopole and a dipole; a
// compact source near each pole; its transpose by the dot-product test, within the fit's zone and
// beyond it; the same bits on any number of threads. The comparisons are of the copy smoothed by a beam
// of 6 pixels per FWHM, what a sample on the copy sums, around both turned poles.
#include <gtest/gtest.h>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <alm_powspec_tools.h>
#include <healpix_base.h>
#include <healpix_map.h>
#include <xcomplex.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

#include "core/polar_copy.hpp"
#include "pisco/error.hpp"
#include "pisco/sky.hpp"

namespace {
constexpr double pi = std::numbers::pi;
using AlmD = Alm<xcomplex<double>>;

struct Alms {
  AlmD t, e, b;
};

// Random a_lm with C_l = 1 / (1 + (l / 30)^2) (the accuracy map's red spectrum), E and B at 0.3 of
// T's amplitude; with `monopole`, a 100-unit monopole and a unit dipole along (1, 2, 3) / sqrt(14).
Alms random_alms(int lmax, unsigned seed, bool monopole) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  Alms a{{lmax, lmax}, {lmax, lmax}, {lmax, lmax}};
  for (AlmD* x : {&a.t, &a.e, &a.b}) {
    const double scale = x == &a.t ? 1.0 : 0.3;
    for (int m = 0; m <= lmax; ++m)
      for (int l = m; l <= lmax; ++l) {
        const double c = x != &a.t && l < 2 ? 0.0 : scale / std::sqrt(1.0 + (l / 30.0) * (l / 30.0));
        (*x)(l, m) = m == 0 ? xcomplex<double>(c * g(rng), 0.0)
                            : xcomplex<double>(c * g(rng) / std::sqrt(2.0), c * g(rng) / std::sqrt(2.0));
      }
  }
  if (monopole) {
    a.t(0, 0) += 100.0 * std::sqrt(4 * pi);
    a.t(1, 0) += std::sqrt(4 * pi / 3) * 3.0 / std::sqrt(14.0);
    a.t(1, 1) += std::sqrt(2 * pi / 3) * xcomplex<double>(-1.0, 2.0) / std::sqrt(14.0);
  }
  return a;
}

pisco::Sky maps(const Alms& a, int nside) {
  Healpix_Map<double> t(nside, RING, SET_NSIDE), q(nside, RING, SET_NSIDE), u(nside, RING, SET_NSIDE);
  alm2map_pol(a.t, a.e, a.b, t, q, u);
  pisco::Sky s(nside);
  for (int p = 0; p < t.Npix(); ++p) {
    s.I()[std::size_t(p)] = t[p];
    s.Q()[std::size_t(p)] = q[p];
    s.U()[std::size_t(p)] = u[p];
  }
  return s;
}

// A Gaussian of 6 pixels FWHM (peak 1; with `unit`, scaled to a unit sum) summed over the copy's
// pixels around `centre`, for I, Q, U.
std::array<double, 3> smoothed(const pisco::Sky& s, const vec3& centre, bool unit = true) {
  const Healpix_Base base(s.nside(), RING, SET_NSIDE);
  const double fwhm = 6.0 * std::sqrt(pi / 3) / s.nside(), sig = fwhm / std::sqrt(8 * std::log(2.0));
  std::vector<int> list;
  base.query_disc(pointing(centre), 2.5 * fwhm, list);
  std::array<double, 3> sum{};
  double w = 0.0;
  for (const int p : list) {
    const double d = std::acos(std::min(1.0, dotprod(base.pix2vec(p), centre)));
    const double b = std::exp(-d * d / (2 * sig * sig));
    for (int c = 0; c < 3; ++c) sum[c] += b * s.stokes(pisco::StokesIndex(c))[std::size_t(p)];
    w += b;
  }
  if (unit)
    for (double& x : sum) x /= w;
  return sum;
}

// Beam centres within `within` of both turned poles (+-1, 0, 0), the first on each.
std::vector<vec3> centres(double within, int count) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<vec3> out;
  for (int k = 0; k < count; ++k) {
    const double a = k < 2 ? 0.0 : within * std::sqrt(u(rng)), ph = 2 * pi * u(rng), sign = k % 2 ? -1.0 : 1.0;
    out.emplace_back(sign * std::cos(a), std::sin(a) * std::cos(ph), std::sin(a) * std::sin(ph));
  }
  return out;
}

// The copy's band in a whole sky (zeros elsewhere).
pisco::Sky whole(const pisco::detail::SkyBand& band) {
  pisco::Sky sky(band.nside);
  for (int c = 0; c < 4; ++c)
    std::copy(band.maps[std::size_t(c)].begin(), band.maps[std::size_t(c)].end(),
              sky.stokes(pisco::StokesIndex(c)).begin() + std::ptrdiff_t(band.first));
  return sky;
}

// The worst error of the smoothed copy against the smoothed reference, relative to the smoothed
// reference's RMS (I about its mean, and |P|).
double smoothed_error(const pisco::Sky& copy, const pisco::Sky& ref, double within) {
  std::vector<std::array<double, 3>> r, c;
  for (const vec3& x : centres(within, 80)) {
    r.push_back(smoothed(ref, x));
    c.push_back(smoothed(copy, x));
  }
  double mean = 0.0, vi = 0.0, vp = 0.0, worst = 0.0;
  for (const auto& x : r) mean += x[0] / double(r.size());
  for (const auto& x : r) {
    vi += (x[0] - mean) * (x[0] - mean) / double(r.size());
    vp += (x[1] * x[1] + x[2] * x[2]) / double(r.size());
  }
  for (std::size_t k = 0; k < r.size(); ++k) {
    worst = std::max(worst, std::abs(c[k][0] - r[k][0]) / std::sqrt(vi));
    worst = std::max(worst, std::hypot(c[k][1] - r[k][1], c[k][2] - r[k][2]) / std::sqrt(vp));
  }
  return worst;
}

TEST(PolarCopy, MatchesTheTurnedSkyAsABeamSeesIt) {
  const int nside = 64;
  const double fwhm = 6.0 * std::sqrt(pi / 3) / nside, reach = 25.0 * pi / 180, within = reach - 2.5 * fwhm;
  for (const int lmax : {nside / 2, nside, 3 * nside / 2, 2 * nside, 3 * nside - 1})
    for (const bool monopole : {false, true}) {
      const Alms a = random_alms(lmax, 11, monopole);
      Alms turned = a;
      rotate_alm(turned.t, turned.e, turned.b, 0.0, pi / 2, 0.0);  // S'(R p) = S(p), R 90 deg about y
      const pisco::Sky copy = whole(pisco::detail::polar_sky(maps(a, nside), false, reach));
      const double e = smoothed_error(copy, maps(turned, nside), within);
      std::printf("band limit %3d%s: worst %.1e of the smoothed RMS\n", lmax, monopole ? ", monopole and dipole" : "", e);
      // Measured 1.5e-5 to 5.4e-5 at every band limit up to 3 NSIDE - 1 (docs/physics.md, "The
      // quadrature"); the rings' interpolation alone was at 1.9e-3 for 3 NSIDE - 1.
      EXPECT_LE(e, 1e-4) << "band limit " << lmax;
    }
}

// A compact source near each pole, band-limited as the sky is (a Gaussian of 1.5 pixels FWHM to
// 3 NSIDE - 1), 2 and 5 deg from the pole: the smoothed copy against the turned source's exact
// smoothing, at beam centres along the meridian through it and across the pole, relative to the
// smoothed peak. (One bright pixel is not band-limited: near a pole a harmonic code's least-squares
// a_lm and the pixel taken as a point differ by 2e-2 of the peak; docs/validation.md, "L".)
TEST(PolarCopy, ACompactSourceNearAPole) {
  const int nside = 128, lmax = 3 * nside - 1;
  const double px = std::sqrt(pi / 3) / nside, s_src = 1.5 * px / std::sqrt(8 * std::log(2.0));
  for (const double colatitude : {2.0, 5.0})
    for (const int sign : {1, -1}) {
      // At the north pole (m = 0 only), then turned to its place: colatitude, longitude 0.3 (or the
      // south's colatitude).
      Alms a{{lmax, lmax}, {lmax, lmax}, {lmax, lmax}};
      a.t.SetToZero();
      a.e.SetToZero();
      a.b.SetToZero();
      for (int l = 0; l <= lmax; ++l) a.t(l, 0) = std::sqrt((2 * l + 1) / (4 * pi)) * std::exp(-0.5 * l * (l + 1) * s_src * s_src);
      const double theta = sign > 0 ? colatitude * pi / 180 : pi - colatitude * pi / 180;
      rotate_alm(a.t, a.e, a.b, 0.0, theta, 0.3);
      Alms turned = a;
      rotate_alm(turned.t, turned.e, turned.b, 0.0, pi / 2, 0.0);
      const pisco::Sky sky = maps(a, nside), ref = maps(turned, nside);
      const pisco::Sky copy = whole(pisco::detail::polar_sky(sky, false, 12.0 * pi / 180));
      double worst = 0.0, peak = 0.0;
      for (double t = -colatitude - 2.0; t <= colatitude + 2.0; t += 0.25) {
        const double th = std::abs(t) * pi / 180, ph = t < 0 ? 0.3 + pi : 0.3;
        const vec3 n(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), sign * std::cos(th));
        const vec3 c(n.z, n.y, -n.x);  // where R puts it
        const double want = smoothed(ref, c)[0];
        peak = std::max(peak, std::abs(want));
        worst = std::max(worst, std::abs(smoothed(copy, c)[0] - want));
      }
      std::printf("a compact source %.0f deg from the %s pole: worst %.1e of its smoothed peak\n", colatitude,
                  sign > 0 ? "north" : "south", worst / peak);
      EXPECT_LE(worst, 1e-4 * peak);
    }
}

// The dot-product test, within the fit's zone (NSIDE 16) and beyond it, where the rings' interpolation
// takes the copy's pixels (a reach of 80 rings at NSIDE 64).
TEST(PolarCopy, ItsTransposeIsExact) {
  for (const auto& [nside, reach_deg] : {std::pair{16, 10.0}, std::pair{16, 40.0}, std::pair{64, 60.0}}) {
    std::mt19937_64 rng(3);
    std::normal_distribution<double> g;
    pisco::Sky s(nside), m(nside);
    for (pisco::Sky* x : {&s, &m})
      for (auto map : {x->I(), x->Q(), x->U(), x->V()})
        for (double& v : map) v = g(rng);
    for (const bool weigh : {false, true}) {
      const double reach = reach_deg * pi / 180;
      const pisco::detail::SkyBand a = pisco::detail::polar_sky(s, weigh, reach);
      const pisco::Sky b = pisco::detail::polar_sky_adjoint(pisco::detail::band_of(m, a.first, a.size()), weigh, reach);
      double lhs = 0.0, rhs = 0.0, scale = 0.0;
      for (int c = 0; c < 4; ++c) {
        const auto k = pisco::StokesIndex(c);
        for (std::size_t p = a.first; p < a.first + a.size(); ++p) {
          lhs += a.value(c, p) * m.stokes(k)[p];
          scale += std::abs(a.value(c, p) * m.stokes(k)[p]);
        }
        for (std::size_t p = 0; p < s.npix(); ++p) rhs += s.stokes(k)[p] * b.stokes(k)[p];
      }
      EXPECT_NEAR(lhs, rhs, 1e-13 * scale) << "NSIDE " << nside << ", " << reach_deg << " deg, " << (weigh ? "weighted" : "unweighted");
    }
  }
}

TEST(PolarCopy, TheSameBitsOnAnyNumberOfThreads) {
  const pisco::Sky sky = maps(random_alms(96, 2, true), 64);
  const pisco::detail::SkyBand one = pisco::detail::polar_sky(sky, true, 0.3, 1),
                               three = pisco::detail::polar_sky(sky, true, 0.3, 3);
  ASSERT_EQ(one.first, three.first);
  for (int c = 0; c < 4; ++c) ASSERT_EQ(one.maps[std::size_t(c)], three.maps[std::size_t(c)]) << "Stokes " << c;
}

// The band holds every pixel within reach of both turned poles, in whole rings, from a multiple of 64,
// and about sin(reach) of the sky: the memory the backends add for it.
TEST(PolarCopy, ItsBandHoldsTheCapsInWholeRings) {
  for (const int nside : {16, 64, 256, 2048})
    for (const double reach_deg : {6.0, 12.0, 25.0, 60.0}) {
      const double reach = reach_deg * pi / 180;
      if (!pisco::detail::polar_copy_fits(nside, reach)) continue;
      const Healpix_Base base(nside, RING, SET_NSIDE);
      const auto [first, count] = pisco::detail::polar_band(nside, reach);
      EXPECT_EQ(first % 64, 0u);
      ASSERT_LE(first + count, std::size_t(base.Npix()));
      for (const double x : {1.0, -1.0}) {
        rangeset<int> set;
        base.query_disc(pointing(vec3(x, 0.0, 0.0)), reach, set);
        EXPECT_GE(std::size_t(set.ivbegin(0)), first);
        EXPECT_LE(std::size_t(set.ivend(set.nranges() - 1)), first + count);
      }
      // Its last pixel ends a ring.
      int start = 0, n = 0;
      double theta = 0.0;
      bool shifted = false;
      base.get_ring_info2(base.pix2ring(int(first + count - 1)), start, n, theta, shifted);
      EXPECT_EQ(std::size_t(start + n), first + count);
      const double fraction = double(count) / double(base.Npix());
      std::printf("NSIDE %4d, reach %4.1f deg: the band is %.3f of the sky (sin reach %.3f)\n", nside, reach_deg,
                  fraction, std::sin(reach));
      EXPECT_LE(fraction, std::sin(reach) + 8.0 / nside + 64.0 / double(base.Npix()));
    }
}

TEST(PolarCopy, RefusesAReachItCannotHold) {
  const pisco::Sky sky(4);
  EXPECT_THROW(pisco::detail::polar_sky(sky, false, 0.2), pisco::Error);  // NSIDE 4 has 15 rings
  EXPECT_THROW(pisco::detail::polar_sky(pisco::Sky(64), false, 89.0 * pi / 180), pisco::Error);
  EXPECT_FALSE(pisco::detail::polar_copy_fits(4, 0.2));
  EXPECT_TRUE(pisco::detail::polar_copy_fits(64, 0.2));
}

}  // namespace

