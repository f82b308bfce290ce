// pisco::Simulation (simulation.hpp): sky -> TOD -> binned maps -> spectra, streaming the TOD chunk by
// chunk through the map-maker and the TOD file, so memory stays bounded whatever the length of the scan.
#include "pisco/simulation.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <numbers>
#include <span>
#include <sstream>
#include <thread>
#include <unistd.h>

#include "io/input_file.hpp"
#include "core/detector_pointing.hpp"
#include "core/thread_pool.hpp"
#include "pisco/deconvolution.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/output_file.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/scan.hpp"
#include "pisco/tod_file.hpp"
#include "pisco/version.hpp"

namespace pisco {

namespace fs = std::filesystem;

void RunContext::agree(const std::optional<std::string>& error) {
  if (error) throw Error(*error);
}

RunContext& serial_run_context() {
  static RunContext context;
  return context;
}

fs::path default_data_dir() {
  if (const char* env = std::getenv("PISCO_DATA_DIR")) return env;
  const fs::path installed = PISCO_INSTALL_DATA_DIR;
  std::error_code ec;
  if (fs::exists(installed / "assets", ec)) return installed;
  return PISCO_SOURCE_DIR;
}

namespace {

// printf into a string.
template <typename... Args>
std::string format(const char* fmt, Args... args) {
  const int n = std::snprintf(nullptr, 0, fmt, args...);
  if (n <= 0) return {};
  std::string s(static_cast<std::size_t>(n) + 1, '\0');
  std::snprintf(s.data(), s.size(), fmt, args...);
  s.resize(static_cast<std::size_t>(n));
  return s;
}

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

// One chunk of boresight pointing, in the form its scan produces: angles for the generated ground and
// test scans, quaternions for the satellite scan and pointing files.
struct BoresightChunk {
  pisco::Pointing angles;
  std::vector<pisco::Quat> quats;
  std::vector<double> hwp;  // the half-wave plate's angle per sample, with [hwp]
  // The angles as quaternions, for the binned map-maker (BinnedMapmaker::add_from_boresight), made
  // once per chunk for all detectors when the stream asks for them (JobPointing::boresight_quats).
  std::vector<pisco::Quat> angle_quats;
  bool angle_quats_made = false;
  bool quaternions = false;
  std::size_t first = 0;
  std::size_t size() const { return quaternions ? quats.size() : angles.size(); }
};

// The boresight pointing of the scan, produced chunk by chunk (a week of constant-elevation
// scanning, a year of satellite scanning or a season's pointing file is never held in memory whole).
class Boresight {
 public:
  Boresight(const ScanConfig& s, const HwpConfig& hwp) : scan_(s), hwp_(hwp) {
    if (s.kind == ScanKind::pixel_centres) all_ = pisco::pixel_centre_scan(s.nside, s.psi);
    else if (s.kind == ScanKind::random_offsets) all_ = pisco::random_offset_scan(s.nside, s.psi, s.f, s.seed, s.symmetric);
    else if (s.kind == ScanKind::raster) all_ = pisco::raster_scan(s.theta, s.phi, s.radius, s.nside, s.psi);
    else if (s.kind == ScanKind::file) file_.emplace(s.file);
    if (hwp_.angles_from_file && !(file_ && file_->has_hwp_angle()))
      throw pisco::Error(s.file.string() + ": [hwp] gives no rotation or steps, and the pointing file has no "
                                           "'hwp_angle' dataset (expected one of them)");
  }
  bool quaternions() const { return scan_.kind == ScanKind::satellite || file_.has_value(); }
  std::size_t size() const {
    if (scan_.kind == ScanKind::ces) return scan_.ces.samples;
    if (scan_.kind == ScanKind::satellite) return scan_.satellite.samples;
    if (file_) return file_->size();
    return all_.size();
  }
  // With `pool`, the generated scans (constant-elevation and satellite, whose samples do not depend on
  // each other) in blocks of samples on its threads: the same values.
  void fill(std::size_t first, std::size_t count, BoresightChunk& out, pisco::detail::ThreadPool* pool = nullptr) const {
    out.first = first;
    out.quaternions = quaternions();
    constexpr std::size_t block = 4096;
    const bool spread = pool && pool->size() > 1 && count > block;
    if (scan_.kind == ScanKind::ces && spread) {
      for (auto* v : {&out.angles.theta, &out.angles.phi, &out.angles.psi}) v->resize(count);
      pool->parallel_for(count, block, [&](std::size_t begin, std::size_t end) {
        pisco::Pointing part;
        scan_.ces.generate(first + begin, end - begin, part);
        std::copy(part.theta.begin(), part.theta.end(), out.angles.theta.begin() + std::ptrdiff_t(begin));
        std::copy(part.phi.begin(), part.phi.end(), out.angles.phi.begin() + std::ptrdiff_t(begin));
        std::copy(part.psi.begin(), part.psi.end(), out.angles.psi.begin() + std::ptrdiff_t(begin));
      });
    } else if (scan_.kind == ScanKind::satellite && spread) {
      out.quats.resize(count);
      pool->parallel_for(count, block, [&](std::size_t begin, std::size_t end) {
        std::vector<pisco::Quat> part;
        scan_.satellite.generate(first + begin, end - begin, part);
        std::copy(part.begin(), part.end(), out.quats.begin() + std::ptrdiff_t(begin));
      });
    } else if (scan_.kind == ScanKind::ces) scan_.ces.generate(first, count, out.angles);
    else if (scan_.kind == ScanKind::satellite) scan_.satellite.generate(first, count, out.quats);
    else if (file_) file_->read(first, count, out.quats);
    else {
      const pisco::PointingView v = all_.view().subspan(first, count);
      out.angles.theta.assign(v.theta.begin(), v.theta.end());
      out.angles.phi.assign(v.phi.begin(), v.phi.end());
      out.angles.psi.assign(v.psi.begin(), v.psi.end());
    }
    out.angle_quats_made = false;
    out.hwp.clear();
    if (hwp_.angles_from_file) file_->read_hwp_angle(first, count, out.hwp);
    else if (hwp_.enabled) hwp_.stream.generate(first, count, out.hwp);
  }

