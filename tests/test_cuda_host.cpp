// The cuda backend without a GPU: chunk sizing, device choice, the monopole split, and the kernel's
// per-sample float32 arithmetic (src/cuda/sample.hpp, the functions convolve.cu runs) executed on the
// host with the warp emulated lane by lane, held to the precision contract of docs/validation.md, "B", against
// the float64 reference; likewise the adjoint's norm pass and fixed-point scatter. On a GPU, test_cuda checks the device itself against the same bars.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <iostream>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include <healpix_base.h>
#include <pointing.h>

#include "core/poles.hpp"
#include "core/prepared.hpp"
#include "cuda/chunk.hpp"
#include "cuda/device_choice.hpp"
#include "cuda/device_data.hpp"
#include "cuda/sample.hpp"
#include "gpu/fixed_point.hpp"
#include "pisco/engine.hpp"
#include "pisco/hwp.hpp"
#include "pisco/units.hpp"
#include "backend_fixtures.hpp"
#include "support.hpp"

namespace {

namespace pc = pisco::detail::cuda;
constexpr double pi = std::numbers::pi;
using pisco::deg;

TEST(CudaChunk, RequestedSizeIsKeptAndCapped) {
  EXPECT_EQ(pc::fit_chunk(7, 0), 7u);
  EXPECT_EQ(pc::fit_chunk(1, 1ull << 40), 1u);
  EXPECT_EQ(pc::fit_chunk(std::size_t(1) << 40, 1ull << 40), pc::max_chunk_samples);
}

TEST(CudaChunk, DefaultFitsHalfTheFreeMemory) {
  EXPECT_EQ(pc::fit_chunk(0, std::size_t(80) << 30), pc::default_chunk_samples);  // an H100: the default
  const std::size_t free_bytes = 1000 * pc::bytes_per_chunk_sample;
  EXPECT_EQ(pc::fit_chunk(0, free_bytes), 500u);
  EXPECT_LE(pc::fit_chunk(0, free_bytes) * pc::bytes_per_chunk_sample, free_bytes / 2);
  EXPECT_EQ(pc::fit_chunk(0, 0), 1u);
}

TEST(CudaDeviceChoice, AutoIndexAndName) {
  const std::vector<std::string> names{"NVIDIA H100 80GB HBM3", "NVIDIA A100-SXM4-40GB"};
  EXPECT_EQ(pc::choose_device(names, "auto"), 0);
  EXPECT_EQ(pc::choose_device(names, ""), 0);
  EXPECT_EQ(pc::choose_device(names, "1"), 1);
  EXPECT_EQ(pc::choose_device(names, "a100"), 1);
  EXPECT_EQ(pc::choose_device(names, "H100"), 0);
  EXPECT_EQ(pc::choose_device(names, "NVIDIA"), 0);  // the first match
}

TEST(CudaDeviceChoice, BadRequestsNameWhatWasAskedAndWhatExists) {
  const std::vector<std::string> names{"NVIDIA H100 80GB HBM3"};
  pisco_test::expect_error([&] { pc::choose_device(names, "99"); }, "99");
  pisco_test::expect_error([&] { pc::choose_device(names, "99"); }, "0: NVIDIA H100 80GB HBM3");
  pisco_test::expect_error([&] { pc::choose_device(names, "99999999999999999999"); }, "out of range");
  pisco_test::expect_error([&] { pc::choose_device(names, "no-such-device"); }, "no-such-device");
  pisco_test::expect_error([&] { pc::choose_device(names, "no-such-device"); }, "H100");
  pisco_test::expect_error([&] { pc::choose_device({}, "auto"); }, "no CUDA devices");
}

// ---- the kernel's arithmetic on the host ----

using pisco_test::cmb_like_sky;
using pisco_test::compare;
using pisco_test::random_pointing;
using pisco_test::Stats;

using pisco_test::Scene;

// The backend tests' scene plus a wide round beam whose 20 deg discs cross more rings than one
// batch holds.
Scene scene(int nside, double monopole) {
  Scene s = pisco_test::backend_scene(nside, monopole);
  pisco::BeamOptions w;
  w.rho_max = 20 * deg;
  s.beams.push_back(pisco::Beamsor::gaussian(6 * deg, w));
  s.focal_plane.add({"wide", 40 * deg, 0.02, 1.0, s.beams.size() - 1});
  return s;
}

// The device's data for one engine input, kept alive for the emulated kernel.
struct HostDevice {
  std::vector<pc::PixelRecord> pixels;
  std::vector<double> vectors;
  std::vector<std::vector<float>> weights;
  std::vector<std::vector<double>> weights64;
  std::vector<std::vector<double>> plates;
  pc::KernelSky sky{};
  std::vector<pc::KernelDetector> detectors;
  bool monopole = false, per_sample = false;

