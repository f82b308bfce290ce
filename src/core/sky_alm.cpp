#include "core/sky_alm.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <span>

#include <alm_healpix_tools.h>
#include <healpix_map.h>

namespace pisco::detail {
namespace {
Healpix_Map<double> healpix_map(std::span<const double> v, int nside) {
  Healpix_Map<double> m(nside, RING, SET_NSIDE);
  std::copy(v.begin(), v.end(), &m[0]);
  return m;
}

void copy_map(const Healpix_Map<double>& m, std::span<double> out) { std::copy(&m[0], &m[0] + m.Npix(), out.begin()); }

// map2alm's quadrature: unit ring weights (one per ring of the northern half and the equator) and
// `iterations` Jacobi iterations.
struct Quadrature {
  arr<double> weight;
  int iterations = 0;
};

Quadrature map2alm_quadrature(int nside, int iterations) {
  return Quadrature{arr<double>(static_cast<tsize>(2 * nside), 1.0), iterations};
}
}  // namespace

std::filesystem::path healpy_data_dir() {
  const char* env = std::getenv("PISCO_HEALPY_DATA_DIR");
  return env && *env ? std::filesystem::path(env) : std::filesystem::path(PISCO_HEALPY_DATA_DIR);
}

SkyAlm sky_alm(const SkyView& sky, int lmax, int iterations) {
  const int nside = sky.nside();
  const Quadrature q = map2alm_quadrature(nside, iterations);
  SkyAlm a{{lmax, lmax}, {lmax, lmax}, {lmax, lmax}, {lmax, lmax}, false};
  map2alm_pol_iter(healpix_map(sky.I(), nside), healpix_map(sky.Q(), nside), healpix_map(sky.U(), nside), a.t, a.e,
                   a.b, q.iterations, q.weight);
  a.has_v = std::any_of(sky.V().begin(), sky.V().end(), [](double x) { return x != 0.0; });
  if (a.has_v) map2alm_iter(healpix_map(sky.V(), nside), a.v, q.iterations, q.weight);
  return a;
}

Sky sky_from_alm(const SkyAlm& a, int nside, const std::string& units) {
  Healpix_Map<double> t(nside, RING, SET_NSIDE), q(nside, RING, SET_NSIDE), u(nside, RING, SET_NSIDE);
  alm2map_pol(a.t, a.e, a.b, t, q, u);
  Sky out(nside, units);
  copy_map(t, out.I());
  copy_map(q, out.Q());
  copy_map(u, out.U());
  if (a.has_v) {
    Healpix_Map<double> v(nside, RING, SET_NSIDE);
    alm2map(a.v, v);
    copy_map(v, out.V());
  }
  return out;
}

namespace {
using AlmD = Alm<xcomplex<double>>;

// D: each pixel times its ring's weight and 4 pi / Npix (map2alm's quadrature).
void weigh_quadrature(Healpix_Map<double>& m, const arr<double>& weight) {
  const int nside = m.Nside();
  const double area = 4.0 * 3.14159265358979323846 / double(m.Npix());
  for (int p = 0; p < m.Npix(); ++p) {
    const int ring = m.pix2ring(p);
    const int r = ring <= 2 * nside ? ring - 1 : 4 * nside - ring - 1;
    m[p] *= weight[static_cast<tsize>(r)] * area;
  }
}

void axpy(AlmD& y, double a, const AlmD& x) {
  for (int m = 0; m <= y.Mmax(); ++m)
    for (int l = m; l <= y.Lmax(); ++l) y(l, m) += a * x(l, m);
}
}  // namespace

SkyAlm sky_from_alm_adjoint(const SkyView& maps, int lmax) {
  const int nside = maps.nside();
  SkyAlm a{{lmax, lmax}, {lmax, lmax}, {lmax, lmax}, {lmax, lmax}, false};
  alm2map_pol_adjoint(healpix_map(maps.I(), nside), healpix_map(maps.Q(), nside), healpix_map(maps.U(), nside), a.t,
                      a.e, a.b);
  a.has_v = std::any_of(maps.V().begin(), maps.V().end(), [](double x) { return x != 0.0; });
  if (a.has_v)
    alm2map_adjoint(healpix_map(maps.V(), nside), a.v);
  else
    a.v.SetToZero();
  return a;
}

Sky sky_alm_adjoint(const SkyAlm& b, int nside, int iterations, const std::string& units) {
  const Quadrature q = map2alm_quadrature(nside, iterations);
  const arr<double>& weight = q.weight;
  const int lmax = b.t.Lmax();
  // s = sum_j (1 - Y^T D Y)^j b, term by term: t <- t - Y^T D Y t.
  SkyAlm t = b, s = b;
  Healpix_Map<double> mt(nside, RING, SET_NSIDE), mq(nside, RING, SET_NSIDE), mu(nside, RING, SET_NSIDE),
      mv(nside, RING, SET_NSIDE);
  // V's transforms only where its a_lm are not all zero (its maps are zero otherwise).
  const bool v = b.has_v;
  for (int j = 0; j < q.iterations; ++j) {
    alm2map_pol(t.t, t.e, t.b, mt, mq, mu);
    for (Healpix_Map<double>* m : {&mt, &mq, &mu}) weigh_quadrature(*m, weight);
    SkyAlm y{{lmax, lmax}, {lmax, lmax}, {lmax, lmax}, {lmax, lmax}, v};
    alm2map_pol_adjoint(mt, mq, mu, y.t, y.e, y.b);
    axpy(t.t, -1.0, y.t);
    axpy(t.e, -1.0, y.e);
    axpy(t.b, -1.0, y.b);
    axpy(s.t, 1.0, t.t);
    axpy(s.e, 1.0, t.e);
    axpy(s.b, 1.0, t.b);
    if (v) {
      alm2map(t.v, mv);
      weigh_quadrature(mv, weight);
      alm2map_adjoint(mv, y.v);
      axpy(t.v, -1.0, y.v);
      axpy(s.v, 1.0, t.v);
    }
  }
  // D Y s.
  alm2map_pol(s.t, s.e, s.b, mt, mq, mu);
  for (Healpix_Map<double>* m : {&mt, &mq, &mu}) weigh_quadrature(*m, weight);
  Sky out(nside, units);
  copy_map(mt, out.I());
  copy_map(mq, out.Q());
  copy_map(mu, out.U());
  if (v) {
    alm2map(s.v, mv);
    weigh_quadrature(mv, weight);
    copy_map(mv, out.V());
  }
  return out;
}

}  // namespace pisco::detail
