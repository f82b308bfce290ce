// Nothing silent (docs/physics.md, "Physical bounds on Mueller matrices"; docs/formats.md, "Errors
// and partial files"): every output value finite where it is produced (the engine's TOD, TOD files,
// HEALPix maps, spectra), Mueller matrices within their physical bounds (half-wave plates, beams'
// constant matrices, sampled beam fields), node counts checked before they are cast, and the focal
// plane every engine is given checked alike. Each error must name what it is about.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/hwp.hpp"
#include "pisco/spectra.hpp"
#include "pisco/tod_file.hpp"
#include "backend_fixtures.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::deg;
using pisco::Mueller;
using pisco::MuellerBounds;
using pisco_test::contains;
using pisco_test::error_of;
using pisco_test::expect_error;

constexpr double pi = std::numbers::pi;

// A fresh directory of its own for each test that writes files.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("pisco_test_checks_" + std::to_string(::getpid())) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Points on the equator, away from the poles.
pisco::Pointing equator(std::size_t n) {
  pisco::Pointing p;
  for (std::size_t i = 0; i < n; ++i) p.push_back(pi / 2, 0.3 * double(i), 0.1 * double(i));
  return p;
}

std::vector<pisco::Beamsor> one_beam() {
  pisco::BeamOptions o;
  o.rho_max = 16 * deg;
  return {pisco::Beamsor::gaussian(8 * deg, o)};
}

pisco::EngineOptions plain_cpu() {
  pisco::EngineOptions o;
  o.backend = "cpu";
  o.quadrature = pisco::Quadrature::plain;  // no polar copy (its ring transforms would overflow first)
  return o;
}

Mueller plate(std::initializer_list<std::pair<std::pair<int, int>, double>> entries) {
  Mueller m = pisco::ideal_hwp_mueller();
  for (const auto& [ij, v] : entries) m[ij.first][ij.second] = v;
  return m;
}

// ---- the engine's TOD ------------------------------------------------------------------------------

// A sky of 1e308 everywhere is finite, and so is a detector of gain 1 on it (5e307 a sample);
// gain 100 overflows float64. The error names the detector, the sample and the value; every
// submission waited for is complete, and a later wait() reports nothing again.
TEST(Checks, NonFiniteTodNamesTheDetectorAndTheSample) {
  pisco::Sky sky(16);
  for (double& v : sky.I()) v = 1e308;
  pisco::FocalPlane fp;
  fp.add({"cold", 0.0, 0.0, 1.0, 0});
  fp.add({"hot", 0.0, 0.0, 100.0, 0});
  pisco::Detector plated{"hot_plate", 0.0, 0.0, 100.0, 0};
  plated.hwp = pisco::HalfWavePlate::ideal(0.0, pisco::HwpPlacement::detector);
  fp.add(plated);
  pisco::Engine engine(sky, one_beam(), fp, plain_cpu());
  const pisco::Pointing p = equator(5);

  std::vector<double> tod(p.size(), 0.0);
  const std::string message = error_of([&] { engine.convolve(1, p, tod); });
  EXPECT_TRUE(contains(message, "detector 'hot'")) << message;
  EXPECT_TRUE(contains(message, "sample 0 of the TOD is inf")) << message;
  EXPECT_TRUE(contains(message, "too large for float64")) << message;

  // The plate between the optics and the detector: completed by the engine, checked alike.
  const std::vector<double> angles(p.size(), 0.2);
  const std::string plate_message = error_of([&] { engine.convolve(2, p, tod, false, angles); });
  EXPECT_TRUE(contains(plate_message, "detector 'hot_plate': sample 0 of the TOD is")) << plate_message;

  // Asynchronously: cold, hot, cold, then one wait() for all three.
  std::vector<double> a(p.size(), 0.0), b(p.size(), 0.0), c(p.size(), 0.0);
  engine.submit(0, p, a);
  engine.submit(1, p, b);
  engine.submit(0, p, c);
  expect_error([&] { engine.wait(); }, "detector 'hot': sample 0");
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_TRUE(std::isfinite(a[i]) && a[i] > 0.4e308) << i << " " << a[i];  // gain / 2 (1 + epsilon) I
    EXPECT_EQ(a[i], c[i]) << i;  // the submission after the failed one completed too
  }
  EXPECT_EQ(error_of([&] { engine.wait(); }), "no error");
  std::vector<double> d(p.size(), 0.0);
  EXPECT_EQ(error_of([&] { engine.convolve(0, p, d); }), "no error");
  EXPECT_EQ(d, a);

  // Accumulating into a TOD that holds a NaN: refused before the work, naming the sample.
  std::vector<double> dirty(p.size(), 0.0);
  dirty[3] = NAN;
  expect_error([&] { engine.convolve(0, p, dirty, true); }, "the TOD to accumulate into is nan at sample 3");
}