  // With `four_columns`, every detector's float32 weights in the 4-column layout; otherwise in the
  // kernel's (kernel_columns).
  HostDevice(const pisco::detail::EngineInputs& in, const pisco::Sky& maps, bool four_columns = false) {
    const double i0 = pisco::detail::float32_monopole(maps);
    monopole = i0 != 0.0;
    per_sample = in.normalization == pisco::Normalization::per_sample;
    const pisco::detail::CapBoundary boundary = pisco::detail::cap_boundary(maps.nside(), in.quadrature);
    pixels = pc::pixel_records(maps, i0, boundary);
    vectors = pc::pixel_vectors(maps);
    sky = {pixels.data(), vectors.data(), in.sky.rings.data(), in.sky.nside, i0, boundary};
    std::vector<int> columns;
    for (const auto& d : in.detectors) {
      columns.push_back(four_columns ? 4 : pc::kernel_columns(d));
      weights.push_back(pc::float_weights(d, columns.back()));
      weights64.push_back(pc::float64_weights(d));
      plates.push_back(pc::plate_weights(d));
    }
    for (std::size_t k = 0; k < in.detectors.size(); ++k)
      detectors.push_back(pc::kernel_detector(in.detectors[k], weights[k].data(), columns[k], weights64[k].data(),
                                              plates[k].data()));
  }
};

// The warp's butterfly reduction (convolve.cu's warp_sum), lane by lane; returns lane 0's value.
template <class T>
T butterfly(T v[pc::warp_lanes]) {
  for (int offset = pc::warp_lanes / 2; offset > 0; offset /= 2) {
    T next[pc::warp_lanes];
    for (int l = 0; l < pc::warp_lanes; ++l) next[l] = v[l] + v[l ^ offset];
    for (int l = 0; l < pc::warp_lanes; ++l) v[l] = next[l];
  }
  return v[0];
}

struct Emulated {
  std::vector<double> tod;
  std::uint64_t pixels = 0;
  int most_batches = 0;  // the largest number of batches one sample needed
};

// convolve_kernel of convolve.cu for every sample, one warp emulated on the host.
// With `quats` (4 doubles a sample), the pointing is boresight quaternions rather than p's angles;
// with `plate_angle`, the detector has an aperture plate at those angles (from its axis).
template <bool Radial, bool Monopole, bool PerSample, bool Plate, int Columns>
Emulated emulate(const pc::KernelSky& sky, const pc::KernelDetector& det, const pisco::Pointing& p,
                 const double* quats, const double* plate_angle) {
  Emulated out;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double angles[4] = {p.theta[i], p.phi[i], p.psi[i], 0.0};
    double theta = 0.0, phi = 0.0;
    const auto fd = pc::sample_frame(quats ? quats + 4 * i : angles, quats != nullptr, det, theta, phi);
    const auto f = pc::to_float(fd);
    pc::PlateSample plate{};
    if constexpr (Plate) plate = pc::plate_sample(det, plate_angle[i]);
    std::uint32_t first[pc::batch_ranges], offset[pc::batch_ranges + 1];
    pc::LaneSums lanes[pc::warp_lanes];
    int batches = 0;
    out.pixels += pc::walk_disc(sky, det, theta, phi, first, offset, true, [&](int count) {
      ++batches;
      for (int l = 0; l < pc::warp_lanes; ++l)
        pc::process_batch<Radial, Monopole, PerSample, Plate, Columns>(sky, det, f, fd, first, offset, count, l,
                                                                       lanes[l], &plate);
    });
    out.most_batches = std::max(out.most_batches, batches);
    float sums[pc::warp_lanes];
    double mono[pc::warp_lanes], norm[pc::warp_lanes];
    for (int l = 0; l < pc::warp_lanes; ++l) {
      sums[l] = pc::lane_total(lanes[l]);
      mono[l] = lanes[l].monopole;
      norm[l] = lanes[l].norm;
    }
    out.tod.push_back(pc::finish_sample(butterfly(sums), butterfly(mono), butterfly(norm), sky.monopole, PerSample));
  }
  return out;
}

template <bool Radial, bool Monopole, bool PerSample>
Emulated emulate_plate(const HostDevice& dev, std::size_t d, const pisco::Pointing& p, const double* quats,
                       const double* plate_angle) {
  // The kernels' variants as convolve.cu's launch picks them: behind a plate always four columns.
  const pc::KernelDetector& det = dev.detectors[d];
  if (plate_angle) return emulate<Radial, Monopole, PerSample, true, 4>(dev.sky, det, p, quats, plate_angle);
  if (det.columns == 2) return emulate<Radial, Monopole, PerSample, false, 2>(dev.sky, det, p, quats, nullptr);
  return emulate<Radial, Monopole, PerSample, false, 4>(dev.sky, det, p, quats, nullptr);
}

Emulated emulate(const HostDevice& dev, std::size_t d, bool radial, const pisco::Pointing& p,
                  const double* quats = nullptr, const double* plate_angle = nullptr) {
  const int v = (radial ? 4 : 0) + (dev.monopole ? 2 : 0) + (dev.per_sample ? 1 : 0);
  switch (v) {
    case 0: return emulate_plate<false, false, false>(dev, d, p, quats, plate_angle);
    case 1: return emulate_plate<false, false, true>(dev, d, p, quats, plate_angle);
    case 2: return emulate_plate<false, true, false>(dev, d, p, quats, plate_angle);
    case 3: return emulate_plate<false, true, true>(dev, d, p, quats, plate_angle);
    case 4: return emulate_plate<true, false, false>(dev, d, p, quats, plate_angle);
    case 5: return emulate_plate<true, false, true>(dev, d, p, quats, plate_angle);
    case 6: return emulate_plate<true, true, false>(dev, d, p, quats, plate_angle);
    default: return emulate_plate<true, true, true>(dev, d, p, quats, plate_angle);
  }
}