 private:
  ScanConfig scan_;
  HwpConfig hwp_;
  pisco::Pointing all_;
  std::optional<pisco::BoresightFile> file_;
};


// The jobs of a run (a detector's span of samples), in the order one process runs them: time spans
// outermost (each boresight chunk made once for all detectors), or, with per-detector pointing files,
// detectors outermost. Under MPI the spans are shortened until there are at least 4 jobs per rank,
// and each rank takes a contiguous run of jobs of about equal cost, a job costing its samples times
// its detector's disc pixels (disc(detector)). The jobs are never listed (a season is 1e9 of them):
// job i of the run is at(i).
struct JobPlan {
  struct Span {
    std::size_t detector = 0, first = 0, count = 0;
  };
  std::size_t ndet = 0, samples = 0, span = 0, spans = 0, njobs = 0;
  bool detectors_outermost = false;
  std::size_t my_first = 0, my_end = 0, rounds = 0;  // this rank's jobs [my_first, my_end); the most any rank has
  Span at(std::size_t i) const {
    const std::size_t d = detectors_outermost ? i / spans : i % ndet, s = detectors_outermost ? i % spans : i / ndet;
    return Span{d, s * span, std::min(span, samples - s * span)};
  }
};

JobPlan plan_jobs(std::size_t ndet, std::size_t samples, std::size_t chunk, bool detectors_outermost,
                  const RunContext& cl, const std::function<double(std::size_t)>& disc) {
  auto ceil_div = [](std::size_t a, std::size_t b) { return (a + b - 1) / b; };
  JobPlan p;
  p.ndet = ndet;
  p.samples = samples;
  p.detectors_outermost = detectors_outermost;
  p.span = chunk;
  if (cl.parallel() && samples > 0) {
    const std::size_t spans_needed = ceil_div(4 * std::size_t(cl.size()), std::max<std::size_t>(ndet, 1));
    p.span = std::max<std::size_t>(1, std::min(chunk, ceil_div(samples, spans_needed)));
  }
  p.spans = samples == 0 ? 0 : ceil_div(samples, p.span);
  p.njobs = p.spans * ndet;
  if (!cl.parallel()) {
    p.my_end = p.rounds = p.njobs;
    return p;
  }
  std::vector<double> cost_of(ndet);
  for (std::size_t d = 0; d < ndet; ++d) cost_of[d] = disc(d);
  double all = 0;
  for (std::size_t i = 0; i < p.njobs; ++i) {
    const JobPlan::Span j = p.at(i);
    all += double(j.count) * cost_of[j.detector];
  }
  std::vector<std::size_t> per_rank(std::size_t(cl.size()), 0);
  double before = 0;
  p.my_first = p.njobs;
  for (std::size_t i = 0; i < p.njobs; ++i) {
    const JobPlan::Span j = p.at(i);
    const double cost = double(j.count) * cost_of[j.detector];
    const int owner = all > 0 ? std::min(cl.size() - 1, int((before + 0.5 * cost) / all * cl.size())) : 0;
    before += cost;
    ++per_rank[std::size_t(owner)];
    if (owner == cl.rank()) {
      p.my_first = std::min(p.my_first, i);
      p.my_end = i + 1;
    }
  }
  if (p.my_first > p.my_end) p.my_first = p.my_end;
  p.rounds = *std::max_element(per_rank.begin(), per_rank.end());
  return p;
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
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
    if (b.kind == BeamKind::gaussian) return pisco::Beamsor::gaussian(b.fwhm, b.options);
    if (b.kind == BeamKind::elliptical) return pisco::Beamsor::elliptical_gaussian(b.fwhm_x, b.fwhm_y, b.angle, b.options);
    pisco::FileBeamOptions fo{b.options.rho_max, b.options.grid_step, angle, b.options.split, {}};
    if (progress) fo.progress = [&](const std::string& line) { progress("beam " + b.name + ": " + line + "\n"); };
    if (b.kind == BeamKind::blm) return pisco::Beamsor::from_harmonic(pisco::HarmonicBeam::read_fits(b.file), fo);
    if (b.kind == BeamKind::grasp) {
      const auto all = pisco::GraspBeam::read(b.file);
      if (b.set == 0 && all.size() > 1)
        throw pisco::Error(b.file.string() + " holds " + std::to_string(all.size()) +
                           " beams (field sets or frequencies): choose one with set = 1.." + std::to_string(all.size()));
      if (b.set > static_cast<int>(all.size()))
        throw pisco::Error("set = " + std::to_string(b.set) + ", but " + b.file.string() + " holds " +
                           std::to_string(all.size()) + " beam" + (all.size() > 1 ? "s" : ""));
      return pisco::Beamsor::from_grasp(all[static_cast<std::size_t>(std::max(b.set, 1) - 1)], fo);
    }
    return pisco::Beamsor::read_healpix_fits(b.file, b.options.rho_max, b.options.grid_step);
  } catch (const pisco::Error& e) {
    throw pisco::Error(config.string() + ": [beams." + b.name + "] " + e.what());
  }
}


SimulationBeams make_beams(const SimulationConfig& c, const std::function<void(const std::string&)>& log) {
  auto say = [&](const char* fmt, auto... args) {
    if (log) log(format(fmt, args...));
  };
  SimulationBeams out;
  std::vector<Beamsor>& beams = out.beams;
  std::vector<std::string>& beam_names = out.names;
  std::vector<Detector>& detectors = out.detectors;
  detectors = c.detectors;
  for (std::size_t k = 0; k < c.beams.size(); ++k) {
    const auto& b = c.beams[k];
    if (!b.turns_with_detector()) {
      beams.push_back(make_beam(b, c.source, 0.0, log));
      say("beam %s: %s\n", b.name.c_str(), beams.back().description().c_str());
      beam_names.push_back(b.name);
      for (std::size_t i = 0; i < detectors.size(); ++i)
        if (c.detectors[i].beam == k) detectors[i].beam = beams.size() - 1;
      continue;
    }
    std::vector<std::pair<double, std::size_t>> made;  // zeta -> beam index
    for (std::size_t i = 0; i < detectors.size(); ++i) {
      if (c.detectors[i].beam != k) continue;
      const double zeta = c.detectors[i].zeta;
      auto it = std::find_if(made.begin(), made.end(), [&](const auto& m) { return m.first == zeta; });
      if (it == made.end()) {
        beams.push_back(make_beam(b, c.source, zeta, log));
        beam_names.push_back(b.name);
        say("beam %s for zeta %g deg: %s\n", b.name.c_str(), zeta * 180 / std::numbers::pi,
            beams.back().description().c_str());
        // A b_lm file of T alone gives a polarized detector no polarization response: said, unless
        // the table says that this is meant.
        const Beamsor& made_beam = beams.back();
        if (b.kind == BeamKind::blm && !b.temperature_only && c.detectors[i].epsilon < 1.0 &&
            !made_beam.has_element(1, 1) && !made_beam.has_element(1, 2) && !made_beam.has_element(2, 1) &&
            !made_beam.has_element(2, 2))
          throw pisco::Error(c.source.string() + ": [beams." + b.name + "] " + b.file.string() +
                             " holds T coefficients alone, so detector '" + c.detectors[i].name +
                             "' (polarization efficiency " + format("%g", 1.0 - c.detectors[i].epsilon) +
                             ") would see no polarization; give a file with T, E and B, or set temperature_only = "
                             "true if a beam without polarization response is meant");
        made.emplace_back(zeta, beams.size() - 1);
        it = made.end() - 1;
      }
      detectors[i].beam = it->second;
    }
    if (made.empty()) {  // checked, though no detector uses it
      beams.push_back(make_beam(b, c.source, 0.0, log));
      beam_names.push_back(b.name);
    }
  }
  return out;
}

// The threads of this process's per-sample host work in the stream: the engine's own on the cpu and
// simd backends when they are set, else the host's hardware threads shared by the node's processes.
unsigned stream_host_threads(const SimulationConfig& c, const Engine& engine, const RunContext& cl) {
  EngineOptions o = c.engine.options;
  if (const unsigned* threads = o.threads_of(engine.backend_name()); threads && *threads > 0) return *threads;
  return std::max(1u, std::thread::hardware_concurrency() / unsigned(std::max(1, cl.node_size())));
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
      if (b.capabilities.worker_threads) {  // the host's threads are what the processes share
        if (unsigned* threads = o.threads_of(backend); threads && *threads == 0) {
          *threads = std::max(1u, std::thread::hardware_concurrency() / unsigned(cl.node_size()));
          return true;
        }
      } else if (std::string* device = o.device_of(backend); device && (*device == "auto" || device->empty()) && !b.devices.empty()) {
        *device = std::to_string(b.devices[std::size_t(cl.node_rank()) % b.devices.size()]);
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
    o.backend = engine_holder->backend_name();
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
namespace {
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
}  // namespace

std::vector<fs::path> write_spectra_files(const SimulationConfig& c, const Sky& sky, const BinnedMaps& maps,
                                          int maps_nside) {
  return spectra_files(c, sky, maps.I, maps.Q, maps.U, maps_nside, "binned maps",
                       window_fwhm(c.beams[c.detectors.front().beam]));
}

namespace {

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
  return format("hwp: maps' rms Q %.3g, U %.3g, I (mean removed) %.3g %s: leakage figure rms P / rms I = %.3g%s\n", rq,
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
         ", none with rcond >= " + format("%g", rcond_min) +
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

// The maps of a run as written: the files, the pixels solved, and why none was ("" when some were).
struct MapOutputs {
  std::vector<fs::path> written;
  std::size_t solved = 0;
  std::string nothing_solved;
};

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
  log(format("maps: NSIDE %d, %zu of %zu pixels reached by the beams (deconvolved%s); binned_maps.fits beside them\n",
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
  log(format("maps: NSIDE %d, %td of %zu pixels solved (rcond >= %g)\n", maps_nside,
             static_cast<std::ptrdiff_t>(out.solved), maps.I.size(), c.output.rcond_min));
  if (c.hwp.enabled && out.solved > 0) log(hwp_figure(maps, out.solved, sky.units(), c.hwp.ideal_mapmaker));
  if (out.solved == 0) out.nothing_solved = unsolved_reason(maps, maps_nside, flagging, c.output.rcond_min);
  if (c.output.spectra && out.nothing_solved.empty())
    for (const auto& f : write_spectra_files(c, sky, maps, maps_nside)) out.written.push_back(f);
  return out;
}

// The scan's pointing: the boresight (generated, or a boresight pointing file) chunk by chunk, or a
// file of each detector's own angles (per-detector groups), read a detector at a time; such a file's
// detectors have no offsets and the same number of samples.
class ScanSource {
 public:
  ScanSource(const SimulationConfig& c, const FocalPlane& fp)
      : c_(c), fp_(fp), per_detector_(c.scan.kind == ScanKind::file && !pisco::BoresightFile::holds_boresight(c.scan.file)) {
    if (per_detector_) {
      const std::string* first = nullptr;  // the detector whose sample count the others must match
      for (const auto& d : fp.detectors()) {
        if (d.has_offset())
          throw pisco::Error(c.scan.file.string() + ": the file gives detector '" + d.name +
                             "' its own pointing, but the focal plane also gives it an offset from the boresight " +
                             "(expected a boresight pointing file, or detectors without offsets)");
        const std::size_t n = pisco::read_pointing_hdf5(c.scan.file, d.name).size();
        if (!first) {
          first = &d.name;
          samples_ = n;
        } else if (n != samples_) {
          throw pisco::Error(c.scan.file.string() + ": detector '" + d.name + "' has " + std::to_string(n) +
                             " samples, detector '" + *first + "' " + std::to_string(samples_) +
                             " (expected the same number of samples for every detector)");
        }
      }
    } else {
      boresight_.emplace(c.scan, c.hwp);
      samples_ = boresight_->size();
    }
    check_hwp_times(c, samples_);
  }
  bool per_detector() const { return per_detector_; }
  std::size_t samples_per_detector() const { return samples_; }
  // The boresight's samples [first, first + count).
  void fill(std::size_t first, std::size_t count, BoresightChunk& out, pisco::detail::ThreadPool* pool = nullptr) const {
    boresight_->fill(first, count, out, pool);
  }
  // A per-detector file's pointing of detector d, whole.
  pisco::Pointing detector_pointing(std::size_t d) const { return pisco::read_pointing_hdf5(c_.scan.file, fp_[d].name); }

 private:
  const SimulationConfig& c_;
  const FocalPlane& fp_;
  bool per_detector_;
  std::optional<Boresight> boresight_;
  std::size_t samples_ = 0;
};

// The pointing of a run's jobs (a detector's chunk), loaded only when it changes: a per-detector
// file's detector read whole when the detector changes, the boresight's chunk filled when the time
// span changes. Each load goes into the other of two buffers, so that the job before keeps its own
// (JobStream's pending job): a job's views stay valid until the load after next.
class JobPointing {
 public:
  // With `pool`, generated scans are made on its threads.
  JobPointing(const SimulationConfig& c, const FocalPlane& fp, const ScanSource& scan,
              pisco::detail::ThreadPool* pool = nullptr)
      : c_(c), fp_(fp), scan_(scan), pool_(pool) {}

  // Job's pointing and its detector's plate angles (none without a plate); a per-detector file's
  // plate angles are generated into `hwp`, which must outlive the views as well.
  pisco::SurveyChunk load(const JobPlan::Span& job, std::vector<double>& hwp) {
    const bool per_detector = scan_.per_detector();
    const std::size_t key = per_detector ? job.detector : job.first;
    if (key != loaded_) {
      slot_ ^= 1;
      if (per_detector) file_[slot_] = scan_.detector_pointing(job.detector);
      else scan_.fill(job.first, job.count, bore_[slot_], pool_);
      loaded_ = key;
    }
    pisco::SurveyChunk chunk;
    chunk.detector = job.detector;
    chunk_slot_ = slot_;
    const bool plate = fp_[job.detector].hwp.has_value();
    if (per_detector) {
      chunk.angles = file_[slot_].view().subspan(job.first, job.count);
      if (plate) {
        c_.hwp.stream.generate(job.first, job.count, hwp);
        chunk.hwp_angle = hwp;
      }
    } else {
      const BoresightChunk& b = bore_[slot_];
      chunk.quaternions = b.quaternions;
      chunk.angles = b.angles.view();
      chunk.quats = pisco::QuatPointingView{b.quats};
      if (plate) chunk.hwp_angle = b.hwp;
    }
    return chunk;
  }

  // The slot of the chunk load() returned last: a chunk stays valid until two more loads.
  int chunk_slot() const { return chunk_slot_; }
  // The boresight of the chunk in `slot` as quaternions: as loaded, or the angles turned into
  // quaternions (pisco::quat_from_pointing, on the pool's threads) the first time a detector of that
  // chunk asks. Per-detector files have none (empty).
  pisco::QuatPointingView boresight_quats(int slot, pisco::detail::ThreadPool& pool) {
    if (scan_.per_detector()) return {};
    BoresightChunk& b = bore_[std::size_t(slot)];
    if (b.quaternions) return pisco::QuatPointingView{b.quats};
    if (!b.angle_quats_made) {
      pisco::detail::pointing_quats(b.angles.view(), b.angle_quats, pool);
      b.angle_quats_made = true;
    }
    return pisco::QuatPointingView{b.angle_quats};
  }

 private:
  const SimulationConfig& c_;
  const FocalPlane& fp_;
  const ScanSource& scan_;
  pisco::detail::ThreadPool* pool_ = nullptr;
  int chunk_slot_ = 0;
  std::array<BoresightChunk, 2> bore_;
  std::array<pisco::Pointing, 2> file_;
  std::size_t loaded_ = static_cast<std::size_t>(-1);  // the detector or the first sample loaded last
  int slot_ = 1;
};

// Calls f with a job's pointing view, angles or quaternions.
template <class F>
decltype(auto) with_view(const pisco::SurveyChunk& chunk, F&& f) {
  return chunk.quaternions ? f(chunk.quats) : f(chunk.angles);
}

// What the TOD streams into: the map-makers and the TOD file (each absent when not asked for).
struct StreamSinks {
  pisco::BinnedMapmaker* binned = nullptr;
  pisco::DeconvolvingMapmaker* deconvolver = nullptr;  // its right-hand side A^T d
  pisco::TodWriter* tod = nullptr;
};

// The run as a stream of jobs (a detector's chunk), two in flight: while the engine convolves job
// j, job j - 1 is binned and written and job j + 1's pointing is prepared, so that the device never
// waits for the host (Engine::submit). Jobs alternate between two TOD buffers, and time chunks
// between two boresight buffers: the pending job is never more than one behind.
class JobStream {
 public:
  JobStream(const SimulationConfig& c, const FocalPlane& fp, const ScanSource& scan, Engine& engine, StreamSinks sinks,
            bool flagging, std::size_t chunk, unsigned host_threads, RunObserver& obs)
      : c_(c), fp_(fp), engine_(engine), sinks_(sinks), flagging_(flagging), obs_(obs),
        modelled_(fp.detectors()), host_(host_threads), pointing_(c, fp, scan, &host_) {
    for (auto& t : tod_) t.resize(chunk);
    // The detectors as the map-maker models them (with [hwp] mapmaker = "ideal": an ideal plate in
    // place of the real one).
    if (c.hwp.ideal_mapmaker)
      for (auto& d : modelled_)
        if (d.hwp) d.hwp->mueller = pisco::ideal_hwp_mueller();
  }

  // This process's jobs of `plan`. Under MPI, a check for an error on another process after every
  // check_every jobs (at most about 1000 in a run), and an error here shared with the others.
  void run(const JobPlan& plan, RunContext& cl) {
    auto ceil_div = [](std::size_t a, std::size_t b) { return (a + b - 1) / b; };
    const std::size_t check_every = std::max<std::size_t>(1, ceil_div(plan.rounds, 1000));
    const std::size_t checks = ceil_div(plan.rounds, check_every);
    if (!cl.parallel()) {
      run_jobs(plan, cl, check_every);
      return;
    }
    std::optional<std::string> failure;
    try {
      run_jobs(plan, cl, check_every);
    } catch (const std::exception& e) {
      failure = e.what();
    }
    engine_.wait();  // after a failure or a stop, nothing in flight writes into the buffers any more
    cl.finish_checks(checks, failure.has_value());
    cl.agree(failure);
  }

  std::uint64_t flagged() const { return flagged_; }

  // After an error, nothing still in flight may write into the buffers once they are gone.
  ~JobStream() {
    try {
      engine_.wait();
    } catch (...) {  // the error that ended the run is already on its way
    }
  }
  JobStream(const JobStream&) = delete;
  JobStream& operator=(const JobStream&) = delete;

 private:
  struct Job {
    std::size_t first = 0;
    pisco::SurveyChunk chunk;  // its pointing and plate angles (JobPointing)
    int pointing_slot = 0;     // JobPointing's slot of that pointing
    int slot = 0;              // its TOD buffer
    std::uint64_t ticket = 0;
  };

  void run_jobs(const JobPlan& plan, RunContext& cl, std::size_t check_every) {
    // Fault injection for the tests (docs/scaling.md): a process told to fails after its first job, as
    // one whose device or disk fails mid-run would.
    const bool inject_failure = cl.parallel() && cl.inject_failure();
    for (std::size_t i = plan.my_first; i < plan.my_end; ++i) {
      const JobPlan::Span span = plan.at(i);
      Job j;
      j.first = span.first;
      j.slot = next_slot_;
      next_slot_ ^= 1;
      j.chunk = pointing_.load(span, hwp_[j.slot]);
      j.pointing_slot = pointing_.chunk_slot();
      const std::span<double> t(tod_[j.slot].data(), span.count);
      j.ticket = with_view(j.chunk, [&](const auto& view) {
        return engine_.submit(span.detector, view, t, false, j.chunk.hwp_angle);
      });
      if (pending_) finish(*pending_);
      pending_ = j;
      if (inject_failure && i > plan.my_first)
        throw pisco::Error("injected failure on rank " + std::to_string(cl.rank()) + " (PISCO_TEST_RANK_FAIL)");
      if ((i - plan.my_first + 1) % check_every == 0) {
        cl.post_check(false);
        if (cl.stop()) return;  // another rank failed
      }
    }
    if (pending_) finish(*pending_);
  }

  // [sky] unseen = "flag": the samples whose disc holds an UNSEEN pixel.
  std::span<const std::uint8_t> flag_samples(const pisco::SurveyChunk& chunk) {
    flags_.resize(chunk.size());
    flagged_ += with_view(chunk, [&](const auto& view) { return engine_.flag_samples(chunk.detector, view, flags_); });
    return std::span<const std::uint8_t>(flags_);
  }

  void finish(const Job& j) {
    engine_.wait(j.ticket);
    const pisco::SurveyChunk& chunk = j.chunk;
    const std::size_t count = chunk.size();
    const std::span<double> t(tod_[j.slot].data(), count);
    // The binned map-maker takes the boresight's quaternions (one conversion per time chunk for every
    // detector) and applies the detector's offset itself; the detector's angles are made only for the
    // TOD file's pointing or weights, or from a per-detector file.
    const bool tod_pointing = sinks_.tod && (c_.output.tod_pointing || c_.output.tod_weights);
    const pisco::QuatPointingView boresight =
        sinks_.binned && !tod_pointing ? pointing_.boresight_quats(j.pointing_slot, host_) : pisco::QuatPointingView{};
    const bool from_boresight = sinks_.binned && !tod_pointing && boresight.size() == count;
    if ((sinks_.binned && !from_boresight) || tod_pointing)
      with_view(chunk, [&](const auto& view) {
        pisco::detail::detector_pointing(view, fp_[chunk.detector].offset, own_, host_);
      });
    const pisco::PointingView detector_view = own_.view();
    std::span<const std::uint8_t> fl;
    if (flagging_) fl = flag_samples(chunk);
    if (from_boresight)
      sinks_.binned->add_from_boresight(modelled_[chunk.detector], boresight.subspan(0, count), t, chunk.hwp_angle, fl);
    else if (sinks_.binned)
      sinks_.binned->add(modelled_[chunk.detector], detector_view, t, chunk.hwp_angle, fl);
    if (sinks_.deconvolver) {  // the right-hand side A^T d, chunk by chunk
      try {
        sinks_.deconvolver->add(chunk, t);
      } catch (const pisco::Error& e) {
        throw pisco::Error(c_.source.string() + ": [mapmaker] type = \"deconvolve\": " + e.what(), e.kind());
      }
    }
    if (sinks_.tod && c_.output.tod_weights) {  // the map-maker's weights of each sample
      const std::span<const double> h = chunk.hwp_angle;
      weights_.resize(3 * count);
      host_.parallel_for(count, 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
          const std::array<double, 3> a = pisco::stokes_weights(modelled_[chunk.detector], detector_view.psi[i],
                                                                h.empty() ? 0.0 : h[i]);
          std::copy(a.begin(), a.end(), weights_.begin() + std::ptrdiff_t(3 * i));
        }
      });
    }
    if (sinks_.tod)
      sinks_.tod->write(chunk.detector, j.first, t, c_.output.tod_pointing ? &detector_view : nullptr, fl,
                        c_.output.tod_weights ? std::span<const double>(weights_) : std::span<const double>());
    obs_.advance(count);
  }

  const SimulationConfig& c_;
  const FocalPlane& fp_;
  Engine& engine_;
  StreamSinks sinks_;
  bool flagging_;
  RunObserver& obs_;
  std::vector<pisco::Detector> modelled_;
  // The per-sample host work (the scan's generation, the map-maker's quaternions, detector pointing,
  // the TOD file's weights) on all its threads, while the backend convolves the next job: the
  // same bits as on one thread.
  pisco::detail::ThreadPool host_;
  JobPointing pointing_;
  std::array<std::vector<double>, 2> tod_;
  std::array<std::vector<double>, 2> hwp_;  // per-detector files: a job's plate angles, by TOD buffer
  std::optional<Job> pending_;
  int next_slot_ = 0;
  pisco::Pointing own_;
  std::vector<double> weights_;
  std::vector<std::uint8_t> flags_;
  std::uint64_t flagged_ = 0;
};

// The survey as the deconvolving map-maker replays it each iteration: this process's jobs of `plan`,
// in order, a chunk at a time.
void replay_survey(const JobPlan& plan, const SimulationConfig& c, const FocalPlane& fp, const ScanSource& scan,
                   const std::function<void(const pisco::SurveyChunk&)>& visit) {
  JobPointing pointing(c, fp, scan);
  std::vector<double> hwp;
  for (std::size_t i = plan.my_first; i < plan.my_end; ++i) visit(pointing.load(plan.at(i), hwp));
}

}  // namespace

Simulation::Simulation(SimulationConfig config, SimulationOptions options)
    : config_(std::move(config)), options_(std::move(options)) {}

Simulation Simulation::from_file(const fs::path& file, SimulationOptions options) {
  return Simulation(read_simulation_file(file), std::move(options));
}

SimulationResult Simulation::run(RunContext& cl, RunObserver* observer) const {
  const auto t0 = std::chrono::steady_clock::now();
  const SimulationConfig& c = config_;
  RunObserver silent;
  RunObserver& obs = observer ? *observer : silent;
  // The run's account: the leading process's alone.
  auto say = [&](const char* fmt, auto... args) {
    if (cl.leader()) obs.log(format(fmt, args...));
  };
  const fs::path data_dir = options_.data_dir.empty() ? default_data_dir() : options_.data_dir;
  SimulationResult result;

  // A run that would write nothing is refused before it starts (spectra and plots come from the maps).
  if (!c.output.tod && !c.output.maps)
    throw Error((c.source.empty() ? std::string("simulation") : c.source.string()) +
                ": [output] tod = false and maps = false: the run would write nothing; set tod or maps to true");
  // The output directory, made when missing and locked by the leading process (pisco-vk makes and
  // locks it before: then nothing to do), so that a second run into it stops before its set-up.
  std::optional<OutputLock> lock;
  cl.step([&] {
    std::error_code ec;
    if (!fs::is_directory(c.output.dir, ec)) {
      fs::create_directories(c.output.dir, ec);
      if (ec && !fs::is_directory(c.output.dir))
        throw Error(c.output.dir.string() + ": cannot make the output directory: " + ec.message());
    }
    if (!cl.leader()) return;
    if (options_.lock_output)
      lock.emplace(c.output.dir, [&](const std::string& m) { obs.log(m + "\n"); });
    else if (!OutputLock::held(c.output.dir))
      throw Error(c.output.dir.string() + ": SimulationOptions::lock_output is false, but this process holds no "
                                          "OutputLock of the directory");
  });
  std::optional<Sky> sky_holder;
  cl.step([&] { sky_holder.emplace(make_sky(c.sky, data_dir)); });
  const Sky& sky = *sky_holder;
  say("sky: NSIDE %d, %s%s\n", sky.nside(), c.sky.file.empty() ? "synthesized from " : "",
      c.sky.file.empty() ? c.sky.cl_file.string().c_str() : c.sky.file.string().c_str());
  SimulationBeams made;
  cl.step([&] { made = make_beams(c, [&](const std::string& line) { if (cl.leader()) obs.log(line); }); });
  const std::vector<Beamsor>& beams = made.beams;
  FocalPlane fp(made.detectors);
  std::optional<Engine> engine_holder;
  cl.step([&] { engine_holder.emplace(make_engine(sky, beams, fp, c, cl)); });
  Engine& engine = *engine_holder;
  say("backend: %s (%s)%s\n", engine.backend_name().c_str(), engine.device_name().c_str(),
      cl.parallel() ? (", rank 0 of " + std::to_string(cl.size()) + " (" + std::to_string(cl.node_size()) +
                       " on its node)").c_str()
                    : "");
  // [sky] unseen = "flag": samples whose disc holds an UNSEEN pixel are flagged in the TOD file and
  // left out of the maps.
  const bool flagging = c.sky.unseen == pisco::UnseenPolicy::flag && engine.unseen_pixels() > 0;
  if (engine.unseen_pixels() > 0)
    say("sky: %zu UNSEEN pixels taken as 0%s\n", engine.unseen_pixels(),
        flagging ? "; samples whose disc holds one are flagged and left out of the maps" : " ([sky] unseen = \"zero\")");
  std::optional<ScanSource> scan;
  cl.step([&] { scan.emplace(c, fp); });
  const bool per_detector_file = scan->per_detector();
  const std::size_t samples_per_detector = scan->samples_per_detector();
  const std::uint64_t total = std::uint64_t(samples_per_detector) * fp.size();
  // [mapmaker] type = "deconvolve": maps at the engine's NSIDE, the sky's (binned ones too, for hits
  // and comparison), solved after the run by conjugate gradients that replay the survey.
  const bool deconvolving = c.output.maps && c.mapmaker.kind == MapmakerKind::deconvolve;
  const int maps_nside = deconvolving ? sky.nside() : pisco::maps_nside(c, sky);
  say("scan: %s, %zu detectors x %zu samples\n", scan_kind_name(c.scan.kind), fp.size(), samples_per_detector);

  // The host's share of this process (the engine's threads on the cpu and simd backends) for the
  // per-sample host work of the stream: detector pointing and binning.
  const unsigned host_threads = stream_host_threads(c, engine, cl);
  std::optional<pisco::BinnedMapmaker> mapper;
  std::optional<pisco::DeconvolvingMapmaker> deconvolver;
  cl.step([&] {
    if (deconvolving && c.output.maps_nside > 0 && c.output.maps_nside != sky.nside())
      throw pisco::Error(c.source.string() + ": [output] maps_nside: [mapmaker] type = \"deconvolve\" solves for the sky at its NSIDE " +
                         std::to_string(sky.nside()) + "; got " + std::to_string(c.output.maps_nside) +
                         " (leave maps_nside out, or set it to the sky's)");
    if (c.output.maps && c.output.spectra && c.output.lmax > 4 * maps_nside)
      throw pisco::Error(c.source.string() + ": [output] lmax: expected a multipole up to 4 maps_nside = " +
                         std::to_string(4 * maps_nside) + ", got " + std::to_string(c.output.lmax));
    if (c.output.maps) {
      mapper.emplace(maps_nside, c.output.rcond_min);
      mapper->set_threads(host_threads);
    }
    if (deconvolving) {
      for (const pisco::BackendInfo& b : pisco::Engine::backends())
        if (b.name == engine.backend_name() && !b.capabilities.adjoint)
          throw pisco::Error(c.source.string() + ": [mapmaker] type = \"deconvolve\" needs the adjoint, which the " +
                                 engine.backend_name() + " backend on " + engine.device_name() +
                                 " lacks; choose another [engine] backend",
                             pisco::ErrorKind::unavailable);
      pisco::DeconvolutionOptions o;
      o.max_iterations = c.mapmaker.iterations;
      o.tolerance = c.mapmaker.tolerance;
      o.regularization = c.mapmaker.regularization;
      if (c.mapmaker.regularize_polarization_only) o.regularize = pisco::DeconvolutionOptions::Regularize::polarization;
      o.target_fwhm = c.mapmaker.target_fwhm;
      if (cl.parallel()) o.reduce = [&cl](std::span<double> v) { cl.sum_in_place(v); };
      deconvolver.emplace(engine, o);
    }
  });
  const fs::path tod_path = c.output.dir / "tod.h5";
  std::optional<pisco::TodWriter> tod_file;
  if (c.output.tod) tod_file = open_tod_file(c, tod_path, sky, made, engine, fp, samples_per_detector, flagging, cl);

  const std::size_t chunk = std::min(c.engine.chunk_samples, std::max<std::size_t>(samples_per_detector, 1));
  const std::size_t ndet = fp.size();
  const JobPlan plan = plan_jobs(ndet, samples_per_detector, chunk, per_detector_file, cl, [&](std::size_t d) {
    return disc_pixels(beams[fp[d].beam], sky.nside(), engine.sidelobe_nside());
  });
  std::uint64_t my_samples = 0;
  for (std::size_t i = plan.my_first; i < plan.my_end; ++i) my_samples += plan.at(i).count;
  obs.begin_convolution(my_samples);
  const auto tc = std::chrono::steady_clock::now();
  std::uint64_t flagged = 0;
  {
    JobStream stream(c, fp, *scan, engine,
                     {mapper ? &*mapper : nullptr, deconvolver ? &*deconvolver : nullptr, tod_file ? &*tod_file : nullptr},
                     flagging, chunk, host_threads, obs);
    stream.run(plan, cl);
    flagged = stream.flagged();
  }
  obs.end_convolution();
  const double my_conv = std::chrono::duration<double>(std::chrono::steady_clock::now() - tc).count();
  const double conv = cl.max(my_conv);  // the slowest rank's
  // Pixels per disc over every rank's samples.
  const double mean_disc =
      cl.parallel() && total > 0 ? cl.sum_of(engine.mean_disc_pixels() * double(my_samples)) / double(total)
                                 : engine.mean_disc_pixels();
  std::vector<fs::path>& written = result.written;
  if (tod_file) {
    cl.step([&] { tod_file->commit(); });
    written.push_back(tod_path);
  }
  flagged = cl.sum(flagged);
  std::uint64_t reduced_bytes = 0;
  if (mapper) cl.step([&] { reduced_bytes = cl.sum(cl.reduce(*mapper)); });
  if (flagging)
    say("flags: %llu of %llu samples flagged (their disc holds an UNSEEN pixel)%s\n",
        static_cast<unsigned long long>(flagged), static_cast<unsigned long long>(total),
        tod_file ? "; the TOD file's 'flags' datasets" : "");

  // The deconvolving map-maker: every process replays its own jobs each iteration, and the maps are
  // summed over the processes (RunContext::sum_in_place), so that all run the same iterations.
  std::optional<pisco::DeconvolvedMaps> deconvolved;
  if (deconvolver) {
    say("mapmaker: deconvolving each detector's beam by conjugate gradients, at most %d iterations "
        "(tolerance %g, regularization %g), reconvolved to a Gaussian of FWHM %g deg (0: not reconvolved)\n",
        c.mapmaker.iterations, c.mapmaker.tolerance, c.mapmaker.regularization,
        c.mapmaker.target_fwhm * 180 / std::numbers::pi);
    const auto survey = [&](const std::function<void(const pisco::SurveyChunk&)>& visit) {
      replay_survey(plan, c, fp, *scan, visit);
    };
    deconvolved = deconvolver->solve(survey, [&](const pisco::DeconvolutionProgress& p) {
      say("mapmaker: iteration %d, residual %.3g of ||A^T d|| (%.1f s)\n", p.iteration, p.residual, p.seconds);
    });
    say("mapmaker: %s after %d iterations, %.2f s each\n", deconvolved->converged ? "converged" : "stopped",
        deconvolved->iterations, deconvolved->seconds_per_iteration);
    for (const std::string& line : deconvolved->left_out) say("mapmaker: left out %s\n", line.c_str());
    result.deconvolution_iterations = deconvolved->iterations;
    result.deconvolution_residual = deconvolved->residuals.empty() ? 0.0 : deconvolved->residuals.back();
    result.deconvolution_converged = deconvolved->converged;
    if (!deconvolved->converged) {
      const auto& r = deconvolved->residuals;
      const auto best = std::min_element(r.begin(), r.end());
      result.warnings.push_back(format(
          "the deconvolving map-maker did not converge: residual %.3g of ||A^T d|| after %d iterations (the "
          "smallest, %.3g, at iteration %d), above [mapmaker] tolerance = %g; raise iterations, or the "
          "tolerance to what the backend reaches (float32 kernels stop near 1e-4), or add regularization",
          result.deconvolution_residual, deconvolved->iterations, best == r.end() ? 0.0 : *best,
          int(best - r.begin()) + 1, c.mapmaker.tolerance));
    }
    if (deconvolved->polarization_unconstrained)
      result.warnings.push_back(
          "the scan's polarization angles constrain Q and U in no pixel the beams reach (one angle per "
          "pixel?): the deconvolved maps hold I alone, Q and U are unseen");
  }

  // Maps and spectra: the leader's, from the normal equations of every process. A run whose maps solve
  // no pixel has no maps to speak of: no spectra (and pisco-vk makes no plots and exits with status 4).
  std::string nothing_solved;
  cl.step([&] {
    if (!cl.leader() || !mapper) return;
    const auto log = [&](const std::string& line) { obs.log(line); };
    const MapOutputs out = deconvolved ? write_deconvolved_maps(c, sky, maps_nside, *deconvolved, *mapper, log)
                                       : write_binned_maps(c, sky, maps_nside, *mapper, flagging, log);
    written.insert(written.end(), out.written.begin(), out.written.end());
    result.solved_pixels = out.solved;
    nothing_solved = out.nothing_solved;
  });
  nothing_solved = cl.broadcast(nothing_solved);

  result.samples = total;
  result.detectors = fp.size();
  result.samples_per_detector = samples_per_detector;
  result.mean_disc_pixels = mean_disc;
  result.convolution_seconds = conv;
  result.backend = engine.backend_name();
  result.device = engine.device_name();
  result.flagged = flagged;
  result.reduced_bytes = reduced_bytes;
  if (tod_file) result.tod_file = tod_path;
  result.nothing_solved = nothing_solved;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace pisco
