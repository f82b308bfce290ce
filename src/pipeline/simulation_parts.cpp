// The parts pisco::Simulation chains (pisco/simulation.hpp), public so that a program can chain them
// otherwise: the sky, the beams and the engine of a simulation file, and the maps and spectra written.
#include "beams/beam_kind.hpp"
#include "pisco/simulation.hpp"

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
#include "pipeline/run_outputs.hpp"

namespace pisco {

namespace fs = std::filesystem;

fs::path default_data_dir() {
  if (const char* env = std::getenv("PISCO_DATA_DIR")) return env;
  const fs::path installed = PISCO_INSTALL_DATA_DIR;
  std::error_code ec;
  if (fs::exists(installed / "assets", ec)) return installed;
  return PISCO_SOURCE_DIR;
}

namespace {

std::vector<double> read_bb_template(const fs::path& file, int lmax) {
  pisco::detail::require_regular_file(file, "the tensor BB template, a text table of l and D_l");
  std::ifstream in(file);
  if (!in) throw pisco::Error(file.string() + ": cannot open the tensor BB template");
  std::vector<double> cl(static_cast<std::size_t>(lmax) + 1, 0.0);
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    double l, dl;
    if (!(ss >> l >> dl) || !std::isfinite(dl) || !(l >= 0))
      throw pisco::Error(file.string() + ":" + std::to_string(lineno) + ": expected 'l D_l^BB'");
    if (l > lmax) continue;  // also keeps the conversion below within int
    const int il = static_cast<int>(l);
    if (il >= 2 && il <= lmax) cl[il] = 2 * std::numbers::pi * dl / (l * (l + 1));
  }
  return cl;
}

}  // namespace

Sky make_sky(const SkyConfig& s, const fs::path& data_dir) {
  const fs::path assets = data_dir / "assets";
  if (!s.file.empty()) {
    // UNSEEN pixels: an error naming the file's column, or kept for the engine ([sky] unseen).
    pisco::Sky sky = pisco::Sky::read_fits(
        s.file, s.unseen == pisco::UnseenPolicy::error ? pisco::UnseenPolicy::error : pisco::UnseenPolicy::flag);
    if (s.unpolarized) {
      std::fill(sky.Q().begin(), sky.Q().end(), 0.0);
      std::fill(sky.U().begin(), sky.U().end(), 0.0);
    }
    return sky;
  }
  if (!s.point_source.empty()) {
    pisco::Sky sky(s.nside, s.units);
    const std::size_t p = pisco::ang2pix(s.nside, s.point_source[0], s.point_source[1]);
    for (int k = 0; k < 4; ++k) sky.stokes(static_cast<pisco::StokesIndex>(k))[p] = s.point_source[2 + k];
    return sky;
  }
  const int lmax = s.lmax > 0 ? s.lmax : 2 * s.nside;
  pisco::Spectra cls = pisco::read_cl_table(s.cl_file, lmax, true);
  if (s.r > 0) {
    const fs::path tmpl = s.bb_template.empty() ? assets / "spectra" / "tensor_bb_r1.txt" : s.bb_template;
    const std::vector<double> bb = read_bb_template(tmpl, lmax);
    for (int l = 0; l <= lmax; ++l) cls.BB[l] = s.r * bb[l];
  }
  if (s.unpolarized) {
    std::fill(cls.EE.begin(), cls.EE.end(), 0.0);
    std::fill(cls.BB.begin(), cls.BB.end(), 0.0);
    std::fill(cls.TE.begin(), cls.TE.end(), 0.0);
  }
  return pisco::synthesize_sky(cls, s.nside, s.seed);
}

// A beam of the simulation file; `angle` turns GRASP and b_lm beams (a detector's zeta).
Beamsor make_beam(const BeamConfig& b, const fs::path& config, double angle,
                  const std::function<void(const std::string&)>& progress) {
  try {
    pisco::FileBeamOptions fo{b.options.rho_max, b.options.grid_step, angle, b.options.split, {}};
    if (progress) fo.progress = [&](const std::string& line) { progress("beam " + b.name + ": " + line + "\n"); };
    const detail::BeamKindEntry& kind = detail::beam_kind(b.kind);
    if (!kind.make) throw pisco::Error("a beam made of other tables' beams has no beamsor of its own", pisco::ErrorKind::internal);
    return kind.make(b, fo);
  } catch (const pisco::Error& e) {
    throw pisco::Error(config.string() + ": [beams." + b.name + "] " + e.named());
  }
}