std::vector<double> reference(const Scene& s, std::size_t d, const pisco::Pointing& p, pisco::Normalization n,
                              double* mean_pixels = nullptr) {
  pisco::EngineOptions o;
  o.quadrature = pisco::Quadrature::plain;  // the kernel itself, against the plain reference
  o.backend = "cpu";
  o.normalization = n;
  pisco::Engine cpu(s.sky, s.beams, s.focal_plane, o);
  std::vector<double> tod(p.size());
  cpu.convolve(d, p, tod);
  if (mean_pixels) *mean_pixels = cpu.mean_disc_pixels();
  return tod;
}

TEST(CudaHostKernel, MonopoleIsSplitOnlyWhereItMatters) {
  const Scene plain = scene(16, 0.0);
  const Scene mono = scene(16, 2.725);
  EXPECT_EQ(pisco::detail::float32_monopole(plain.sky), 0.0);
  const double i0 = pisco::detail::float32_monopole(mono.sky);
  EXPECT_NEAR(i0, 2.725, 1e-5);
  pisco::Sky flat(8);
  for (std::size_t i = 0; i < flat.npix(); ++i) flat.I()[i] = -3.0;
  EXPECT_EQ(pisco::detail::float32_monopole(flat), -3.0);
  const auto records = pc::pixel_records(flat, -3.0);
  EXPECT_EQ(records[5].i, 0.0f);
}

// B1 for the kernel's arithmetic: relative RMS <= 1e-5, max <= 1e-4 of the RMS, the reference's discs.
TEST(CudaHostKernel, Float32SamplesMatchTheReference) {
  for (auto norm : {pisco::Normalization::integral, pisco::Normalization::per_sample}) {
    const Scene s = scene(64, 0.0);
    const pisco::Pointing p = random_pointing(1500, 11);
    const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, norm);
    const HostDevice dev(in, s.sky);
    EXPECT_FALSE(dev.monopole);
    for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
      double ref_pixels = 0;
      const std::vector<double> ref = reference(s, d, p, norm, &ref_pixels);
      const Emulated got = emulate(dev, d, in.detectors[d].radial, p);
      const Stats st = compare(ref, got.tod);
      std::cout << s.focal_plane[d].name << (norm == pisco::Normalization::per_sample ? " (per sample)" : "")
                << ": relative rms error " << st.rms_err / st.rms_ref << ", max error / rms "
                << st.max_err / st.rms_ref << ", up to " << got.most_batches << " batches a sample\n";
      EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref) << s.focal_plane[d].name;
      EXPECT_LE(st.max_err, 1e-4 * st.rms_ref) << s.focal_plane[d].name;
      EXPECT_EQ(double(got.pixels), ref_pixels * double(p.size())) << "the discs differ";
      if (s.focal_plane[d].name == "wide") EXPECT_GT(got.most_batches, 1) << "batching left untested";
    }
  }
}

// The kernel's pointing forms: detectors off the boresight, given boresight quaternions (composed with
// each detector's offset in the kernel) and boresight angles, against the reference (B bars).
TEST(CudaHostKernel, OffsetsAndQuaternionsMatchTheReference) {
  Scene s = scene(64, 0.0);
  std::vector<pisco::Detector> dets = s.focal_plane.detectors();
  for (std::size_t i = 0; i < dets.size(); ++i) dets[i].set_offset((1.0 + double(i)) * pisco::deg, -2.0 * pisco::deg, 0.4 * double(i));
  s.focal_plane = pisco::FocalPlane(dets);
  const pisco::Pointing p = random_pointing(800, 17);
  std::vector<double> quats;
  std::vector<pisco::Quat> qv;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const pisco::Quat q = pisco::quat_from_pointing(p.theta[i], p.phi[i], p.psi[i]);
    qv.push_back(q);
    quats.insert(quats.end(), {q.x, q.y, q.z, q.w});
  }
  const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, pisco::Normalization::integral);
  const HostDevice dev(in, s.sky);
  pisco::Engine cpu(s.sky, s.beams, s.focal_plane, {.backend = "cpu", .quadrature = pisco::Quadrature::plain});
  for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
    std::vector<double> ref(p.size());
    cpu.convolve(d, pisco::QuatPointingView{qv}, ref);
    const Stats sq = compare(ref, emulate(dev, d, in.detectors[d].radial, p, quats.data()).tod);
    const Stats sa = compare(ref, emulate(dev, d, in.detectors[d].radial, p).tod);
    std::cout << s.focal_plane[d].name << " (offset): quaternions relative rms error " << sq.rms_err / sq.rms_ref
              << ", angles " << sa.rms_err / sa.rms_ref << "\n";
    for (const Stats& st : {sq, sa}) {
      EXPECT_LE(st.rms_err, 1e-5 * st.rms_ref) << s.focal_plane[d].name;
      EXPECT_LE(st.max_err, 1e-4 * st.rms_ref) << s.focal_plane[d].name;
    }
  }
}

