// Right everywhere on the sphere (docs/physics.md, "The quadrature"; docs/validation.md, "L"): the TOD
// of band-limited skies, random polarized ones with and without a monopole and dipole and two point
// sources near the poles, against their exact harmonic smoothing evaluated at each sample, at
// colatitudes 0, 0.3, 1, 3 and 30 deg from both poles, on the rings where the polar caps meet the belt
// and across phi = 0, on every backend present. The plain pixel sum fails the same bars at the poles,
// and reads one bright pixel as a point at every colatitude, as the band-limited reading cannot.
#include <gtest/gtest.h>

#include <alm.h>
#include <alm_healpix_tools.h>
#include <healpix_base.h>
#include <healpix_map.h>
#include <xcomplex.h>

#include <cmath>
#include <cstdlib>
#include <complex>
#include <cstdio>
#include <numbers>
#include <random>

#include "backend_fixtures.hpp"
#include "support.hpp"
#include "pisco/beam_files.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/units.hpp"

namespace {

using pisco::deg;
constexpr double pi = std::numbers::pi;

// The exact transfer functions of a circular Gaussian truncated at rho_max, normalized by its cap
// integral: T by the Legendre polynomials, Q and U by d^l_22, since a co-polar axis carried along
// each great circle from the beam's axis (Ludwig's third definition) is parallel transport.
struct Windows {
  std::vector<double> t, p;
};

Windows gaussian_windows(double fwhm, double rho_max, int lmax) {
  const double s = fwhm / std::sqrt(8 * std::log(2.0));
  const int n = 40000;  // Simpson's rule on [0, rho_max]
  const double h = rho_max / n;
  Windows w{std::vector<double>(std::size_t(lmax) + 1, 0.0), std::vector<double>(std::size_t(lmax) + 1, 0.0)};
  double norm = 0.0;
  for (int i = 0; i <= n; ++i) {
    const double rho = i * h, x = std::cos(rho);
    const double f = (i == 0 || i == n ? 1.0 : i % 2 ? 4.0 : 2.0) * h / 3 * std::exp(-rho * rho / (2 * s * s)) * std::sin(rho);
    norm += f;
    double p0 = 1.0, p1 = x;
    w.t[0] += f;
    if (lmax >= 1) w.t[1] += f * x;
    for (int l = 1; l < lmax; ++l) {
      const double p2 = ((2 * l + 1) * x * p1 - l * p0) / (l + 1);
      p0 = p1;
      p1 = p2;
      w.t[std::size_t(l) + 1] += f * p1;
    }
    double d0 = 0.0, d1 = std::pow((1 + x) / 2, 2);  // d^1_22 = 0, d^2_22
    if (lmax >= 2) w.p[2] += f * d1;
    for (int l = 2; l < lmax; ++l) {
      const double d2 = ((2 * l + 1) * (l * (l + 1.0) * x - 4) * d1 - (l + 1) * (l * l - 4.0) * d0) /
                        (l * ((l + 1.0) * (l + 1) - 4));
      d0 = d1;
      d1 = d2;
      w.p[std::size_t(l) + 1] += f * d1;
    }
  }
  for (int l = 0; l <= lmax; ++l) {
    w.t[std::size_t(l)] /= norm;
    w.p[std::size_t(l)] /= norm;
  }
  return w;
}

// A sky given by its a_lm (healpy's layout), its maps, and its exact smoothing at points.
struct HarmonicSky {
  pisco::HarmonicBeam alm;  // T, E, B up to lmax
  pisco::Sky sky;
};

HarmonicSky make_sky(int nside, int lmax, std::uint64_t seed, bool monopole_dipole, bool point_source) {
  pisco::HarmonicBeam a;
  a.lmax = a.mmax = lmax;
  const std::size_t n = pisco::HarmonicBeam::size(lmax, lmax);
  a.t.assign(n, 0.0);
  a.e.assign(n, 0.0);
  a.b.assign(n, 0.0);
  std::mt19937_64 g(seed);
  std::normal_distribution<double> z(0, 1);
  for (int m = 0; m <= lmax; ++m)
    for (int l = std::max(m, 1); l <= lmax; ++l) {
      const std::size_t i = pisco::HarmonicBeam::index(lmax, l, m);
      auto draw = [&] { return m == 0 ? std::complex<double>(z(g), 0.0) : std::complex<double>(z(g), z(g)) / std::sqrt(2.0); };
      const double c = 1.0 / (1.0 + std::pow(l / 30.0, 2));
      if (point_source) continue;
      a.t[i] = std::sqrt(c) * draw();
      if (l >= 2) {
        a.e[i] = std::sqrt(0.3 * c) * draw();
        a.b[i] = std::sqrt(0.1 * c) * draw();
      }
    }
  if (point_source) {
    // Two sources, 0.5 deg from the north pole and 1.2 deg from the south one: a_lm = Y*_lm of their
    // directions with a Gaussian taper, through HEALPix's own synthesis of one point.
    for (const auto& [theta, phi, amp] : {std::tuple{0.5 * deg, 1.0, 1.0}, std::tuple{pi - 1.2 * deg, 4.0, -0.7}})
      for (int m = 0; m <= lmax; ++m) {
        // Y_lm(theta, 0) by the normalized associated Legendre recursion.
        const double x = std::cos(theta), sx = std::sin(theta);
        double pmm = 1.0 / std::sqrt(4 * pi);
        for (int k = 1; k <= m; ++k) pmm *= -sx * std::sqrt((2 * k + 1.0) / (2 * k));
        double p0 = 0.0, p1 = pmm;
        for (int l = m; l <= lmax; ++l) {
          if (l > m) {
            const double al = std::sqrt((4.0 * l * l - 1) / (double(l) * l - double(m) * m));
            const double bl = std::sqrt(((l - 1.0) * (l - 1) - double(m) * m) / (4.0 * (l - 1) * (l - 1) - 1));
            const double p2 = al * (x * p1 - bl * p0);
            p0 = p1;
            p1 = p2;
          }
          const double taper = std::exp(-0.5 * std::pow(l / (1.2 * nside), 2));
          const std::complex<double> y = amp * taper * p1 * std::polar(1.0, -m * phi);
          a.t[pisco::HarmonicBeam::index(lmax, l, m)] += y;
          if (l >= 2) a.e[pisco::HarmonicBeam::index(lmax, l, m)] += 0.5 * y;
        }
      }
  }
  if (monopole_dipole) {
    a.t[0] = 100.0 * std::sqrt(4 * pi);
    a.t[pisco::HarmonicBeam::index(lmax, 1, 0)] = 3.0;
    a.t[pisco::HarmonicBeam::index(lmax, 1, 1)] = std::complex<double>(1.5, -0.8);
  }
  Alm<xcomplex<double>> t(lmax, lmax), e(lmax, lmax), b(lmax, lmax);
  for (int m = 0; m <= lmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const std::size_t i = pisco::HarmonicBeam::index(lmax, l, m);
      t(l, m) = xcomplex<double>(a.t[i].real(), a.t[i].imag());
      e(l, m) = xcomplex<double>(a.e[i].real(), a.e[i].imag());
      b(l, m) = xcomplex<double>(a.b[i].real(), a.b[i].imag());
    }
  Healpix_Map<double> mt(nside, RING, SET_NSIDE), mq(nside, RING, SET_NSIDE), mu(nside, RING, SET_NSIDE);
  alm2map_pol(t, e, b, mt, mq, mu);
  pisco::Sky sky(nside, "K_CMB");
  for (std::size_t p = 0; p < sky.npix(); ++p) {
    sky.I()[p] = mt[int(p)];
    sky.Q()[p] = mq[int(p)];
    sky.U()[p] = mu[int(p)];
  }
  return {a, sky};
}

// The ideal detector's exact TOD: 1/2 (I + Q cos 2 psi + U sin 2 psi) of the smoothed sky.
std::vector<double> exact_tod(const pisco::HarmonicBeam& sky, const Windows& w, const pisco::Pointing& p) {
  pisco::HarmonicBeam s = sky;
  for (int m = 0; m <= s.lmax; ++m)
    for (int l = m; l <= s.lmax; ++l) {
      const std::size_t i = pisco::HarmonicBeam::index(s.lmax, l, m);
      s.t[i] *= w.t[std::size_t(l)];
      s.e[i] *= w.p[std::size_t(l)];
      s.b[i] *= w.p[std::size_t(l)];
    }
  // stokes_at wants a beam's positive integral: 1 is added to a_00 here and its 1 / sqrt(4 pi) taken back.
  s.t[0] += 1.0;
  std::vector<double> d(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    auto v = s.stokes_at(p.theta[i], p.phi[i]);
    v[0] -= 1.0 / std::sqrt(4 * pi);
    // stokes_at gives Q and U in the beam frame's Ludwig-3 basis, turned by sigma = phi from HEALPix's.
    const std::complex<double> pol = std::complex<double>(v[1], v[2]) * std::polar(1.0, -2.0 * p.phi[i]);
    v[1] = pol.real();
    v[2] = pol.imag();
    d[i] = 0.5 * (v[0] + v[1] * std::cos(2 * p.psi[i]) + v[2] * std::sin(2 * p.psi[i]));
  }
  return d;
}

// The poles, and the rings where the polar caps meet the belt (z = +-2/3, 48.19 deg from the poles).
constexpr double colatitudes_deg[] = {0.0, 0.3, 1.0, 3.0, 30.0, 48.19, 90.0, 131.81, 150.0, 177.0, 179.0, 179.7, 180.0};
constexpr std::size_t per_colatitude = 12;

// Each colatitude at 12 longitudes, four of them straddling phi = 0, then random samples over the sphere.
pisco::Pointing pole_pointing(std::size_t random_samples) {
  std::mt19937_64 g(11);
  std::uniform_real_distribution<double> u(0, 1);
  pisco::Pointing p;
  for (const double c : colatitudes_deg)
    for (std::size_t k = 0; k < per_colatitude; ++k) {
      const double phi = k < 4 ? std::fmod(2 * pi + (k % 2 ? 1 : -1) * 1e-3 * double(k + 1) * deg, 2 * pi)
                               : 2 * pi * double(k - 4) / 8.0 + 0.3;
      p.push_back(c * deg, phi, 2 * pi * u(g) - pi);
    }
  for (std::size_t i = 0; i < random_samples; ++i) p.push_back(std::acos(2 * u(g) - 1), 2 * pi * u(g), 2 * pi * u(g) - pi);
  return p;
}

struct Errors {
  std::vector<double> worst;  // per colatitude, relative to the TOD's RMS
  double rms_random = 0.0;    // over the random samples, relative
  double rms_off_boundary = 0.0;  // the same beyond 5 deg of the rings where the caps meet the belt
};

Errors errors(const std::vector<double>& d, const std::vector<double>& ref, double scale, const pisco::Pointing& p) {
  Errors e;
  const std::size_t nc = std::size(colatitudes_deg);
  for (std::size_t c = 0; c < nc; ++c) {
    double w = 0.0;
    for (std::size_t k = 0; k < per_colatitude; ++k) {
      const std::size_t i = c * per_colatitude + k;
      w = std::max(w, std::abs(d[i] - ref[i]) / scale);
    }
    e.worst.push_back(w);
  }
  double s = 0.0, s_off = 0.0;
  std::size_t n_off = 0;
  const std::size_t first = nc * per_colatitude;
  for (std::size_t i = first; i < d.size(); ++i) {
    const double e2 = std::pow((d[i] - ref[i]) / scale, 2);
    s += e2;
    if (std::abs(std::abs(std::cos(p.theta[i])) - 2.0 / 3.0) > 0.07) {
      s_off += e2;
      ++n_off;
    }
  }
  e.rms_random = std::sqrt(s / double(d.size() - first));
  e.rms_off_boundary = std::sqrt(s_off / double(n_off));
  return e;
}

class Poles : public ::testing::TestWithParam<std::string> {};

TEST_P(Poles, BandLimitedSkiesMatchTheirExactSmoothingEverywhere) {
  const std::string backend = GetParam();
  const std::string why = pisco_test::backend_unavailable(backend);
  if (!why.empty()) GTEST_SKIP() << backend << ": " << why;
  const int nside = 128, lmax = 2 * nside;
  const double pixel = std::sqrt(pi / 3) / nside;
  pisco::FocalPlane fp;
  pisco::Detector det;
  det.name = "d";
  fp.add(det);
  const pisco::Pointing p = pole_pointing(backend == "cpu" ? 400 : 1000);
  struct Case {
    const char* name;
    bool monopole_dipole, point_source;
  };
  for (const double per_fwhm : {6.0, 10.0}) {
    const double fwhm = per_fwhm * pixel;
    pisco::BeamOptions bo;
    bo.rho_max = 2.5 * fwhm;
    const pisco::Beamsor beam = pisco::Beamsor::gaussian(fwhm, bo);
    const Windows w = gaussian_windows(fwhm, bo.rho_max, lmax);
    for (const Case c : {Case{"random polarized", false, false}, Case{"monopole + dipole + random", true, false},
                         Case{"two point sources", false, true}}) {
      const HarmonicSky hs = make_sky(nside, lmax, 7, c.monopole_dipole, c.point_source);
      const std::vector<double> ref = exact_tod(hs.alm, w, p);
      const double scale = pisco_test::rms_about_mean(ref);
      for (const pisco::Quadrature poles : {pisco::Quadrature::corrected, pisco::Quadrature::plain}) {
        if (poles == pisco::Quadrature::plain && (backend != "cpu" || per_fwhm != 6.0)) continue;
        pisco::EngineOptions o;
        o.backend = backend;
        o.quadrature = poles;
        pisco::Engine engine(hs.sky, {beam}, fp, o);
        std::vector<double> d(p.size());
        engine.convolve(0, p, d);
        const Errors e = errors(d, ref, scale, p);
        std::printf("%s, %s sky, NSIDE %d, %.0f pixels per FWHM, %s quadrature (%llu samples on the polar copy):\n  colatitude",
                    backend.c_str(), c.name, nside, per_fwhm, poles == pisco::Quadrature::corrected ? "corrected" : "plain",
                    static_cast<unsigned long long>(engine.polar_samples()));
        for (const double col : colatitudes_deg) std::printf(" %7.1f", col);
        std::printf("\n  worst     ");
        for (const double x : e.worst) std::printf(" %7.1e", x);
        std::printf("\n  RMS over %zu random samples: %.1e of the TOD's RMS (%.1e beyond 5 deg of the cap boundaries)\n",
                    p.size() - std::size(colatitudes_deg) * per_colatitude, e.rms_random, e.rms_off_boundary);
        if (poles == pisco::Quadrature::plain) {
          EXPECT_GT(e.worst[0], 1e-3) << "the plain sum's error at the pole, which the polar copy removes";
          continue;
        }
        for (std::size_t k = 0; k < e.worst.size(); ++k)
          EXPECT_LE(e.worst[k], 1e-4) << c.name << ", " << per_fwhm << " pixels per FWHM, colatitude " << colatitudes_deg[k];
        EXPECT_LE(e.rms_random, 2e-5) << c.name << ", " << per_fwhm << " pixels per FWHM";
        EXPECT_GT(engine.polar_samples(), 0u);
      }
    }
  }
}

// One bright pixel 2 deg from a pole and one at the equator (docs/physics.md, "The quadrature"): with
// quadrature = "plain" the pixel sum reads each pixel as a point, the same at every colatitude, so that
// a sample at a given offset from either pixel reads the same; the corrected quadrature reads the map
// as a band-limited sky, which near a pole is not the point (its polar copy's least-squares fit). No
// linear reading of a map gives both: a map is the sum of its pixels.
TEST(OnePixel, IsAPointAtEveryColatitudeWithThePlainQuadrature) {
  const int nside = 64;
  const Healpix_Base base(nside, RING, SET_NSIDE);
  const double fwhm = 6 * std::sqrt(pi / 3) / nside;
  pisco::BeamOptions bo;
  bo.rho_max = 2.5 * fwhm;
  const pisco::Beamsor beam = pisco::Beamsor::gaussian(fwhm, bo);
  pisco::FocalPlane fp;
  pisco::Detector det;
  det.name = "d";
  fp.add(det);
  const int near = int(base.ang2pix(pointing(2.0 * deg, 0.3))), far = int(base.ang2pix(pointing(pi / 2 + 0.01, 0.3)));
  pisco::Sky sky(nside);
  sky.I()[std::size_t(near)] = 1.0;
  sky.I()[std::size_t(far)] = 1.0;
  // Samples at 0 to 1.5 FWHM from each pixel's centre c, in three directions: c cos r + sin r (cos a
  // e_theta + sin a e_phi).
  pisco::Pointing p;
  for (const int pix : {near, far}) {
    const pointing c = base.pix2ang(pix);
    const vec3 n = c.to_vec3(), et(std::cos(c.theta) * std::cos(c.phi), std::cos(c.theta) * std::sin(c.phi), -std::sin(c.theta)),
               ep(-std::sin(c.phi), std::cos(c.phi), 0.0);
    for (const double r : {0.0, 0.3, 0.6, 1.0, 1.5})
      for (const double a : {0.0, 1.6, 3.5}) {
        const vec3 v = n * std::cos(r * fwhm) + (et * std::cos(a) + ep * std::sin(a)) * std::sin(r * fwhm);
        const pointing q(v);
        p.push_back(q.theta, q.phi, 0.7);
      }
  }
  const std::size_t half = p.size() / 2;
  for (const pisco::Quadrature quadrature : {pisco::Quadrature::plain, pisco::Quadrature::corrected}) {
    pisco::EngineOptions o;
    o.backend = "cpu";
    o.quadrature = quadrature;
    pisco::Engine engine(sky, {beam}, fp, o);
    std::vector<double> d(p.size());
    engine.convolve(0, p, d);
    const double peak = d[half];  // on the equator's pixel
    double worst = 0.0;
    for (std::size_t i = 0; i < half; ++i) worst = std::max(worst, std::abs(d[i] - d[half + i]));
    const bool plain = quadrature == pisco::Quadrature::plain;
    std::printf("%s quadrature: 2 deg from the pole against the equator, worst %.1e of the peak\n",
                plain ? "plain" : "corrected", worst / peak);
    ASSERT_GT(peak, 0.0);
    if (plain) EXPECT_LE(worst, 1e-9 * peak) << "a pixel read as a point is the same pixel everywhere";
    else EXPECT_GT(worst, 1e-3 * peak) << "the band-limited reading near a pole is not the point (docs/physics.md)";
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, Poles, ::testing::ValuesIn(pisco::Engine::backend_names()),
                         [](const auto& info) { return info.param; });

}  // namespace
