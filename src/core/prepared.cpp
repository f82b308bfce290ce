#include "core/prepared.hpp"

#include <cmath>
#include <algorithm>
#include <limits>
#include <numbers>
#include <thread>
#include <string>

#include <healpix_base.h>
#include <vec3.h>

#include "kernel/grid_curvature.hpp"
#include "core/text.hpp"
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

double float32_monopole(const SkyView& sky) {
  const std::size_t npix = sky.npix();
  if (npix == 0) return 0.0;
  const auto& I = sky.I();
  double mean = 0.0;
  for (std::size_t i = 0; i < npix; ++i) mean += I[i];
  mean /= double(npix);
  double var = 0.0;
  for (std::size_t i = 0; i < npix; ++i) {
    const double d = I[i] - mean;
    var += d * d;
  }
  const double rms = std::sqrt(var / double(npix));
  // Taken out only where it dominates: a map whose mean is near its spread (a ground below a horizon,
  // a sky of bright regions and empty ones) would otherwise carry -I0 in float32 where it holds zeros,
  // an error of 1e-7 I0 in every disc (docs/vulkan.md, "Precision").
  return std::abs(mean) > 10.0 * rms ? mean : 0.0;
}

std::vector<float> float32_weights(const PreparedDetector& d) {
  double largest = 0.0;
  for (const double w : d.weights) largest = std::max(largest, std::abs(w));
  const double cutoff = std::max(std::ldexp(largest, -64), double(std::numeric_limits<float>::min()));
  std::vector<float> w32(d.weights.size());
  for (std::size_t k = 0; k < w32.size(); ++k) w32[k] = std::abs(d.weights[k]) < cutoff ? 0.0f : float(d.weights[k]);
  return w32;
}

int weight_columns(const PreparedDetector& d) {
  for (std::size_t k = 0; k + 3 < d.weights.size(); k += 4)
    if (d.weights[k + 2] != 0.0 || d.weights[k + 3] != 0.0) return 4;
  return 2;
}

struct PixelVectors::Impl {
  Healpix_Base base;
};

PixelVectors::PixelVectors(int nside) : impl_(std::make_unique<Impl>(Impl{Healpix_Base(nside, RING, SET_NSIDE)})) {}
PixelVectors::~PixelVectors() = default;

void PixelVectors::get(std::size_t first, std::size_t count, double* xyz, unsigned threads) const {
  auto run = [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const vec3 k = impl_->base.pix2vec(static_cast<int>(first + i));
      xyz[3 * i] = k.x;
      xyz[3 * i + 1] = k.y;
      xyz[3 * i + 2] = k.z;
    }
  };
  threads = std::max(1u, std::min<unsigned>(threads, unsigned(count / 4096 + 1)));
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(run, count * t / threads, count * (t + 1) / threads);
  run(0, count / threads);
  for (auto& t : pool) t.join();
}

PreparedSky prepare_sky(const SkyView& sky) {
  sky.check_finite("sky");
  PreparedSky p;
  p.nside = sky.nside();
  p.pixel_area = sky.pixel_area();
  p.npix = sky.npix();
  p.rings = make_ring_table(sky.nside());
  return p;
}

std::vector<double> reference_pixels(int nside, std::size_t first_pixel,
                                     const std::array<std::span<const double>, 4>& maps, unsigned threads) {
  const std::size_t count = maps[0].size();
  std::vector<double> pixels(count * 8);
  const PixelVectors vectors(nside);
  constexpr std::size_t piece = std::size_t(1) << 16;
  std::vector<double> xyz(3 * piece);
  for (std::size_t first = 0; first < count; first += piece) {
    const std::size_t n = std::min(piece, count - first);
    vectors.get(first_pixel + first, n, xyz.data(), threads);
    for (std::size_t j = 0; j < n; ++j) {
      double* px = &pixels[(first + j) * 8];
      px[0] = xyz[3 * j];
      px[1] = xyz[3 * j + 1];
      px[2] = xyz[3 * j + 2];
      px[3] = 0.0;
      for (int c = 0; c < 4; ++c) px[4 + c] = maps[std::size_t(c)].empty() ? 0.0 : maps[std::size_t(c)][first + j];
    }
  }
  return pixels;
}

std::vector<double> reference_pixels(const SkyView& sky, unsigned threads) {
  return reference_pixels(sky.nside(), 0, {sky.I(), sky.Q(), sky.U(), sky.V()}, threads);
}