// Aperture half-wave plates in the kernel's arithmetic (the engine combines the row detectors of
// plates between the optics and the detector itself): a generic plate, on a plain sky and on a
// 2.725 K monopole sky, against the reference at the B bars (of the anisotropy's TOD).
TEST(CudaHostKernel, AperturePlatesMatchTheReference) {
  const pisco::Mueller m0 = pisco_test::generic_plate();
  for (const double monopole : {0.0, 2.725}) {
    Scene s = scene(64, monopole);
    std::vector<pisco::Detector> dets = s.focal_plane.detectors();
    for (std::size_t i = 0; i < dets.size(); ++i) dets[i].hwp = pisco::HalfWavePlate{m0, pisco::HwpPlacement::aperture, 0.3};
    s.focal_plane = pisco::FocalPlane(dets);
    const Scene a = scene(64, 0.0);
    const pisco::Pointing p = random_pointing(600, 19);
    std::vector<double> h(p.size()), theta(p.size());
    for (std::size_t i = 0; i < h.size(); ++i) {
      h[i] = 0.173 * double(i);
      theta[i] = h[i] - 0.3;
    }
    const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, pisco::Normalization::integral);
    const HostDevice dev(in, s.sky);
    pisco::Engine cpu(s.sky, s.beams, s.focal_plane, {.backend = "cpu", .quadrature = pisco::Quadrature::plain});
    pisco::Engine cpu_a(a.sky, a.beams, s.focal_plane, {.backend = "cpu", .quadrature = pisco::Quadrature::plain});
    for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
      std::vector<double> ref(p.size()), aniso(p.size());
      cpu.convolve(d, p, ref, false, h);
      cpu_a.convolve(d, p, aniso, false, h);
      const Stats st = compare(ref, emulate(dev, d, in.detectors[d].radial, p, nullptr, theta.data()).tod);
      const double scale = compare(aniso, aniso).rms_ref;
      std::cout << s.focal_plane[d].name << " (plate" << (monopole ? ", monopole sky" : "") << "): relative rms error "
                << st.rms_err / scale << ", max error / rms " << st.max_err / scale << "\n";
      EXPECT_LE(st.rms_err, 1e-5 * scale) << s.focal_plane[d].name;
      EXPECT_LE(st.max_err, 1e-4 * scale) << s.focal_plane[d].name;
    }
  }
}

// B2: a 2.725 K monopole plus anisotropies: the error stays below 1e-5 of the anisotropy RMS.
TEST(CudaHostKernel, MonopoleSkyKeepsTheAnisotropies) {
  for (auto norm : {pisco::Normalization::integral, pisco::Normalization::per_sample}) {
    const Scene s = scene(64, 2.725);
    const Scene a = scene(64, 0.0);
    const pisco::Pointing p = random_pointing(1000, 14);
    const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, norm);
    const HostDevice dev(in, s.sky);
    EXPECT_TRUE(dev.monopole);
    for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
      const std::vector<double> ref = reference(s, d, p, norm);
      const std::vector<double> aniso = reference(a, d, p, norm);
      const Stats st = compare(ref, emulate(dev, d, in.detectors[d].radial, p).tod);
      const double aniso_rms = compare(aniso, aniso).rms_ref;
      std::cout << s.focal_plane[d].name << ": anisotropy rms " << aniso_rms << " K, max error " << st.max_err
                << " K\n";
      EXPECT_LE(st.max_err, 1e-5 * aniso_rms) << s.focal_plane[d].name;
    }
  }
}

// Without the split, float32 cannot carry the monopole: the bar above is one that can fail.
TEST(CudaHostKernel, WithoutTheSplitTheMonopoleSkyFails) {
  const Scene s = scene(32, 2.725);
  const Scene a = scene(32, 0.0);
  const pisco::Pointing p = random_pointing(300, 15);
  const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, pisco::Normalization::integral);
  HostDevice dev(in, s.sky);
  dev.pixels = pc::pixel_records(s.sky, 0.0);  // the monopole left in float32
  dev.sky.pixels = dev.pixels.data();
  dev.sky.monopole = 0.0;
  dev.monopole = false;
  const Stats st = compare(reference(s, 0, p, pisco::Normalization::integral), emulate(dev, 0, false, p).tod);
  const std::vector<double> aniso = reference(a, 0, p, pisco::Normalization::integral);
  const double aniso_rms = compare(aniso, aniso).rms_ref;
  EXPECT_GT(st.max_err, 1e-5 * aniso_rms);
}


// ---- the adjoint's kernels on the host ----

struct EmulatedAdjoint {
  std::array<std::vector<double>, 4> maps;  // I Q U V, after the fold
  std::vector<std::int64_t> sums;           // the fixed-point sums before it
};