// ---- Mueller matrices ---------------------------------------------------------------------------

TEST(Checks, HalfWavePlateBounds) {
  const auto plate_error = [](const Mueller& m) {
    return error_of([&] { pisco::HalfWavePlate{m, pisco::HwpPlacement::aperture, 0.0}.check("p"); });
  };
  // M00 <= 0.
  std::string e = plate_error(plate({{{0, 0}, -1.0}}));
  EXPECT_TRUE(contains(e, "p: half-wave plate: M00 = -1 (T to T) is not positive")) << e;
  EXPECT_TRUE(contains(plate_error(plate({{{0, 0}, 0.0}})), "M00 = 0 (T to T) is not positive"));
  // More light out than in.
  e = plate_error(plate({{{0, 1}, 1e200}}));
  EXPECT_TRUE(contains(e, "p: half-wave plate: transmits up to 1e+200 times the light (M00 + |(M01, M02, M03)| = "
                          "1e+200), at most 1.01 for a passive element")) << e;
  e = plate_error(plate({{{0, 0}, 1.02}}));
  EXPECT_TRUE(contains(e, "transmits up to 1.02 times the light")) << e;
  // Unpolarized light polarized beyond 1: |(0.8, 0.8, 0)| = 1.13.
  e = plate_error(plate({{{1, 1}, 0.5}, {{2, 2}, -0.5}, {{3, 3}, -0.5}, {{1, 0}, 0.8}, {{2, 0}, 0.8}}));
  EXPECT_TRUE(contains(e, "polarizes unpolarized light to a degree of 1.13137 (|(M10, M20, M30)| / M00), at most 1.01"))
      << e;
  // One entry above M00.
  e = plate_error(plate({{{2, 2}, -1.5}}));
  EXPECT_TRUE(contains(e, "|M22| = 1.5 exceeds (1 + 0.01) M00 = 1.01")) << e;
  // Not finite.
  e = plate_error(plate({{{3, 1}, INFINITY}}));
  EXPECT_TRUE(contains(e, "Mueller entry [3][1] is inf")) << e;

  // Accepted: the ideal plate, the tests' generic one, a plate a little off its design (the example
  // assets/examples/hwp_satellite.toml), a 1% T-to-Q leak at the bound, and a lossy Jones plate of
  // litebird_sim's non-ideal model (h1 = -0.016, h2 = -0.042, beta = -14.5 deg, z1 = z2 = 0.01, its
  // MFT 100 GHz table at 89 GHz), converted as litebird_sim's JonesToMueller does.
  EXPECT_EQ(plate_error(pisco::ideal_hwp_mueller()), "no error");
  EXPECT_EQ(plate_error(pisco_test::generic_plate()), "no error");
  const Mueller off_design{{{1.0, 0.001, 0.0, 0.0}, {0.001, 0.99, 0.002, 0.0}, {0.0, 0.002, -0.99, 0.01},
                            {0.0, 0.0, -0.01, -0.99}}};
  EXPECT_EQ(plate_error(off_design), "no error");
  EXPECT_EQ(plate_error(plate({{{0, 1}, 0.01}})), "no error");
  {
    using cd = std::complex<double>;
    const double h1 = -1.634e-2, h2 = -4.191e-2, beta = -14.54 * deg, z = 0.01;
    const cd j[2][2] = {{cd(1 + h1), cd(z)}, {cd(z), -(1 + h2) * std::exp(cd(0, beta))}};
    // M_ij = 1/2 tr(sigma_i J sigma_j J^H), with the Pauli basis (1, z, x, y) of I, Q, U, V.
    const cd s[4][2][2] = {{{1, 0}, {0, 1}}, {{1, 0}, {0, -1}}, {{0, 1}, {1, 0}}, {{0, cd(0, -1)}, {cd(0, 1), 0}}};
    Mueller m{};
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        cd t = 0;
        for (int p = 0; p < 2; ++p)
          for (int q = 0; q < 2; ++q)
            for (int r = 0; r < 2; ++r)
              for (int u = 0; u < 2; ++u) t += s[a][p][q] * j[q][r] * s[b][r][u] * std::conj(j[p][u]);
        m[a][b] = 0.5 * t.real();
      }
    EXPECT_NEAR(m[0][0], 0.943, 1e-3);
    EXPECT_EQ(plate_error(m), "no error");
  }

  // Through an engine: the detector is named.
  pisco::Sky sky(8);
  pisco::Detector d{"plated", 0.0, 0.0, 1.0, 0};
  d.hwp = pisco::HalfWavePlate{plate({{{0, 1}, 1e200}}), pisco::HwpPlacement::aperture, 0.0};
  pisco::FocalPlane fp;
  fp.add(d);
  expect_error([&] { pisco::Engine(sky, one_beam(), fp, plain_cpu()); },
               "detector 'plated': half-wave plate: transmits up to 1e+200 times the light");
}

