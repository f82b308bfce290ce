// The bundled quick-start: a small end-to-end simulation through the library's public API.
// A Gaussian r = 0 CMB sky (NSIDE 128, from healpy-data's totcls.dat) is observed by one PSB pair
// with a 1.5 deg Gaussian beam at every NSIDE 64 pixel centre at psi = 0, 45, 90 deg; the TOD
// streams into a binned map-maker; the maps' spectra, divided by the beam window, are compared with
// the input's. Writes the input sky and the output maps as HEALPix FITS files.
//   usage: pisco-quickstart [OUTPUT_DIR] [--backend NAME]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <numbers>
#include <string>

#include "pisco/pisco.hpp"

namespace {
constexpr double deg = std::numbers::pi / 180;
double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}
double dl(int l, double cl) { return l * (l + 1.0) * cl / (2 * std::numbers::pi); }
}  // namespace

int main(int argc, char** argv) try {
  std::filesystem::path out_dir = "pisco-quickstart-out";
  std::string backend = "auto";
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--backend") && i + 1 < argc) {
      backend = argv[++i];
    } else if (!std::strcmp(argv[i], "--help") || !std::strcmp(argv[i], "-h")) {
      std::puts("usage: pisco-quickstart [OUTPUT_DIR] [--backend NAME]\n"
                "Observes a synthesized CMB sky with a PSB pair, makes maps and compares spectra.");
      return 0;
    } else {
      out_dir = argv[i];
    }
  }
  std::printf("PISCO-VK %s quick-start\n", pisco::version);
  const auto t0 = std::chrono::steady_clock::now();
  const int nside_sky = 128, nside_out = 64;
  const double fwhm = 1.5 * deg;
  const pisco::Spectra cls = pisco::read_cl_table(pisco::default_cl_file(), 2 * nside_sky, true);
  const pisco::Sky sky = pisco::synthesize_sky(cls, nside_sky, 42);
  std::printf("sky: NSIDE %d Gaussian CMB from %s, r = 0, seed 42\n", nside_sky,
              pisco::default_cl_file().string().c_str());

  pisco::BeamOptions beam_options;
  beam_options.rho_max = 5 * deg;
  const std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(fwhm, beam_options)};
  pisco::FocalPlane focal_plane;
  focal_plane.add_pair("q1", 0.0, 0, 0);
  pisco::Engine engine(sky, beams, focal_plane, {.backend = backend});
  std::printf("beam: %s\nbackend: %s (%s)\n", beams[0].description().c_str(), engine.backend_name().c_str(),
              engine.device_name().c_str());

  const pisco::Pointing scan = pisco::pixel_centre_scan(nside_out, {0.0, 45 * deg, 90 * deg});
  pisco::BinnedMapmaker mapper(nside_out);
  std::vector<double> tod(scan.size());
  const auto t1 = std::chrono::steady_clock::now();
  for (std::size_t d = 0; d < focal_plane.size(); ++d) {
    engine.convolve(d, scan, tod);
    mapper.add(focal_plane[d], scan, tod);
  }
  const double conv = since(t1);
  const double samples = double(scan.size() * focal_plane.size());
  std::printf("TOD: %.0f samples, %.1f pixels per disc, %.2f s: %.3g samples/s, %.3g pixel evaluations/s\n",
              samples, engine.mean_disc_pixels(), conv, samples / conv, samples * engine.mean_disc_pixels() / conv);

  const pisco::BinnedMaps maps = mapper.solve();
  const auto solved = std::count_if(maps.I.begin(), maps.I.end(), [](double v) { return v != pisco::unseen; });
  std::printf("maps: NSIDE %d, %td of %zu pixels solved\n", nside_out, solved, maps.I.size());

  const int lmax = 3 * nside_out - 1, lcmp = 96;
  const pisco::Spectra out = pisco::deconvolve_windows(
      pisco::anafast(maps.I, maps.Q, maps.U, nside_out, lmax), pisco::gaussian_beam_window(fwhm, lmax, false),
      pisco::gaussian_beam_window(fwhm, lmax, true), {}, {});
  const pisco::Spectra in = pisco::anafast(sky.I(), sky.Q(), sky.U(), nside_sky, lmax);
  double dtt = 0, dee = 0, bb = 0;
  for (int l = 2; l <= lcmp; ++l) {
    dtt = std::max(dtt, std::abs(dl(l, out.TT[l] - in.TT[l])));
    dee = std::max(dee, std::abs(dl(l, out.EE[l] - in.EE[l])));
    bb = std::max(bb, std::abs(dl(l, out.BB[l])));
  }
  std::printf("spectra, 2 <= l <= %d, beam-deconvolved output minus input: max |dD_l| TT %.3g, EE %.3g uK^2; "
              "max output BB %.3g uK^2 (input r = 0)\n", lcmp, dtt, dee, bb);

  std::filesystem::create_directories(out_dir);
  sky.write_fits(out_dir / "input_sky.fits");
  pisco::Sky out_maps(nside_out, sky.units());
  std::copy(maps.I.begin(), maps.I.end(), out_maps.I().begin());
  std::copy(maps.Q.begin(), maps.Q.end(), out_maps.Q().begin());
  std::copy(maps.U.begin(), maps.U.end(), out_maps.U().begin());
  out_maps.write_fits(out_dir / "binned_maps.fits");
  std::printf("wrote %s and %s\n", (out_dir / "input_sky.fits").string().c_str(),
              (out_dir / "binned_maps.fits").string().c_str());
  std::printf("total wall time %.1f s\n", since(t0));
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "pisco-quickstart: %s\n", e.what());
  return 1;
}