// convolve.cu's adjoint for one detector, lanes in order and samples in the order given (reversed
// with `reverse`): the norm pass (convolve_kernel with Norms) where per-sample, the batch's scale,
// scatter_kernel's integer sums, and the fold (gpu/fixed_point.hpp).
template <bool Radial, bool Float64, bool Plate, int Columns>
EmulatedAdjoint emulate_adjoint(const HostDevice& dev, const pisco::detail::PreparedDetector& prepared, std::size_t d,
                                const pisco::Pointing& p, std::vector<double> values, const double* plate_angle,
                                bool reverse) {
  const pc::KernelSky& sky = dev.sky;
  const pc::KernelDetector& det = dev.detectors[d];
  const std::size_t npix = dev.vectors.size() / 4;
  const auto frame = [&](std::size_t i, double& theta, double& phi) {
    const double angles[4] = {p.theta[i], p.phi[i], p.psi[i], 0.0};
    return pc::sample_frame(angles, false, det, theta, phi);
  };
  std::uint32_t first[pc::batch_ranges], offset[pc::batch_ranges + 1];
  if (dev.per_sample)
    for (std::size_t i = 0; i < p.size(); ++i) {
      double theta = 0.0, phi = 0.0;
      const auto fd = frame(i, theta, phi);
      const auto f = pc::to_float(fd);
      pc::PlateSample plate{};
      if constexpr (Plate) plate = pc::plate_sample(det, plate_angle[i]);
      pc::LaneSums lanes[pc::warp_lanes];
      pc::walk_disc(sky, det, theta, phi, first, offset, true, [&](int count) {
        for (int l = 0; l < pc::warp_lanes; ++l)
          pc::process_batch<Radial, false, true, Plate, Columns>(sky, det, f, fd, first, offset, count, l, lanes[l],
                                                                 &plate);
      });
      double norm[pc::warp_lanes];
      for (int l = 0; l < pc::warp_lanes; ++l) norm[l] = lanes[l].norm;
      const double n = butterfly(norm);
      values[i] = n > 0.0 ? values[i] / n : 0.0;
    }
  const double scale = pisco::detail::fixed_point_scale(values, pisco::detail::adjoint_weight_bound(prepared));
  for (double& v : values) v *= scale;
  EmulatedAdjoint out;
  out.sums.assign(4 * npix, 0);
  for (std::size_t k = 0; k < p.size(); ++k) {
    const std::size_t i = reverse ? p.size() - 1 - k : k;
    if (values[i] == 0.0) continue;
    double theta = 0.0, phi = 0.0;
    const auto fd = frame(i, theta, phi);
    const auto f = pc::to_float(fd);
    pc::PlateSample plate{};
    if constexpr (Plate) plate = pc::plate_sample(det, plate_angle[i]);
    pc::walk_disc(sky, det, theta, phi, first, offset, true, [&](int count) {
      for (int l = 0; l < pc::warp_lanes; ++l)
        pc::scatter_batch<Radial, Float64, Plate, false, Columns>(
            sky, det, f, fd, first, offset, count, l, values[i], &plate,
            [&](std::size_t c, std::int64_t q) { out.sums[c] += q; });
    });
  }
  for (auto& m : out.maps) m.assign(npix, 0.0);
  pisco::detail::fold_fixed_point(out.sums.data(), npix, scale, out.maps);
  return out;
}

template <bool Radial, bool Float64>
EmulatedAdjoint emulate_adjoint(const HostDevice& dev, const pisco::detail::PreparedDetector& prepared, std::size_t d,
                                const pisco::Pointing& p, const std::vector<double>& values, const double* plate_angle,
                                bool reverse) {
  if (plate_angle) return emulate_adjoint<Radial, Float64, true, 4>(dev, prepared, d, p, values, plate_angle, reverse);
  if (dev.detectors[d].columns == 2)
    return emulate_adjoint<Radial, Float64, false, 2>(dev, prepared, d, p, values, plate_angle, reverse);
  return emulate_adjoint<Radial, Float64, false, 4>(dev, prepared, d, p, values, plate_angle, reverse);
}

EmulatedAdjoint emulate_adjoint(const HostDevice& dev, const pisco::detail::PreparedDetector& prepared, std::size_t d,
                                const pisco::Pointing& p, const std::vector<double>& values, const double* plate_angle,
                                bool reverse = false) {
  const bool float64 = dev.monopole || dev.per_sample;
  if (prepared.radial)
    return float64 ? emulate_adjoint<true, true>(dev, prepared, d, p, values, plate_angle, reverse)
                   : emulate_adjoint<true, false>(dev, prepared, d, p, values, plate_angle, reverse);
  return float64 ? emulate_adjoint<false, true>(dev, prepared, d, p, values, plate_angle, reverse)
                 : emulate_adjoint<false, false>(dev, prepared, d, p, values, plate_angle, reverse);
}