// Each beam option is checked once, by pisco::check_beam_options, which every builder calls: its error
// is keyed by the field (Error::key), for a simulation file to name by its own key.
TEST(Checks, BeamOptionsAreKeyedByTheirField) {
  const auto key_of = [](const std::function<void()>& f) -> std::string {
    try {
      f();
    } catch (const pisco::Error& e) {
      return e.key();
    }
    return "no error";
  };
  pisco::check_beam_options(pisco::BeamOptions{});  // the defaults
  std::vector<std::pair<std::string, std::function<void(pisco::BeamOptions&)>>> cases = {
      {"rho_max", [](pisco::BeamOptions& o) { o.rho_max = 90 * deg; }},
      {"rho_max", [](pisco::BeamOptions& o) { o.rho_max = 0.0; }},
      {"grid_step", [](pisco::BeamOptions& o) { o.grid_step = -1e-3; }},
      {"split.rho_main", [](pisco::BeamOptions& o) { o.split.rho_main = 6 * deg; }},
      {"split.taper", [](pisco::BeamOptions& o) { o.split = {2 * deg, 3 * deg, 0}; }},
      {"split.nside", [](pisco::BeamOptions& o) { o.split = {2 * deg, 0.0, 12}; }},
      {"cross_polar", [](pisco::BeamOptions& o) { o.cross_polar = NAN; }},
      {"mueller", [](pisco::BeamOptions& o) { o.mueller[0][0] = -1.0; }},
      {"far_sidelobe.level", [](pisco::BeamOptions& o) { o.far_sidelobe.level = -1e-3; }},
      {"far_sidelobe.radius", [](pisco::BeamOptions& o) { o.far_sidelobe = {1e-3, 6 * deg, 1 * deg, 0.0, 0.0}; }},
      {"far_sidelobe.width", [](pisco::BeamOptions& o) { o.far_sidelobe = {1e-3, 4 * deg, 0.0, 0.0, 0.0}; }},
      {"far_sidelobe.asymmetry", [](pisco::BeamOptions& o) { o.far_sidelobe = {1e-3, 4 * deg, 1 * deg, 0.0, 1.5}; }},
  };
  for (const auto& [key, spoil] : cases) {
    pisco::BeamOptions o;
    spoil(o);
    EXPECT_EQ(key_of([&] { pisco::check_beam_options(o); }), key);
    EXPECT_EQ(key_of([&] { pisco::Beamsor::gaussian(1 * deg, o); }), key) << "the builder checks with it";
  }
  EXPECT_EQ(key_of([] { pisco::check_beam_width(10.5 * deg, 5 * deg, "fwhm_x"); }), "fwhm_x");
  EXPECT_EQ(key_of([] { pisco::check_beam_width(-1 * deg, 5 * deg, "fwhm"); }), "fwhm");
  EXPECT_EQ(key_of([] { pisco::Beamsor::elliptical_gaussian(1 * deg, 11 * deg, 0.0, {}); }), "fwhm_y");
  pisco::check_beam_width(9.9 * deg, 5 * deg, "fwhm");  // its half-maximum radius within rho_max
}

