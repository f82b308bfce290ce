#include "core/prepared.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include <healpix_base.h>
#include <vec3.h>

#include "pisco/error.hpp"

namespace pisco::detail {

std::vector<RingEntry> make_ring_table(int nside) {
  const Healpix_Base base(nside, RING, SET_NSIDE);
  std::vector<RingEntry> rings(static_cast<std::size_t>(4) * nside - 1);
  for (int r = 1; r <= 4 * nside - 1; ++r) {
    int first = 0, count = 0;
    bool shifted = false;
    base.get_ring_info_small(r, first, count, shifted);
    rings[r - 1] = {ring_z(nside, r), static_cast<std::uint32_t>(first),
                    static_cast<std::uint32_t>(count), shifted ? 1u : 0u, 0u};
  }
  return rings;
}

double float32_monopole(const PreparedSky& sky) {
  const std::size_t npix = sky.pixels.size() / 8;
  if (npix == 0) return 0.0;
  double mean = 0.0;
  for (std::size_t i = 0; i < npix; ++i) mean += sky.pixels[i * 8 + 4];
  mean /= double(npix);
  double var = 0.0;
  for (std::size_t i = 0; i < npix; ++i) {
    const double d = sky.pixels[i * 8 + 4] - mean;
    var += d * d;
  }
  const double rms = std::sqrt(var / double(npix));
  return std::abs(mean) > 0.1 * rms ? mean : 0.0;
}

PreparedSky prepare_sky(const Sky& sky) {
  sky.check_finite("sky");
  PreparedSky p;
  p.nside = sky.nside();
  p.pixel_area = sky.pixel_area();
  const Healpix_Base base(sky.nside(), RING, SET_NSIDE);
  const std::size_t npix = sky.npix();
  p.pixels.resize(npix * 8);
  for (std::size_t i = 0; i < npix; ++i) {
    const vec3 k = base.pix2vec(static_cast<int>(i));
    double* px = &p.pixels[i * 8];
    px[0] = k.x;
    px[1] = k.y;
    px[2] = k.z;
    px[3] = 0.0;
    px[4] = sky.I()[i];
    px[5] = sky.Q()[i];
    px[6] = sky.U()[i];
    px[7] = sky.V()[i];
  }
  p.rings = make_ring_table(sky.nside());
  return p;
}

PreparedDetector prepare_detector(const Detector& d, const Beamsor& beam, double pixel_area,
                                  Normalization normalization) {
  if (!std::isfinite(d.zeta) || !std::isfinite(d.epsilon) || !std::isfinite(d.gain))
    throw Error("detector '" + d.name + "': zeta, epsilon and gain must be finite");
  PreparedDetector p;
  p.cos_zeta = std::cos(d.zeta);
  p.sin_zeta = std::sin(d.zeta);
  p.rho_max = beam.rho_max();
  p.cos_rho_max = std::cos(beam.rho_max());
  p.radial = beam.is_radial();
  p.grid_n = beam.grid_size();
  p.grid_a = beam.grid_half_width();
  p.grid_inv_step = 1.0 / beam.grid_step();
  const std::size_t nodes = p.radial ? static_cast<std::size_t>(p.grid_n)
                                     : static_cast<std::size_t>(p.grid_n) * p.grid_n;
  const double scale = pixel_area / beam.omega_tilde() * d.gain / 2;
  const double row_t = scale * (1 + d.epsilon), row_q = scale * (1 - d.epsilon);
  p.weights.assign(nodes * 4, 0.0);
  for (int col = 0; col < 4; ++col) {
    const auto bt = beam.element(0, col);
    const auto bq = beam.element(1, col);
    for (std::size_t k = 0; k < nodes; ++k) {
      double w = 0.0;
      if (!bt.empty()) w += row_t * bt[k];
      if (!bq.empty()) w += row_q * bq[k];
      p.weights[k * 4 + col] = w;
    }
  }
  if (normalization == Normalization::per_sample) {
    p.norm_weights.assign(nodes * 4, 0.0);
    const auto btt = beam.element(0, 0);
    for (std::size_t k = 0; k < nodes; ++k) p.norm_weights[k * 4] = pixel_area / beam.omega_tilde() * btt[k];
  }
  return p;
}

EngineInputs prepare_inputs(const Sky& sky, const std::vector<Beamsor>& beams,
                            const FocalPlane& focal_plane, Normalization normalization) {
  if (focal_plane.size() == 0) throw Error("focal plane: no detectors");
  EngineInputs in;
  in.normalization = normalization;
  in.sky = prepare_sky(sky);
  for (const Detector& d : focal_plane.detectors()) {
    if (d.beam >= beams.size())
      throw Error("detector '" + d.name + "': beam index " + std::to_string(d.beam) +
                  " but only " + std::to_string(beams.size()) + " beamsors were given");
    in.detectors.push_back(prepare_detector(d, beams[d.beam], in.sky.pixel_area, normalization));
  }
  return in;
}

}  // namespace pisco::detail