// The adjoint kernel's arithmetic against the reference's adjoint (the maps of every detector, at the
// float32 bars of the backends' adjoint parity, tests/test_adjoint.cpp), and the transpose of the
// emulated forward kernel: <s, A^T d> = <A s, d> to float32 rounding. Both normalizations, a sky with
// a 2.725 K monopole (the forward's float64 sums, and the beam coordinates from float64 vectors),
// aperture plates, samples over the whole sphere and near both poles. The integer sums are the same
// whatever the order of the samples.
TEST(CudaHostKernel, AdjointMatchesTheReferenceAndTheForward) {
  const pisco::Mueller m0 = pisco_test::generic_plate();
  pisco::Pointing p = random_pointing(300, 23);
  for (int i = 0; i < 30; ++i) p.push_back(i % 2 ? pi - 0.01 * i * deg : 0.01 * i * deg, 0.3 * i, 0.1 * i);
  std::vector<double> h(p.size()), theta(p.size());
  for (std::size_t i = 0; i < h.size(); ++i) {
    h[i] = 0.173 * double(i);
    theta[i] = h[i] - 0.3;
  }
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g;
  for (const bool plates : {false, true})
    for (const auto norm : {pisco::Normalization::integral, pisco::Normalization::per_sample}) {
      Scene s = scene(32, 2.725);
      if (plates) {
        std::vector<pisco::Detector> dets = s.focal_plane.detectors();
        for (auto& det : dets) det.hwp = pisco::HalfWavePlate{m0, pisco::HwpPlacement::aperture, 0.3};
        s.focal_plane = pisco::FocalPlane(dets);
      }
      const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, norm);
      const HostDevice dev(in, s.sky);
      pisco::EngineOptions o;
      o.backend = "cpu";
      o.quadrature = pisco::Quadrature::plain;
      o.normalization = norm;
      pisco::Engine cpu(s.sky, s.beams, s.focal_plane, o);
      for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
        std::vector<double> values(p.size());
        for (double& v : values) v = g(rng);
        cpu.adjoint(d, p, values, plates ? std::span<const double>(h) : std::span<const double>());
        pisco::Sky want(s.sky.nside());
        cpu.take_adjoint({want.I(), want.Q(), want.U(), want.V()});
        const double* plate_angle = plates ? theta.data() : nullptr;
        const EmulatedAdjoint got = emulate_adjoint(dev, in.detectors[d], d, p, values, plate_angle);
        const std::string what = s.focal_plane[d].name + (plates ? ", plate" : "") +
                                 (norm == pisco::Normalization::per_sample ? ", per sample" : "");
        // Against the reference's maps.
        for (int c = 0; c < 4; ++c) {
          const auto a = want.stokes(pisco::StokesIndex(c));
          if (c == 3 && !plates) continue;  // no V response without a plate
          const Stats st = compare(std::vector<double>(a.begin(), a.end()), got.maps[c]);
          double largest = 0;
          for (double x : a) largest = std::max(largest, std::abs(x));
          EXPECT_LT(st.rms_err, 1e-5 * st.rms_ref) << what << " " << "IQUV"[c];
          EXPECT_LT(st.max_err, 1e-4 * largest) << what << " " << "IQUV"[c];
        }
        // The transpose of the emulated forward kernel.
        const Emulated forward = emulate(dev, d, in.detectors[d].radial, p, nullptr, plate_angle);
        double as_d = 0, s_atd = 0, n_as = 0, n_d = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
          as_d += forward.tod[i] * values[i];
          n_as += forward.tod[i] * forward.tod[i];
          n_d += values[i] * values[i];
        }
        for (int c = 0; c < 4; ++c)
          for (std::size_t k = 0; k < s.sky.npix(); ++k) s_atd += s.sky.stokes(pisco::StokesIndex(c))[k] * got.maps[c][k];
        const double relative = std::abs(as_d - s_atd) / std::sqrt(n_as * n_d);
        std::cout << what << ": adjoint against the forward kernel, difference / (||As|| ||d||) = " << relative << "\n";
        EXPECT_LT(relative, 1e-5) << what;
        if (d == 0) EXPECT_EQ(emulate_adjoint(dev, in.detectors[d], d, p, values, plate_angle, true).sums, got.sums) << what;
      }
    }
}

// The frame, line of sight and disc rings as the warp makes them, their transcendental functions on
// lanes of their own (convolve.cu's warp_sample_frame: angle_trig on lanes 0 to 5, the line of sight's
// angles on lanes 0 and 1, the disc's cosines on lanes 0 to 2, each lane's value shuffled to all),
// emulated lane by lane: the bits of sample_frame and disc_rings, for angles and quaternions, detectors
// on and off the boresight, longitudes outside [0, 2 pi), and samples at and around both poles.
TEST(CudaHostKernel, FrameOnLanesGivesTheSerialFrame) {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const auto rings = pisco::detail::make_ring_table(128);
  pc::KernelSky sky{};
  sky.rings = rings.data();
  sky.nside = 128;
  const auto same = [](const pisco::detail::Vec3<double>& a, const pisco::detail::Vec3<double>& b) {
    return a.x == b.x && a.y == b.y && a.z == b.z;
  };
  std::uint64_t checked = 0;
  for (int detector = 0; detector < 3; ++detector) {
    pc::KernelDetector det{};
    det.rho_max = (detector == 2 ? 30.0 : 5.0) * deg;
    det.cos_zeta = std::cos(0.3 * detector);
    det.sin_zeta = std::sin(0.3 * detector);
    if (detector > 0) {
      const pisco::Quat o = pisco::quat_from_pointing(2.0 * deg, 0.7, 0.2);
      det.offset = pisco::detail::make_offset({o.x, o.y, o.z, o.w});
    }
    for (int k = 0; k < 20000; ++k) {
      double theta = std::acos(1 - 2 * u(rng));
      if (k % 4 == 0) theta = k % 8 ? 3 * deg * u(rng) : pi - 3 * deg * u(rng);
      if (k < 8) theta = k % 2 ? 0.0 : pi;
      const double angles[4] = {theta, 6 * pi * u(rng) - 2 * pi, 2 * pi * u(rng), 0.0};
      const pisco::Quat q = pisco::quat_from_pointing(angles[0], angles[1], angles[2]);
      const double quat[4] = {q.x, q.y, q.z, q.w};
      for (const bool quaternions : {false, true}) {
        const double* b = quaternions ? quat : angles;
        double theta0 = 0.0, phi0 = 0.0;
        const auto serial = pc::sample_frame(b, quaternions, det, theta0, phi0);
        const auto d0 = pisco::detail::disc_rings(sky.nside, theta0, det.rho_max);
        // The warp, lane by lane.
        double lanes[pc::warp_lanes] = {}, trig[pc::angle_trig_lanes] = {};
        if (!quaternions) {
          for (int l = 0; l < pc::angle_trig_lanes; ++l) lanes[l] = pc::angle_trig(b, l);
          for (int l = 0; l < pc::angle_trig_lanes; ++l) trig[l] = lanes[l];
        }
        pisco::detail::Vec3<double> theta_p, phi_p, pv;
        double theta1 = 0.0, phi1 = 0.0;
        if (!pc::detector_basis(b, quaternions, det, trig, theta_p, phi_p, pv, theta1, phi1)) {
          for (int l = 0; l < 2; ++l) lanes[l] = pisco::detail::pisco_direction_angle(pv, l);
          theta1 = lanes[0];
          phi1 = lanes[1];
        }
        for (int l = 0; l < 3; ++l) lanes[l] = pisco::detail::disc_cos(theta1, det.rho_max, l);
        const auto d1 =
            pisco::detail::disc_rings_from_cos(sky.nside, theta1, det.rho_max, lanes[0], lanes[1], lanes[2]);
        const auto spread = pisco::detail::frame_with_zeta(theta_p, phi_p, pv, det.cos_zeta, det.sin_zeta);
        ++checked;
        const bool ok = theta0 == theta1 && phi0 == phi1 && same(serial.theta_p, spread.theta_p) &&
                        same(serial.phi_p, spread.phi_p) && same(serial.p, spread.p) && same(serial.e_c, spread.e_c) &&
                        d0.first == d1.first && d0.last == d1.last && d0.north == d1.north && d0.south == d1.south &&
                        d0.z0 == d1.z0 && d0.xa == d1.xa;
        if (!ok) {
          ADD_FAILURE() << "detector " << detector << (quaternions ? ", quaternion" : ", angles") << " pointing ("
                        << angles[0] << ", " << angles[1] << ", " << angles[2] << ")";
          return;
        }
      }
    }
  }
  EXPECT_EQ(checked, 120000u);
}