TEST(Checks, BeamConstantMuellerBounds) {
  pisco::BeamOptions o;
  o.mueller[0][0] = 0.0;
  expect_error([&] { pisco::Beamsor::gaussian(1 * deg, o); },
               "mueller: the constant Mueller matrix: M00 = 0 (T to T) is not positive");
  o.mueller = pisco::identity_mueller();
  o.mueller[1][0] = 2.0;
  expect_error([&] { pisco::Beamsor::gaussian(1 * deg, o); }, "|M10| = 2 exceeds (1 + 0.01) M00 = 1.01");
  o.mueller[1][0] = NAN;
  expect_error([&] { pisco::Beamsor::gaussian(1 * deg, o); }, "Mueller entry [1][0] is nan");
  // A leak within M00, and an overall scale: accepted (the beam is normalized by its own B_TT).
  o.mueller = pisco::identity_mueller();
  o.mueller[1][0] = 0.003;
  o.mueller[3][3] = 0.5;
  EXPECT_EQ(error_of([&] { pisco::Beamsor::gaussian(1 * deg, o); }), "no error");
  for (auto& row : o.mueller)
    for (double& v : row) v *= 1e6;
  EXPECT_EQ(error_of([&] { pisco::Beamsor::gaussian(1 * deg, o); }), "no error");
  // The library helper itself: finiteness only.
  Mueller big{};
  big[2][3] = 1e300;
  EXPECT_EQ(error_of([&] { pisco::check_mueller(big, "m", MuellerBounds::finite); }), "no error");
}

// A Gaussian field with one entry set by `entry` (row, column) as a multiple of B_TT, or a value at
// rho > 1 deg.
pisco::Beamsor::Field field_with(int row, int col, double factor, double beyond = 0.0) {
  return [=](double rho, double) {
    const double b = std::exp(-rho * rho / (2 * std::pow(1 * deg, 2)));
    Mueller m{};
    m[0][0] = m[1][1] = m[2][2] = b;
    m[row][col] = factor * b;
    if (beyond != 0.0 && rho > 1 * deg) m[row][col] = beyond;
    return m;
  };
}

TEST(Checks, BeamFieldBounds) {
  for (const bool radial : {false, true}) {
    SCOPED_TRACE(radial ? "radial" : "grid");
    const auto build = [&](const pisco::Beamsor::Field& f) {
      pisco::Beamsor::from_field(f, 4 * deg, 0.1 * deg, "test beam", 0.0, radial);
    };
    // B_TQ (row Q, column T) 1.5 times B_TT everywhere: above the peak B_TT = 1 at the axis.
    std::string e = error_of([&] { build(field_with(1, 0, 1.5)); });
    EXPECT_TRUE(contains(e, "beam 'test beam': B_TQ (row 1, column 0) = 1.5 at ")) << e;
    EXPECT_TRUE(contains(e, "exceeds the beam's peak B_TT = 1 by more than 1%")) << e;
    EXPECT_TRUE(contains(e, radial ? "radial node 0 (rho = 0 deg)" : "node (")) << e;
    // Entries within the peak anywhere are fine, even above the local B_TT (a sidelobe's cross-polar).
    EXPECT_EQ(error_of([&] { build(field_with(1, 0, 0.5, 0.9)); }), "no error");
    // Not finite at one node.
    e = error_of([&] { build(field_with(2, 3, 0.0, NAN)); });
    EXPECT_TRUE(contains(e, "beam 'test beam': B_VU (row 2, column 3) is nan at ")) << e;
    EXPECT_TRUE(contains(e, "must be finite")) << e;
    // B_TT nowhere positive.
    e = error_of([&] { build(field_with(0, 0, -1.0)); });
    EXPECT_TRUE(contains(e, "B_TT is nowhere positive (its largest value is ")) << e;
  }
}

// ---- the writers -----------------------------------------------------------------------------------

