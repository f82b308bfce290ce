// What a run writes beside its TOD (run_outputs.hpp).
#include "pipeline/run_outputs.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <thread>
#include <vector>
#include <unistd.h>

#include "core/detector_pointing.hpp"
#include "core/text.hpp"
#include "core/thread_pool.hpp"
#include "io/input_file.hpp"
#include "pisco/deconvolution.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/output_file.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/scan.hpp"
#include "pisco/tod_file.hpp"
#include "pisco/version.hpp"

namespace pisco::detail {
namespace {

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

}  // namespace

// The spectra files of maps I, Q, U: `note` says what the maps are, `fw` the Gaussian beam window
// [output] deconvolve_beam divides out (none: nullopt).
std::vector<fs::path> spectra_files(const SimulationConfig& c, const Sky& sky, const std::vector<double>& I,
                                    const std::vector<double>& Q, const std::vector<double>& U, int maps_nside,
                                    std::string note, std::optional<double> fw) {
  const int lmax = c.output.lmax > 0 ? c.output.lmax : 2 * maps_nside;
  const int lmax_sky = std::min(lmax, 3 * sky.nside() - 1);
  const pisco::Spectra out = pisco::anafast(I, Q, U, maps_nside, lmax);
  std::vector<double> bt, bp, pt, pp;
  if (c.output.deconvolve_beam && fw) {
    bt = pisco::gaussian_beam_window(*fw, lmax, false);
    bp = pisco::gaussian_beam_window(*fw, lmax, true);
    note += ", divided by the Gaussian beam window of FWHM " + std::to_string(*fw * 180 / std::numbers::pi) + " deg";
  }
  if (c.output.deconvolve_pixel_window) {
    pt = pisco::pixel_window(maps_nside, lmax, false);
    pp = pisco::pixel_window(maps_nside, lmax, true);
    note += ", divided by the NSIDE " + std::to_string(maps_nside) + " pixel window";
  }
  const fs::path spectra_path = c.output.dir / "spectra.txt", input_path = c.output.dir / "input_spectra.txt";
  write_spectra(spectra_path, pisco::deconvolve_windows(out, bt, bp, pt, pp), lmax, note);
  write_spectra(input_path, pisco::anafast(sky.I(), sky.Q(), sky.U(), sky.nside(), lmax_sky), lmax_sky,
                "input sky");
  return {spectra_path, input_path};
}

// The half-wave plate's figure of a run's binned maps: their polarization against their temperature
// (on an unpolarized sky, the plate's leakage of temperature into polarization as the map-maker's
// model leaves it), as a line of the run's account.
std::string hwp_figure(const BinnedMaps& maps, std::size_t solved, const std::string& units, bool ideal_mapmaker) {
  double ii = 0, qq = 0, uu = 0, mean_i = 0;
  for (std::size_t p = 0; p < maps.I.size(); ++p)
    if (maps.I[p] != pisco::unseen) mean_i += maps.I[p];
  mean_i /= double(solved);
  for (std::size_t p = 0; p < maps.I.size(); ++p)
    if (maps.I[p] != pisco::unseen) {
      ii += (maps.I[p] - mean_i) * (maps.I[p] - mean_i);
      qq += maps.Q[p] * maps.Q[p];
      uu += maps.U[p] * maps.U[p];
    }
  const double ri = std::sqrt(ii / double(solved)), rq = std::sqrt(qq / double(solved)), ru = std::sqrt(uu / double(solved));
  return detail::printf_text("hwp: maps' rms Q %.3g, U %.3g, I (mean removed) %.3g %s: leakage figure rms P / rms I = %.3g%s\n", rq,
                ru, ri, units.c_str(), std::hypot(rq, ru) / ri,
                ideal_mapmaker ? " (maps binned with an ideal plate's model)" : "");
}

// Why binned maps that solve no pixel solve none: no sample reached them, or too few angles.
std::string unsolved_reason(const BinnedMaps& maps, int maps_nside, bool flagging, double rcond_min) {
  const auto hit = std::count_if(maps.hits.begin(), maps.hits.end(), [](std::uint32_t h) { return h > 0; });
  const std::string outcome = "; maps.fits is all UNSEEN, and no spectra or plots were made";
  if (hit == 0)
    return std::string("the maps solve no pixel: ") + (flagging ? "every sample is flagged" : "no sample reached the maps") +
           outcome;
  return "the maps solve no pixel: " + std::to_string(hit) + " of " + std::to_string(maps.I.size()) + " NSIDE " +
         std::to_string(maps_nside) + " pixels are hit" + (flagging ? " by unflagged samples" : "") +
         ", none with rcond >= " + detail::printf_text("%g", rcond_min) +
         " (each pixel needs three or more polarization angles: one detector or pair without a "
         "half-wave plate or a boresight rotation cannot tell Q from U)" +
         outcome;
}

// The TOD file (tod.h5) of a run: its attributes (units, NSIDE, beams, backend, device, version, time
// and the simulation file's text) and, under MPI, one file for all ranks.
std::optional<pisco::TodWriter> open_tod_file(const SimulationConfig& c, const fs::path& tod_path, const Sky& sky,
                                              const SimulationBeams& made, const Engine& engine, const FocalPlane& fp,
                                              std::size_t samples_per_detector, bool flagging, RunContext& cl) {
  const std::vector<Beamsor>& beams = made.beams;
  const std::vector<std::string>& beam_names = made.names;
  std::optional<pisco::TodWriter> tod_file;
  std::string beam_desc;
  for (std::size_t i = 0; i < beams.size(); ++i)
    beam_desc += (i ? "; " : "") + beam_names[i] + ": " + beams[i].description();
  const std::map<std::string, std::string> attributes{{"units", sky.units()},
                                                      {"nside", std::to_string(sky.nside())},
                                                      {"beam", beam_desc},
                                                      {"backend", engine.backend_name()},
                                                      {"device", engine.device_name()},
                                                      {"pisco_version", pisco::version},
                                                      {"created", utc_now()},
                                                      {"config", c.text}};
  if (!cl.parallel()) {
    tod_file.emplace(tod_path, fp, samples_per_detector, c.output.tod_precision, c.output.tod_pointing, attributes,
                     flagging, c.output.tod_weights);
  } else {
    // One file for all ranks (parallel HDF5): rank 0 creates it whole, then every rank opens it and
    // writes its own samples; rank 0 renames it once every rank has closed it.
    pisco::SharedTodOptions shared;
    shared.temporary_suffix = cl.broadcast(pisco::temporary_suffix());  // the one the lock records
    shared.leader = cl.leader();
    shared.mpi_communicator = cl.mpi_communicator();
    shared.barrier = [&cl] { cl.barrier(); };
    cl.step([&] {
      if (cl.leader())
        pisco::TodWriter::create_shared(tod_path, fp, samples_per_detector, c.output.tod_precision,
                                        c.output.tod_pointing, attributes, flagging, shared.temporary_suffix,
                                        c.output.tod_weights);
    });
    cl.step([&] {
      tod_file.emplace(pisco::TodWriter::open_shared(tod_path, fp, samples_per_detector, c.output.tod_precision,
                                                     c.output.tod_pointing, flagging, shared,
                                                     c.output.tod_weights));
    });
  }
  return tod_file;
}


// The deconvolving map-maker's maps: maps.fits holds the solution, reconvolved with the target beam
// when one is given (then the solution itself in deconvolved.fits); binned_maps.fits and hits.fits
// from the binned map-maker beside it; the spectra of maps.fits.
MapOutputs write_deconvolved_maps(const SimulationConfig& c, const Sky& sky, int maps_nside, const pisco::DeconvolvedMaps& d,
                                  pisco::BinnedMapmaker& binned_mapmaker,
                                  const std::function<void(const std::string&)>& log) {
  MapOutputs out;
  const bool target = !d.smoothed_I.empty();
  const std::vector<double>& I = target ? d.smoothed_I : d.I;
  const std::vector<double>& Q = target ? d.smoothed_Q : d.Q;
  const std::vector<double>& U = target ? d.smoothed_U : d.U;
  const fs::path maps_path = c.output.dir / "maps.fits", raw_path = c.output.dir / "deconvolved.fits";
  write_healpix_map(maps_path, maps_nside, {{"I_STOKES", I}, {"Q_STOKES", Q}, {"U_STOKES", U}}, sky.units());
  out.written.push_back(maps_path);
  if (target) {
    write_healpix_map(raw_path, maps_nside, {{"I_STOKES", d.I}, {"Q_STOKES", d.Q}, {"U_STOKES", d.U}, {"V_STOKES", d.V}},
                      sky.units());
    out.written.push_back(raw_path);
  }
  const BinnedMaps binned = binned_mapmaker.solve();
  const fs::path binned_path = c.output.dir / "binned_maps.fits", hits_path = c.output.dir / "hits.fits";
  write_healpix_map(binned_path, maps_nside, {{"I_STOKES", binned.I}, {"Q_STOKES", binned.Q}, {"U_STOKES", binned.U}},
                    sky.units());
  std::vector<double> hits(binned.hits.begin(), binned.hits.end());
  write_healpix_map(hits_path, maps_nside, {{"HITS", hits}}, "samples");
  out.written.push_back(binned_path);
  out.written.push_back(hits_path);
  out.solved = static_cast<std::size_t>(std::count_if(I.begin(), I.end(), [](double v) { return v != unseen; }));
  log(detail::printf_text("maps: NSIDE %d, %zu of %zu pixels reached by the beams (deconvolved%s); binned_maps.fits beside them\n",
             maps_nside, out.solved, I.size(), target ? ", reconvolved; deconvolved.fits holds the solution" : ""));
  if (out.solved == 0)
    out.nothing_solved = "the deconvolved maps reach no pixel; maps.fits is all UNSEEN, and no spectra or plots were made";
  if (c.output.spectra && out.nothing_solved.empty()) {
    std::optional<double> fw;
    if (target) fw = c.mapmaker.target_fwhm;
    for (const auto& f :
         spectra_files(c, sky, I, Q, U, maps_nside, target ? "deconvolved maps, reconvolved" : "deconvolved maps", fw))
      out.written.push_back(f);
  }
  return out;
}

// The binned map-maker's maps (maps.fits, hits.fits), the plate's figure and the spectra.
MapOutputs write_binned_maps(const SimulationConfig& c, const Sky& sky, int maps_nside, pisco::BinnedMapmaker& mapmaker,
                             bool flagging, const std::function<void(const std::string&)>& log) {
  MapOutputs out;
  const BinnedMaps maps = mapmaker.solve();
  out.solved = write_maps(c.output.dir, maps, maps_nside, sky.units());
  out.written.push_back(c.output.dir / "maps.fits");
  out.written.push_back(c.output.dir / "hits.fits");
  log(detail::printf_text("maps: NSIDE %d, %td of %zu pixels solved (rcond >= %g)\n", maps_nside,
             static_cast<std::ptrdiff_t>(out.solved), maps.I.size(), c.output.rcond_min));
  if (c.hwp.enabled && out.solved > 0) log(hwp_figure(maps, out.solved, sky.units(), c.hwp.ideal_mapmaker));
  if (out.solved == 0) out.nothing_solved = unsolved_reason(maps, maps_nside, flagging, c.output.rcond_min);
  if (c.output.spectra && out.nothing_solved.empty())
    for (const auto& f : write_spectra_files(c, sky, maps, maps_nside)) out.written.push_back(f);
  return out;
}

std::vector<fs::path> write_ground_maps(const SimulationConfig& c, const Sky& sky, int maps_nside,
                                        pisco::BinnedMapmaker& ground, const std::function<void(const std::string&)>& log) {
  const BinnedMaps maps = ground.solve();
  const fs::path maps_path = c.output.dir / "ground_maps.fits";
  write_healpix_map(maps_path, maps_nside, {{"I_STOKES", maps.I}, {"Q_STOKES", maps.Q}, {"U_STOKES", maps.U}},
                    sky.units());
  std::vector<fs::path> written{maps_path};
  double ii = 0, pp = 0, mean = 0;
  std::size_t n = 0;
  for (std::size_t p = 0; p < maps.I.size(); ++p)
    if (maps.I[p] != pisco::unseen) mean += maps.I[p], ++n;
  if (n == 0) return written;
  mean /= double(n);
  for (std::size_t p = 0; p < maps.I.size(); ++p)
    if (maps.I[p] != pisco::unseen) {
      ii += (maps.I[p] - mean) * (maps.I[p] - mean);
      pp += maps.Q[p] * maps.Q[p] + maps.U[p] * maps.U[p];
    }
  log(detail::printf_text("ground: in the maps (ground_maps.fits, the ground's TOD alone binned): mean I %.4g, rms I "
                          "about it %.4g, rms P %.4g %s\n",
                          mean, std::sqrt(ii / double(n)), std::sqrt(pp / double(n)), sky.units().c_str()));
  if (c.output.spectra) {
    const int lmax = c.output.lmax > 0 ? c.output.lmax : 2 * maps_nside;
    std::vector<double> bt, bp, pt, pw;
    std::string note = "the ground's TOD alone, binned as maps.fits";
    if (c.output.deconvolve_pixel_window) {
      pt = pisco::pixel_window(maps_nside, lmax, false);
      pw = pisco::pixel_window(maps_nside, lmax, true);
      note += ", divided by the NSIDE " + std::to_string(maps_nside) + " pixel window";
    }
    const fs::path spectra_path = c.output.dir / "ground_spectra.txt";
    write_spectra(spectra_path, pisco::deconvolve_windows(pisco::anafast(maps.I, maps.Q, maps.U, maps_nside, lmax), bt, bp, pt, pw),
                  lmax, note);
    written.push_back(spectra_path);
  }
  return written;
}

}  // namespace pisco::detail