SimulationBeams make_beams(const SimulationConfig& c, const std::function<void(const std::string&)>& log) {
  auto say = [&](const char* fmt, auto... args) {
    if (log) log(detail::printf_text(fmt, args...));
  };
  SimulationBeams out;
  std::vector<Beamsor>& beams = out.beams;
  std::vector<std::string>& beam_names = out.names;
  std::vector<Detector>& detectors = out.detectors;
  detectors = c.detectors;
  // Each table's beams as made: one, or one per detector's zeta for a beam that turns with the
  // detector (made when a detector, or a sequence of a detector, first needs it).
  std::vector<std::vector<std::pair<double, std::size_t>>> made(c.beams.size());  // (zeta, beam index)
  const auto beam_for = [&](std::size_t k, double zeta, const Detector* d, bool quiet = false) {
    const BeamConfig& b = c.beams[k];
    if (!b.turns_with_detector()) zeta = 0.0;
    for (const auto& [z, index] : made[k])
      if (z == zeta) return index;
    beams.push_back(make_beam(b, c.source, zeta, log));
    beam_names.push_back(b.name);
    if (!quiet && b.turns_with_detector() && d)
      say("beam %s for zeta %g deg: %s\n", b.name.c_str(), zeta * 180 / std::numbers::pi, beams.back().description().c_str());
    else if (!quiet)
      say("beam %s: %s\n", b.name.c_str(), beams.back().description().c_str());
    // A b_lm file of T alone gives a polarized detector no polarization response: said, unless the
    // table says that this is meant.
    const Beamsor& made_beam = beams.back();
    if (d && b.kind == BeamKind::blm && !b.temperature_only && d->epsilon < 1.0 && !made_beam.has_element(1, 1) &&
        !made_beam.has_element(1, 2) && !made_beam.has_element(2, 1) && !made_beam.has_element(2, 2))
      throw pisco::Error(c.source.string() + ": [beams." + b.name + "] " + b.file.string() +
                         " holds T coefficients alone, so detector '" + d->name +
                         "' (polarization efficiency " + detail::printf_text("%g", 1.0 - d->epsilon) +
                         ") would see no polarization; give a file with T, E and B, or set temperature_only = "
                         "true if a beam without polarization response is meant");
    made[k].emplace_back(zeta, beams.size() - 1);
    return beams.size() - 1;
  };
  for (std::size_t k = 0; k < c.beams.size(); ++k) {
    if (c.beams[k].combines_beams()) continue;
    if (!c.beams[k].turns_with_detector()) beam_for(k, 0.0, nullptr);
    for (std::size_t i = 0; i < detectors.size(); ++i)
      if (c.detectors[i].beam == k) detectors[i].beam = beam_for(k, c.detectors[i].zeta, &c.detectors[i]);
    if (made[k].empty()) beam_for(k, 0.0, nullptr, true);  // checked, though no detector uses it
  }
  // Beams that change with time or turn with the plate: each detector's beams, those of the tables
  // they name (checked to exist when the file was read, check_combined_beams).
  const auto table = [&](const std::string& name) {
    return std::size_t(std::find_if(c.beams.begin(), c.beams.end(), [&](const BeamConfig& x) { return x.name == name; }) -
                       c.beams.begin());
  };
  for (std::size_t k = 0; k < c.beams.size(); ++k) {
    const BeamConfig& b = c.beams[k];
    if (!b.combines_beams()) continue;
    for (std::size_t i = 0; i < detectors.size(); ++i) {
      if (c.detectors[i].beam != k) continue;
      std::vector<std::size_t> made_nodes;
      for (const std::string& name : b.nodes) made_nodes.push_back(beam_for(table(name), c.detectors[i].zeta, &c.detectors[i]));
      Detector& d = detectors[i];
      d.beam = made_nodes.front();
      if (b.kind == BeamKind::sequence) {
        d.beam_sequence.clear();
        for (std::size_t n = 0; n < made_nodes.size(); ++n) d.beam_sequence.push_back({b.node_times[n], made_nodes[n]});
        continue;
      }
      // The plate is in the beams, at plate angles from the detector's own plate gamma ([hwp]'s).
      if (!d.hwp)
        throw pisco::Error(c.source.string() + ": detector '" + d.name + "' has the beam " + b.name +
                           ", which turns with the plate, but its half-wave plate is off (hwp = false)");
      d.plate_beams = pisco::PlateBeams{made_nodes, b.plate_period, d.hwp->gamma};
      if (!b.plate_normalize_by.empty()) {  // the beam without the plate: its Omega~ keeps the plate's losses
        d.plate_beams->omega = out.beams[beam_for(table(b.plate_normalize_by), c.detectors[i].zeta, &c.detectors[i])].omega_tilde();
      }
      d.hwp.reset();
    }
  }
  return out;
}

Sky make_ground_sky(const GroundConfig& g, const Sky& sky, const fs::path& origin) {
  const std::string where = origin.string() + ": [ground] ";
  if (!g.file.empty()) {
    pisco::Sky ground = pisco::Sky::read_fits(g.file, pisco::UnseenPolicy::error);
    if (!ground.units().empty() && !sky.units().empty() && ground.units() != sky.units())
      throw pisco::Error(where + "file: " + g.file.string() + " is in '" + ground.units() + "', the sky in '" +
                         sky.units() + "' (expected the sky's units: the two add up in one TOD)");
    ground.set_units(sky.units());
    return ground;
  }
  pisco::GroundModel model = g.model;
  try {
    model.value = pisco::rayleigh_jeans_in(sky.units(), g.temperature, g.frequency_ghz);
  } catch (const pisco::Error& e) {
    throw pisco::Error(where + "temperature_k: " + e.what() + (g.frequency_ghz > 0 ? "" : " (frequency_ghz)"));
  }
  return pisco::ground_sky(g.nside, model, sky.units());
}