TEST(Checks, TodWriterRefusesNonFiniteAndOutOfRangeValues) {
  const fs::path dir = scratch("tod");
  pisco::FocalPlane fp;
  fp.add({"d0", 0.0, 0.0, 1.0, 0});
  fp.add({"d1", 0.0, 0.0, 1.0, 0});
  const std::size_t n = 10;
  const std::vector<double> good(n, 2.5);
  for (const auto precision : {pisco::TodPrecision::float32, pisco::TodPrecision::float64}) {
    const bool f32 = precision == pisco::TodPrecision::float32;
    SCOPED_TRACE(f32 ? "float32" : "float64");
    const fs::path file = dir / (f32 ? "f32.h5" : "f64.h5");
    {
      pisco::TodWriter w(file, fp, n, precision, false, {});
      w.write(0, 0, good);
      w.write(1, 0, good);
      std::vector<double> bad = good;
      bad[4] = NAN;
      std::string e = error_of([&] { w.write(1, 3, std::span<const double>(bad).subspan(0, 7)); });
      EXPECT_TRUE(contains(e, file.string() + ": detector 'd1': the signal of sample 7 is nan")) << e;
      bad[4] = -INFINITY;
      e = error_of([&] { w.write(1, 0, bad); });
      EXPECT_TRUE(contains(e, "the signal of sample 4 is -inf")) << e;
      // Beyond float32: refused in a float32 file only.
      bad[4] = 1e39;
      e = error_of([&] { w.write(1, 0, bad); });
      if (f32)
        EXPECT_TRUE(contains(e, "detector 'd1': the signal of sample 4 is 1e+39, beyond float32's range")) << e;
      else
        EXPECT_EQ(e, "no error");
      if (!f32) w.write(1, 0, good);
      w.commit();
    }
    // Nothing of the refused writes reached the file.
    EXPECT_EQ(pisco::read_tod_signal(file, "d1"), good);
  }
}

TEST(Checks, HealpixMapWriterRefusesNonFiniteValues) {
  const fs::path dir = scratch("map");
  const int nside = 2;
  std::vector<double> a(48, 1.0), b(48, pisco::unseen);
  b[0] = 0.5;
  const fs::path file = dir / "map.fits";
  // UNSEEN is finite: written.
  pisco::write_healpix_map(file, nside, {{"I_STOKES", a}, {"HITS", b}}, "K_CMB");
  EXPECT_TRUE(fs::exists(file));
  fs::remove(file);
  b[5] = NAN;
  const std::string e = error_of([&] { pisco::write_healpix_map(file, nside, {{"I_STOKES", a}, {"HITS", b}}, "K_CMB"); });
  EXPECT_TRUE(contains(e, "map.fits")) << e;
  EXPECT_TRUE(contains(e, "column HITS: pixel 5 is nan")) << e;
  EXPECT_FALSE(fs::exists(file));
  EXPECT_TRUE(fs::is_empty(dir));  // no temporary left either
}

TEST(Checks, SpectraMustBeFinite) {
  pisco::Spectra s;
  for (auto* v : {&s.TT, &s.EE, &s.BB, &s.TE, &s.EB, &s.TB}) v->assign(11, 1.0);
  EXPECT_EQ(error_of([&] { pisco::check_finite(s, "out.txt"); }), "no error");
  s.EB[7] = INFINITY;
  expect_error([&] { pisco::check_finite(s, "out.txt"); }, "out.txt: EB at l = 7 is inf");
  EXPECT_EQ(error_of([&] { pisco::check_finite(s, "out.txt", 2, 6); }), "no error");  // beyond the range written
}

// ---- node counts before their cast --------------------------------------------------------------

TEST(Checks, RadialNodeCountsAreBoundedBeforeTheCast) {
  EXPECT_EQ(pisco::Beamsor::radial_nodes(10 * deg, 0.1 * deg, "b"),
            static_cast<int>(std::ceil(std::sin(10 * deg) / (0.1 * deg / 64))) + 2);
  std::string e = error_of([&] { pisco::Beamsor::radial_nodes(10 * deg, 1e-300, "b"); });
  EXPECT_TRUE(contains(e, "b: grid_step = ")) << e;
  EXPECT_TRUE(contains(e, "radial profile nodes for rho_max = 10 deg; at most " +
                              std::to_string(pisco::Beamsor::max_radial_nodes) + " are allowed"))
      << e;
  // The finest grid step the 2-D limit accepts is accepted radially too.
  EXPECT_NO_THROW(pisco::Beamsor::radial_nodes(80 * deg, 2 * std::sin(80 * deg) / 8190.5, "b"));

  // A harmonic beam's radial layout, synthesized ahead of the grid: named by its source.
  pisco::HarmonicBeam blm;
  blm.lmax = 8;
  blm.mmax = 0;
  blm.source = "round.fits";
  for (int l = 0; l <= 8; ++l) blm.t.push_back(std::exp(-0.01 * l * (l + 1)));
  pisco::FileBeamOptions o;
  o.rho_max = 30 * deg;
  o.grid_step = 1e-300;
  e = error_of([&] { pisco::Beamsor::from_harmonic(blm, o); });
  EXPECT_TRUE(contains(e, "harmonic beam round.fits: grid_step = ")) << e;
  EXPECT_TRUE(contains(e, "radial profile nodes")) << e;

  // GRASP cuts whose theta steps are tiny beside their distance from the axis: refused before
  // lround's cast, naming the file.
  pisco::GraspBeam g;
  g.grid = pisco::GraspBeam::Grid::cuts;
  g.nx = 2;
  g.ny = 3;
  g.x_values = {0.0, pi / 2};
  g.xs = 0.0;
  g.xe = pi / 2;
  g.ys = 1.0;
  g.ye = 1.0 + 2e-12;
  g.co.assign(6, {1.0, 0.0});
  g.cx.assign(6, {0.0, 0.0});
  g.source = "far.cut";
  pisco::FileBeamOptions go;
  go.rho_max = 1 * deg;
  e = error_of([&] { pisco::Beamsor::from_grasp(g, go); });
  EXPECT_TRUE(contains(e, "far.cut: theta = ")) << e;
  EXPECT_TRUE(contains(e, "beyond the 3 samples of a cut")) << e;
}