// The weights of detectors without w_U and w_V as (w_I, w_Q) pairs, one 16-byte load a node pair
// (kernel_columns, IQPairGrid): the same TOD values (equal as numbers) and the same adjoint integers
// as the 4-column layout, for radial and 2D beams, both normalizations, a plain and a 2.725 K monopole
// sky, over the whole sphere and across both poles. The scene holds detectors of both layouts.
TEST(CudaHostKernel, TwoColumnWeightsGiveTheFourColumnValues) {
  pisco::Pointing p = random_pointing(400, 29);
  for (int i = 0; i < 40; ++i) p.push_back(i % 2 ? pi - 0.05 * i * deg : 0.05 * i * deg, 0.37 * i, 0.11 * i);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  std::vector<double> values(p.size());
  for (double& v : values) v = g(rng);
  int paired = 0, four = 0;
  for (const double monopole : {0.0, 2.725})
    for (const auto norm : {pisco::Normalization::integral, pisco::Normalization::per_sample}) {
      const Scene s = scene(32, monopole);
      const auto in = pisco::detail::prepare_inputs(s.sky, s.beams, s.focal_plane, norm);
      const HostDevice dev(in, s.sky), all_four(in, s.sky, true);
      for (std::size_t d = 0; d < s.focal_plane.size(); ++d) {
        const std::string what = s.focal_plane[d].name + (monopole ? ", monopole sky" : "") +
                                 (norm == pisco::Normalization::per_sample ? ", per sample" : "");
        EXPECT_EQ(all_four.detectors[d].columns, 4);
        if (dev.detectors[d].columns != 2) {
          ++four;
          continue;
        }
        ++paired;
        const bool radial = in.detectors[d].radial;
        const Emulated a = emulate(dev, d, radial, p), b = emulate(all_four, d, radial, p);
        ASSERT_EQ(a.tod.size(), b.tod.size());
        std::size_t differ = 0;
        for (std::size_t i = 0; i < a.tod.size(); ++i) differ += a.tod[i] != b.tod[i];
        EXPECT_EQ(differ, 0u) << what << ": samples whose values differ";
        EXPECT_EQ(a.pixels, b.pixels) << what;
        EXPECT_EQ(emulate_adjoint(dev, in.detectors[d], d, p, values, nullptr).sums,
                  emulate_adjoint(all_four, in.detectors[d], d, p, values, nullptr).sums)
            << what;
      }
    }
  EXPECT_GT(paired, 0) << "no detector took the paired layout";
  EXPECT_GT(four, 0) << "no detector kept four columns";
}