Engine make_engine(const SkyView& sky, const std::vector<Beamsor>& beams, const FocalPlane& fp, const SimulationConfig& c,
                   const RunContext& cl) {
  EngineOptions engine_options = c.engine.options;
  engine_options.unseen = c.sky.unseen;
  // Each process of a node takes its share of the host's threads, or its own device; true if that
  // changed the options.
  auto share_out = [&](const std::string& backend, pisco::EngineOptions& o) {
    if (cl.node_size() <= 1) return false;
    for (const auto& b : pisco::Engine::backends()) {
      if (b.name != backend) continue;
      if (pisco::backend_has_setting(backend, "threads")) {  // the host's threads are what the processes share
        if (o.number("threads") == 0) {
          o.settings["threads"] = (long long)std::max(1u, std::thread::hardware_concurrency() / unsigned(cl.node_size()));
          return true;
        }
      } else if (pisco::backend_has_setting(backend, "device") && o.text("device") == "auto" &&
                 !b.devices.empty()) {
        o.settings["device"] = std::to_string(b.devices[std::size_t(cl.node_rank()) % b.devices.size()]);
        return true;
      }
    }
    return false;
  };
  pisco::EngineOptions o = engine_options;
  if (o.backend != "auto") share_out(o.backend, o);
  std::optional<Engine> engine_holder;
  engine_holder.emplace(sky, beams, fp, o);
  if (engine_options.backend == "auto") {
    o = pisco::options_for_backend(o, engine_holder->backend_name());  // its settings alone, now named
    if (share_out(o.backend, o)) {
      engine_holder.reset();
      engine_holder.emplace(sky, beams, fp, o);
    }
  }
  return std::move(*engine_holder);
}

double disc_pixels(const Beamsor& beam, int sky_nside, int sidelobe_nside) {
  const double npix = 12.0 * double(sky_nside) * double(sky_nside);
  double disc = std::max(1.0, 0.5 * (1 - std::cos(beam.rho_max())) * npix);
  if (const Beamsor* outer = beam.sidelobes())  // a split beam's outer part, on the coarser sky
    disc += 0.5 * (1 - std::cos(outer->rho_max())) * 12.0 * sidelobe_nside * sidelobe_nside;
  return disc;
}

int maps_nside(const SimulationConfig& c, const Sky& sky) {
  return c.output.maps_nside > 0 ? c.output.maps_nside : c.scan.kind == ScanKind::file ? sky.nside() : c.scan.nside;
}

// Beam window for the spectra: exact for a Gaussian; the Gaussian of the geometric-mean width for
// an elliptical beam (the leading term of its mean radial profile); none for beams from files.
std::optional<double> window_fwhm(const BeamConfig& b) {
  if (b.kind == BeamKind::gaussian) return b.fwhm;
  if (b.kind == BeamKind::elliptical) return std::sqrt(b.fwhm_x * b.fwhm_y);
  return std::nullopt;
}

// Written whole or not at all (pisco::write_file_atomically): a full disk is an error naming the file.
void write_spectra(const fs::path& file, const pisco::Spectra& s, int lmax, const std::string& header) {
  pisco::check_finite(s, file.string(), 2, lmax);
  std::string text = "# " + header + "\n# l  D_l = l(l+1)C_l/2pi:  TT EE BB TE EB TB\n";
  char buf[256];
  for (int l = 2; l <= lmax; ++l) {
    const double f = l * (l + 1.0) / (2 * std::numbers::pi);
    std::snprintf(buf, sizeof buf, "%d %.10e %.10e %.10e %.10e %.10e %.10e\n", l, f * s.TT[l], f * s.EE[l],
                  f * s.BB[l], f * s.TE[l], f * s.EB[l], f * s.TB[l]);
    text += buf;
  }
  pisco::write_file_atomically(file, text);
}

std::size_t write_maps(const fs::path& dir, const BinnedMaps& maps, int nside, const std::string& units) {
  const fs::path maps_path = dir / "maps.fits", hits_path = dir / "hits.fits";
  write_healpix_map(maps_path, nside, {{"I_STOKES", maps.I}, {"Q_STOKES", maps.Q}, {"U_STOKES", maps.U}}, units);
  std::vector<double> hits(maps.hits.begin(), maps.hits.end());
  write_healpix_map(hits_path, nside, {{"HITS", hits}}, "samples");
  return static_cast<std::size_t>(std::count_if(maps.I.begin(), maps.I.end(), [](double v) { return v != unseen; }));
}

// The spectra of the solved maps (spectra.txt, the windows divided out as [output] says) and of the input
// sky (input_spectra.txt), in [output] dir.

std::vector<fs::path> write_spectra_files(const SimulationConfig& c, const Sky& sky, const BinnedMaps& maps,
                                          int maps_nside) {
  return detail::spectra_files(c, sky, maps.I, maps.Q, maps.U, maps_nside, "binned maps",
                       window_fwhm(c.beams[c.detectors.front().beam]));
}

}  // namespace pisco