// ---- focal planes -----------------------------------------------------------------------------------

TEST(Checks, FocalPlaneValidation) {
  pisco::Sky sky(8);
  const auto beams = one_beam();
  const auto engine_error = [&](const std::vector<pisco::Detector>& ds) {
    return error_of([&] { pisco::Engine(sky, beams, pisco::FocalPlane(ds), plain_cpu()); });
  };
  const pisco::Detector good{"a", 0.0, 0.0, 1.0, 0};
  pisco::Detector b = good, c = good;
  b.name = "b";
  EXPECT_EQ(engine_error({good, b}), "no error");
  EXPECT_EQ(engine_error({good, b, good}),
            "focal plane: detectors 0 and 2 are both named 'a' (expected unique detector names)");
  c.name = "";
  EXPECT_EQ(engine_error({good, c}), "focal plane: detector 1 has an empty name (expected unique names)");
  for (const double gain : {0.0, -1.0, double(NAN), double(INFINITY)}) {
    pisco::Detector d = good;
    d.gain = gain;
    const std::string e = engine_error({d});
    EXPECT_TRUE(contains(e, "detector 'a': gain = ")) << e;
    EXPECT_TRUE(contains(e, "(its responsivity) must be positive and finite")) << e;
  }
  pisco::Detector eps = good;
  eps.epsilon = 1.5;
  EXPECT_EQ(engine_error({eps}), "detector 'a': epsilon = 1.5 (cross-polar leakage) is outside [0, 1]");
  eps.epsilon = NAN;
  EXPECT_TRUE(contains(engine_error({eps}), "epsilon = nan"));
  pisco::Detector z = good;
  z.zeta = INFINITY;
  EXPECT_EQ(engine_error({z}), "detector 'a': zeta = inf is not finite");
  pisco::Detector off = good;
  off.offset = {0.0, 0.0, 0.0, 2.0};
  std::string e = engine_error({off});
  EXPECT_TRUE(contains(e, "detector 'a': the offset quaternion (0, 0, 0, 2) has norm 2 (expected a unit "
                          "quaternion x, y, z, w, to within 1e-06)"))
      << e;
  off.offset = {0.0, 0.0, 0.0, 1.0 + 1e-9};  // rounding: accepted
  EXPECT_EQ(engine_error({off}), "no error");
  off.offset = {0.0, 0.0, 0.0, 1.0 + 1e-5};
  EXPECT_TRUE(contains(engine_error({off}), "has norm 1.00001"));
  pisco::Detector beam = good;
  beam.beam = 1;
  EXPECT_EQ(engine_error({beam}), "detector 'a': beam index 1 but only 1 beamsors were given");
  // The library function itself, as the Engine calls it.
  EXPECT_EQ(error_of([&] { pisco::check_focal_plane(pisco::FocalPlane({good, good}), 1); }),
            "focal plane: detectors 0 and 1 are both named 'a' (expected unique detector names)");
  EXPECT_EQ(error_of([&] { pisco::check_focal_plane(pisco::FocalPlane(), 1); }), "focal plane: no detectors");
}

}  // namespace