namespace {

// A detector's weights w(col) = sum_r row[r] B_r,col(node) over the beam's rows r, with the grid's
// edge records appended (src/kernel/grid_curvature.hpp); per-sample normalization's (Omega_pix B_TT /
// Omega~, 0, 0, 0) likewise. `d` is the detector as check_focal_plane() has accepted it.
PreparedDetector prepare(const Detector& d, const Beamsor& beam, double pixel_area, Normalization normalization,
                         const double (&row)[4]) {
  PreparedDetector p;
  const Quat& o = d.offset;
  p.offset = make_offset({o.x, o.y, o.z, o.w});  // rotation_matrix() is exact for any norm
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
  p.weights.assign(nodes * 4, 0.0);
  for (int col = 0; col < 4; ++col)
    for (int r = 0; r < 4; ++r) {
      const auto b = beam.element(r, col);
      if (row[r] == 0.0 || b.empty()) continue;
      for (std::size_t k = 0; k < nodes; ++k) p.weights[k * 4 + col] += row[r] * b[k];
    }
  if (normalization == Normalization::per_sample) {
    p.norm_weights.assign(nodes * 4, 0.0);
    const auto btt = beam.element(0, 0);
    for (std::size_t k = 0; k < nodes; ++k) p.norm_weights[k * 4] = pixel_area / beam.omega_tilde() * btt[k];
  }
  if (!p.radial) {
    append_edge_curvature(p.weights, p.grid_n, 4);
    if (!p.norm_weights.empty()) append_edge_curvature(p.norm_weights, p.grid_n, 4);
  }
  p.d0[0] = d.gain / 2 * (1 + d.epsilon);
  p.d0[1] = d.gain / 2 * (1 - d.epsilon);
  if (d.hwp) {
    p.plate = d.hwp->placement == HwpPlacement::aperture ? PreparedDetector::Plate::aperture
                                                          : PreparedDetector::Plate::detector;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) p.plate_mueller[i][j] = d.hwp->mueller[i][j];
    p.plate_gamma = d.hwp->gamma;
  }
  return p;
}

}  // namespace

// The detector as check_focal_plane() has accepted it: rows T and Q, s/2 (1 + eps) and s/2 (1 - eps).
PreparedDetector prepare_detector(const Detector& d, const Beamsor& beam, double pixel_area,
                                  Normalization normalization) {
  const double scale = pixel_area / beam.omega_tilde() * d.gain / 2;
  const double row[4] = {scale * (1 + d.epsilon), scale * (1 - d.epsilon), 0.0, 0.0};
  return prepare(d, beam, pixel_area, normalization, row);
}

PreparedDetector prepare_row_detector(const Detector& d, const Beamsor& beam, double pixel_area,
                                      Normalization normalization, int row) {
  Detector plain = d;
  plain.hwp.reset();
  double rows[4] = {0.0, 0.0, 0.0, 0.0};
  rows[row] = pixel_area / beam.omega_tilde();
  return prepare(plain, beam, pixel_area, normalization, rows);
}

EngineInputs prepare_inputs(const SkyView& sky, const std::vector<Beamsor>& beams,
                            const FocalPlane& focal_plane, Normalization normalization) {
  // The focal plane is the Engine's to check (check_focal_plane), before the sky's set-up.
  EngineInputs in;
  in.normalization = normalization;
  in.sky = prepare_sky(sky);
  // A disc narrower than the sky's largest pixel radius holds no pixel centre wherever it falls between
  // them, and its sample would be 0: refused, naming the detector.
  const double largest = T_Healpix_Base<int>(sky.nside(), RING, SET_NSIDE).max_pixrad();
  for (const Detector& d : focal_plane.detectors())
    if (beams[d.beam].rho_max() < largest)
      throw Error("detector '" + d.name + "': its beam's rho_max, " + degrees_text(beams[d.beam].rho_max()) +
                  ", is below the largest pixel radius of the sky (NSIDE " + std::to_string(sky.nside()) + "), " +
                  degrees_text(largest) + ": a disc between pixel centres would hold none, and its sample would be 0; "
                  "widen rho_max or give a finer sky");
  for (const Detector& d : focal_plane.detectors()) {
    in.detectors.push_back(prepare_detector(d, beams[d.beam], in.sky.pixel_area, normalization));
    in.detectors.back().owner = in.detectors.size() - 1;
  }
  // The row detectors of plates between the optics and the detector, after the focal plane's.
  for (std::size_t i = 0; i < focal_plane.size(); ++i) {
    if (in.detectors[i].plate != PreparedDetector::Plate::detector) continue;
    const Detector& d = focal_plane[i];
    for (int r = 0; r < 4; ++r) {
      in.detectors[i].rows[r] = in.detectors.size();
      in.detectors.push_back(prepare_row_detector(d, beams[d.beam], in.sky.pixel_area, normalization, r));
      in.detectors.back().owner = i;
    }
  }
  return in;
}

}  // namespace pisco::detail