// The cooperative disc walk (sample.hpp; convolve.cu's walk_disc_warp), its warp steps run lane by
// lane: each lane's ring_ranges, the ballots as masks, stage_ranges and unstage_batch per lane, the
// offsets' scan as a running sum. Appends every batch to `out` as (count, first..., offsets...).
std::uint32_t cooperative_walk(const pc::KernelSky& sky, const pc::KernelDetector& det, double theta, double phi,
                               std::vector<std::uint32_t>& out) {
  const pisco::detail::DiscRings d = pisco::detail::disc_rings(sky.nside, theta, det.rho_max);
  std::uint32_t begin[pc::staging_ranges], end[pc::staging_ranges], offset[pc::warp_lanes + 1];
  std::uint32_t pixels = 0;
  int pending = 0;
  const auto cut = [&](bool all) {
    while (pending >= pc::batch_ranges || (all && pending > 0)) {
      const int count = std::min(pending, pc::batch_ranges);
      std::uint32_t sum = 0;
      offset[0] = 0;
      for (int l = 0; l < pc::warp_lanes; ++l) {
        sum += l < count ? end[l] - begin[l] : 0u;
        offset[l + 1] = sum;
      }
      out.push_back(std::uint32_t(count));
      out.insert(out.end(), begin, begin + count);
      out.insert(out.end(), offset, offset + count + 1);
      pixels += sum;
      if (pending > count)
        for (int l = 0; l < pc::warp_lanes; ++l) pc::unstage_batch(begin, end, pending, l);
      pending -= count;
    }
  };
  pc::stage_cap(begin, end, pending, true, [&](auto&& emit) { pisco::detail::emit_north_cap(sky.rings, d, emit); });
  for (std::int64_t base = d.first; base <= d.last; base += pc::warp_lanes) {
    pc::RingRanges rr[pc::warp_lanes];
    std::uint32_t one = 0, two = 0;
    for (int l = 0; l < pc::warp_lanes; ++l) {
      if (base + l <= d.last) rr[l] = pc::ring_ranges(sky, d, phi, det.cos_rho_max, base + l);
      if (rr[l].count >= 1) one |= 1u << l;
      if (rr[l].count == 2) two |= 1u << l;
    }
    for (int l = 0; l < pc::warp_lanes; ++l) pc::stage_ranges(begin, end, pending, one, two, l, rr[l]);
    pending += pc::popcount32(one) + pc::popcount32(two);
    cut(false);
  }
  pc::stage_cap(begin, end, pending, true,
                [&](auto&& emit) { pisco::detail::emit_south_cap(sky.rings, sky.nside, d, emit); });
  cut(true);
  return pixels;
}

// walk_disc's batches, in the same form.
std::uint32_t serial_walk(const pc::KernelSky& sky, const pc::KernelDetector& det, double theta, double phi,
                          std::vector<std::uint32_t>& out) {
  std::uint32_t first[pc::batch_ranges], offset[pc::batch_ranges + 1];
  return pc::walk_disc(sky, det, theta, phi, first, offset, true, [&](int count) {
    out.push_back(std::uint32_t(count));
    out.insert(out.end(), first, first + count);
    out.insert(out.end(), offset, offset + count + 1);
  });
}

// The cooperative walk hands every lane the pixels walk_disc hands it (the same batches, so the same
// TOD bits): every sample of the Table 1 workload (every NSIDE 128 pixel centre) at every Table 1
// radius, and samples at and around both poles, discs holding a pole, and other NSIDE.
TEST(CudaHostKernel, CooperativeRingWalkGivesTheSerialWalksBatches) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<std::uint32_t> serial, cooperative;
  std::uint64_t samples = 0, batches_over_one = 0;
  const auto check = [&](const pc::KernelSky& sky, const pc::KernelDetector& det, double theta, double phi) {
    serial.clear();
    cooperative.clear();
    const std::uint32_t a = serial_walk(sky, det, theta, phi, serial);
    const std::uint32_t b = cooperative_walk(sky, det, theta, phi, cooperative);
    ++samples;
    batches_over_one += serial.size() > std::size_t(2 * pc::batch_ranges + 2);
    if (a != b || serial != cooperative) {
      ADD_FAILURE() << "NSIDE " << sky.nside << ", rho_max " << det.rho_max / deg << " deg, theta " << theta
                    << ", phi " << phi << ": " << a << " against " << b << " pixels";
      return false;
    }
    return true;
  };
  const auto kernel_sky = [](const std::vector<pisco::detail::RingEntry>& rings, int nside) {
    pc::KernelSky sky{};
    sky.rings = rings.data();
    sky.nside = nside;
    return sky;
  };
  const auto detector = [](double rho) {
    pc::KernelDetector det{};
    det.rho_max = rho;
    det.cos_rho_max = std::cos(rho);
    return det;
  };
  {
    const int nside = 128;
    const auto rings = pisco::detail::make_ring_table(nside);
    const pc::KernelSky sky = kernel_sky(rings, nside);
    const Healpix_Base base(nside, RING, SET_NSIDE);
    for (const double rho : {5.0, 7.5, 10.0, 15.0, 20.0, 25.0, 30.0}) {
      const pc::KernelDetector det = detector(rho * deg);
      bool ok = true;
      for (int p = 0; p < base.Npix() && ok; ++p) {
        const pointing c = base.pix2ang(p);
        ok = check(sky, det, c.theta, c.phi);
      }
      for (int k = 0; k < 2000 && ok; ++k) {  // at and around the poles, on and off the rings' own longitudes
        const double theta = k % 2 ? 4 * deg * u(rng) : pi - 4 * deg * u(rng);
        ok = check(sky, det, k < 4 ? (k % 2 ? 0.0 : pi) : theta, 2 * pi * u(rng));
      }
    }
  }
  for (const int nside : {1, 4, 64, 1024}) {
    const auto rings = pisco::detail::make_ring_table(nside);
    const pc::KernelSky sky = kernel_sky(rings, nside);
    for (const double rho : {0.5, 5.0, 30.0, 60.0}) {
      const pc::KernelDetector det = detector(rho * deg);
      bool ok = true;
      for (int k = 0; k < (nside == 1024 && rho > 10 ? 200 : 3000) && ok; ++k)
        ok = check(sky, det, k % 3 == 0 ? 10 * deg * u(rng) : std::acos(1 - 2 * u(rng)), 2 * pi * u(rng));
    }
  }
  std::cout << samples << " discs, " << batches_over_one << " of them in more than one batch\n";
  EXPECT_GT(batches_over_one, 100000u) << "the staging's carry from batch to batch left untested";
}

}  // namespace
