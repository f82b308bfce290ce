// pisco::Simulation (simulation.hpp): sky -> TOD -> binned maps -> spectra, streaming the TOD chunk by
// chunk through the map-maker and the TOD file, so memory stays bounded whatever the length of the scan.
// The parts it chains are in simulation_parts.cpp (the sky, beams, engine, maps and spectra of a
// simulation file), survey.hpp (the stream of jobs) and run_outputs.hpp (the TOD file and the maps).
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
#include "pipeline/survey.hpp"

namespace pisco {

namespace fs = std::filesystem;
using namespace detail;

void RunContext::agree(const std::optional<std::string>& error) {
  if (error) throw Error(*error);
}

RunContext& serial_run_context() {
  static RunContext context;
  return context;
}

namespace {

// The output directory, made when missing and locked by the leading process (pisco-vk makes and
// locks it before: then nothing to do), so that a second run into it stops before its set-up.
void lock_output_dir(const SimulationConfig& c, const SimulationOptions& options, RunContext& cl, RunObserver& obs,
                     std::optional<OutputLock>& lock) {
  cl.step([&] {
    std::error_code ec;
    if (!fs::is_directory(c.output.dir, ec)) {
      fs::create_directories(c.output.dir, ec);
      if (ec && !fs::is_directory(c.output.dir))
        throw Error(c.output.dir.string() + ": cannot make the output directory: " + ec.message());
    }
    if (!cl.leader()) return;
    if (options.lock_output)
      lock.emplace(c.output.dir, [&](const std::string& m) { obs.log(m + "\n"); });
    else if (!OutputLock::held(c.output.dir))
      throw Error(c.output.dir.string() + ": SimulationOptions::lock_output is false, but this process holds no "
                                          "OutputLock of the directory");
  });
}

// The run's map-maker, of [mapmaker]'s kind, when maps are asked for (its threads the stream's host
// share; with [ground], the ground's TOD binned beside), and the NSIDE of its maps.
std::unique_ptr<RunMapmaker> make_mapmaker(const SimulationConfig& c, const Sky& sky, Engine& engine, bool ground,
                                           unsigned host_threads, RunContext& cl, int& maps_nside) {
  std::unique_ptr<RunMapmaker> made;
  cl.step([&] {
    if (!c.output.maps) return;
    const MapmakerKindEntry& kind = mapmaker_kind(c.mapmaker.kind);
    maps_nside = kind.maps_nside(c, sky);
    if (c.output.spectra && c.output.lmax > 4 * maps_nside)
      throw pisco::Error(c.source.string() + ": [output] lmax: expected a multipole up to 4 maps_nside = " +
                         std::to_string(4 * maps_nside) + ", got " + std::to_string(c.output.lmax));
    made = kind.make({c, sky, engine, maps_nside, host_threads, ground, cl});
  });
  return made;
}

// [ground]: the pickup over every process's samples (SimulationResult's ground_ fields).
// Told in the sky's units.
void ground_summary(const std::vector<detail::JobStream::GroundStats>& stats, RunContext& cl, SimulationResult& r,
                    const std::string& units, const std::function<void(const std::string&)>& say_line) {
  // Every detector's count, sum and sum of squares summed over the processes in one call.
  std::vector<double> sums;
  for (const auto& g : stats) sums.insert(sums.end(), {double(g.n), g.sum, g.sum2});
  cl.sum_in_place(sums);
  double sum = 0.0, n = 0.0, variance = 0.0, detectors = 0.0, peak = 0.0;
  for (std::size_t k = 0; k < stats.size(); ++k) {
    const auto& g = stats[k];
    const double dn = sums[3 * k], ds = sums[3 * k + 1], ds2 = sums[3 * k + 2];
    const double hi = cl.max(g.max), lo = -cl.max(-g.min);
    if (dn == 0) continue;
    sum += ds;
    n += dn;
    const double mean = ds / dn;
    variance += std::max(0.0, ds2 / dn - mean * mean);
    detectors += 1.0;
    peak = std::max(peak, hi - lo);
  }
  r.ground_mean = n > 0 ? sum / n : 0.0;
  r.ground_rms = detectors > 0 ? std::sqrt(variance / detectors) : 0.0;
  r.ground_peak_to_peak = peak;
  say_line(detail::printf_text(
      "ground: picked up through the beams: mean %.6g %s, scan-synchronous rms %.6g, largest peak to peak %.6g\n",
      r.ground_mean, units.c_str(), r.ground_rms, r.ground_peak_to_peak));
}

// [ground]: a second engine over the ground map in the horizon frame, with the run's beams, on
// [ground]'s backend (the run's own by default) with [engine]'s other settings.
void make_ground_engine(const SimulationConfig& c, const Sky& sky, const std::vector<Beamsor>& beams, const FocalPlane& fp,
                        RunContext& cl, const std::function<void(const std::string&)>& say_line,
                        std::optional<Engine>& ground_engine) {
  auto say = [&](const char* fmt, auto... args) { say_line(detail::printf_text(fmt, args...)); };
  std::optional<Sky> ground_sky;
  cl.step([&] { ground_sky.emplace(make_ground_sky(c.ground, sky, c.source)); });
  cl.step([&] {
    try {
      // [ground] backend, with [engine]'s other settings that it takes (a device given for [engine]'s
      // named backend stays with it).
      SimulationConfig ground_config = c;
      if (!c.ground.backend.empty())
        ground_config.engine.options = options_for_backend(c.engine.options, c.ground.backend);
      ground_engine.emplace(make_engine(*ground_sky, beams, fp, ground_config, cl));
    } catch (const Error& e) {
      throw Error(c.source.string() + ": [ground]: " + e.what(), e.kind());
    }
  });
  const auto [lo, hi] = std::minmax_element(ground_sky->I().begin(), ground_sky->I().end());
  say("ground: NSIDE %d in the horizon frame, %s, from %.6g to %.6g %s; backend %s\n", ground_sky->nside(),
      c.ground.file.empty() ? "the model" : c.ground.file.string().c_str(), *lo, *hi, sky.units().c_str(),
      ground_engine->backend_name().c_str());
}

// A run that would write nothing is refused before it starts (spectra and plots come from the maps).
void refuse_a_run_that_writes_nothing(const SimulationConfig& c) {
  if (!c.output.tod && !c.output.maps)
    throw Error((c.source.empty() ? std::string("simulation") : c.source.string()) +
                ": [output] tod = false and maps = false: the run would write nothing; set tod or maps to true");
}

// The engine's backend and the sky's UNSEEN pixels, told; returns whether samples are flagged: with
// [sky] unseen = "flag", samples whose disc holds an UNSEEN pixel are flagged in the TOD file and left
// out of the maps.
bool describe_engine(const SimulationConfig& c, const Engine& engine, RunContext& cl,
                     const std::function<void(const std::string&)>& say_line) {
  auto say = [&](const char* fmt, auto... args) { say_line(detail::printf_text(fmt, args...)); };
  say("backend: %s (%s)%s\n", engine.backend_name().c_str(), engine.device_name().c_str(),
      cl.parallel() ? (", rank 0 of " + std::to_string(cl.size()) + " (" + std::to_string(cl.node_size()) +
                       " on its node)").c_str()
                    : "");
  const bool flagging = c.sky.unseen == pisco::UnseenPolicy::flag && engine.unseen_pixels() > 0;
  if (engine.unseen_pixels() > 0)
    say("sky: %zu UNSEEN pixels taken as 0%s\n", engine.unseen_pixels(),
        flagging ? "; samples whose disc holds one are flagged and left out of the maps" : " ([sky] unseen = \"zero\")");
  return flagging;
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
  const std::function<void(const std::string&)> say_line = [&](const std::string& line) {
    if (cl.leader()) obs.log(line);
  };
  auto say = [&](const char* fmt, auto... args) { say_line(detail::printf_text(fmt, args...)); };
  const fs::path data_dir = options_.data_dir.empty() ? default_data_dir() : options_.data_dir;
  SimulationResult result;

  refuse_a_run_that_writes_nothing(c);
  std::optional<OutputLock> lock;
  lock_output_dir(c, options_, cl, obs, lock);
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
  // [ground]: a second engine over the ground map in the horizon frame, with the same beams.
  std::optional<Engine> ground_engine;
  if (c.ground.enabled) make_ground_engine(c, sky, beams, fp, cl, say_line, ground_engine);
  const bool flagging = describe_engine(c, engine, cl, say_line);
  std::optional<ScanSource> scan;
  cl.step([&] { scan.emplace(c, fp); });
  const bool per_detector_file = scan->per_detector();
  const std::size_t samples_per_detector = scan->samples_per_detector();
  const std::uint64_t total = std::uint64_t(samples_per_detector) * fp.size();
  say("scan: %s, %zu detectors x %zu samples\n", scan_kind_name(c.scan.kind), fp.size(), samples_per_detector);

  // The host's share of this process (the engine's threads on the cpu and simd backends) for the
  // per-sample host work of the stream: detector pointing and binning.
  const unsigned host_threads = stream_host_threads(c, engine, cl);
  int maps_nside = 0;
  const std::unique_ptr<RunMapmaker> mapmaker =
      make_mapmaker(c, sky, engine, ground_engine.has_value(), host_threads, cl, maps_nside);
  const fs::path tod_path = c.output.dir / "tod.h5";
  std::optional<pisco::TodWriter> tod_file;
  if (c.output.tod) tod_file = open_tod_file(c, tod_path, sky, made, engine, fp, samples_per_detector, flagging, cl);

  const std::size_t chunk = std::min(c.engine.chunk_samples, std::max<std::size_t>(samples_per_detector, 1));
  const JobPlan plan = plan_jobs(fp.size(), samples_per_detector, chunk, per_detector_file, cl, [&](std::size_t d) {
    return disc_pixels(beams[fp[d].beam], sky.nside(), engine.sidelobe_nside());
  });
  std::uint64_t my_samples = 0;
  for (std::size_t i = plan.my_first; i < plan.my_end; ++i) my_samples += plan.at(i).count;
  obs.begin_convolution(my_samples);
  const auto tc = std::chrono::steady_clock::now();
  std::uint64_t flagged = 0;
  {
    JobStream stream(c, fp, *scan, engine, {mapmaker.get(), tod_file ? &*tod_file : nullptr}, flagging, chunk,
                     host_threads, obs, ground_engine ? &*ground_engine : nullptr);
    stream.run(plan, cl);
    flagged = stream.flagged();
    if (ground_engine) ground_summary(stream.ground_stats(), cl, result, sky.units(), say_line);
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
  result.flagged = flagged = cl.sum(flagged);
  if (mapmaker) cl.step([&] { result.reduced_bytes = mapmaker->reduce(cl); });
  if (flagging)
    say("flags: %llu of %llu samples flagged (their disc holds an UNSEEN pixel)%s\n",
        static_cast<unsigned long long>(flagged), static_cast<unsigned long long>(total),
        tod_file ? "; the TOD file's 'flags' datasets" : "");

  // What the map-maker solves beyond the reduction (the deconvolving one replays the survey), then
  // its maps and spectra: the leader's. A run whose maps solve no pixel has no maps to speak of: no
  // spectra (and pisco-vk makes no plots and exits with status 4).
  const std::function<void(const std::string&)> log = [&](const std::string& line) { obs.log(line); };
  const MapmakerEnd end{c, sky, maps_nside, flagging, plan, fp, *scan, say_line, log, result};
  if (mapmaker) mapmaker->solve(end);
  std::string nothing_solved;
  cl.step([&] {
    if (!cl.leader() || !mapmaker) return;
    const MapOutputs out = mapmaker->write(end);
    result.written.insert(result.written.end(), out.written.begin(), out.written.end());
    result.solved_pixels = out.solved;
    nothing_solved = out.nothing_solved;
  });
  result.nothing_solved = cl.broadcast(nothing_solved);

  result.samples = total;
  result.detectors = fp.size();
  result.samples_per_detector = samples_per_detector;
  result.mean_disc_pixels = mean_disc;
  result.convolution_seconds = conv;
  result.backend = engine.backend_name();
  result.device = engine.device_name();
  if (tod_file) result.tod_file = tod_path;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace pisco
