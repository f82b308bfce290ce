// The survey of a run as a stream (pisco::Simulation, simulation.cpp): the boresight made chunk by chunk,
// the plan of jobs (a detector's span of samples) over the processes, each job's pointing, and the
// stream of jobs through the engine into the map-makers and the TOD file. Internal.
#pragma once

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

#include "scans/scan_kind.hpp"
#include "pipeline/mapmaker_kind.hpp"
#include "core/detector_pointing.hpp"
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
#include "pisco/simulation.hpp"

namespace pisco::detail {

namespace fs = std::filesystem;


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
  Boresight(const ScanConfig& s, const HwpConfig& hwp) : scan_(pisco::detail::scan_kind(s.kind).make(s)), hwp_(hwp) {
    if (hwp_.angles_from_file && !(scan_->file() && scan_->file()->has_hwp_angle()))
      throw pisco::Error(s.file.string() + ": [hwp] gives no rotation or steps, and the pointing file has no "
                                           "'hwp_angle' dataset (expected one of them)");
  }
  bool quaternions() const { return scan_->quaternions(); }
  std::size_t size() const { return scan_->samples(); }
  // With `pool`, the scans whose samples do not depend on each other (ScanGenerator::by_blocks) in
  // blocks of samples on its threads: the same values.
  void fill(std::size_t first, std::size_t count, BoresightChunk& out, pisco::detail::ThreadPool* pool = nullptr) const {
    out.first = first;
    out.quaternions = quaternions();
    constexpr std::size_t block = 4096;
    if (pool && pool->size() > 1 && count > block && scan_->by_blocks()) {
      if (out.quaternions) out.quats.resize(count);
      else
        for (auto* v : {&out.angles.theta, &out.angles.phi, &out.angles.psi}) v->resize(count);
      pool->parallel_for(count, block, [&](std::size_t begin, std::size_t end) {
        pisco::Pointing angles;
        std::vector<pisco::Quat> quats;
        scan_->generate(first + begin, end - begin, angles, quats);
        if (out.quaternions) {
          std::copy(quats.begin(), quats.end(), out.quats.begin() + std::ptrdiff_t(begin));
          return;
        }
        std::copy(angles.theta.begin(), angles.theta.end(), out.angles.theta.begin() + std::ptrdiff_t(begin));
        std::copy(angles.phi.begin(), angles.phi.end(), out.angles.phi.begin() + std::ptrdiff_t(begin));
        std::copy(angles.psi.begin(), angles.psi.end(), out.angles.psi.begin() + std::ptrdiff_t(begin));
      });
    } else {
      scan_->generate(first, count, out.angles, out.quats);
    }
    out.angle_quats_made = false;
    out.hwp.clear();
    if (hwp_.angles_from_file) scan_->file()->read_hwp_angle(first, count, out.hwp);
    else if (hwp_.enabled) hwp_.stream.generate(first, count, out.hwp);
  }

 private:
  std::unique_ptr<const pisco::detail::ScanGenerator> scan_;
  HwpConfig hwp_;
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
                  const RunContext& cl, const std::function<double(std::size_t)>& disc);

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
    fresh_ = key != loaded_;
    if (fresh_) {
      slot_ ^= 1;
      if (per_detector) file_[slot_] = scan_.detector_pointing(job.detector);
      else scan_.fill(job.first, job.count, bore_[slot_], pool_);
      loaded_ = key;
    }
    pisco::SurveyChunk chunk;
    chunk.detector = job.detector;
    chunk_slot_ = slot_;
    // A plate's angles for a detector with a plate, or with beams that turn with it.
    const bool plate = fp_[job.detector].hwp.has_value() || fp_[job.detector].plate_beams.has_value();
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
    // A beam that changes with time: sample i of the run at time i / the scan's rate.
    if (!fp_[job.detector].beam_sequence.empty()) {
      time_slot_ ^= 1;
      std::vector<double>& t = time_[std::size_t(time_slot_)];
      t.resize(job.count);
      for (std::size_t i = 0; i < job.count; ++i) t[i] = double(job.first + i) / c_.sample_rate;
      chunk.time = t;
    }
    return chunk;
  }

  // The slot of the chunk load() returned last: a chunk stays valid until two more loads.
  int chunk_slot() const { return chunk_slot_; }
  // Whether load() loaded that chunk's pointing (rather than finding it loaded for the job before).
  bool fresh() const { return fresh_; }
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
  bool fresh_ = false;
  std::array<BoresightChunk, 2> bore_;
  std::array<pisco::Pointing, 2> file_;
  std::array<std::vector<double>, 2> time_;  // the chunks' sample times, alternately (a beam that changes with time)
  int time_slot_ = 0;
  std::size_t loaded_ = static_cast<std::size_t>(-1);  // the detector or the first sample loaded last
  int slot_ = 1;
};

// Calls f with a job's pointing view, angles or quaternions.
template <class F>
decltype(auto) with_view(const pisco::SurveyChunk& chunk, F&& f) {
  return chunk.quaternions ? f(chunk.quats) : f(chunk.angles);
}

// What the TOD streams into: the run's map-maker and the TOD file (each absent when not asked for).
struct StreamSinks {
  RunMapmaker* mapmaker = nullptr;
  pisco::TodWriter* tod = nullptr;
};

// The run as a stream of jobs (a detector's chunk), two in flight: while the engine convolves job
// j, job j - 1 is binned and written and job j + 1's pointing is prepared, so that the device never
// waits for the host (Engine::submit). Jobs alternate between two TOD buffers, and time chunks
// between two boresight buffers: the pending job is never more than one behind.
class JobStream {
 public:
  JobStream(const SimulationConfig& c, const FocalPlane& fp, const ScanSource& scan, Engine& engine, StreamSinks sinks,
            bool flagging, std::size_t chunk, unsigned host_threads, RunObserver& obs, Engine* ground = nullptr)
      : c_(c), fp_(fp), engine_(engine), sinks_(sinks), flagging_(flagging), obs_(obs),
        modelled_(fp.detectors()), host_(host_threads), pointing_(c, fp, scan, &host_), ground_(ground),
        ground_stats_(fp.size()) {
    for (auto& t : tod_) t.resize(chunk);
    // The detectors as the map-maker models them (with [hwp] mapmaker = "ideal": an ideal plate in
    // place of the real one; beams that turn with the plate: an ideal plate at the aperture, at their
    // plate angles).
    if (c.hwp.ideal_mapmaker)
      for (auto& d : modelled_)
        if (d.hwp) d.hwp->mueller = pisco::ideal_hwp_mueller();
    for (auto& d : modelled_)
      if (d.plate_beams) d.hwp = pisco::HalfWavePlate::ideal(d.plate_beams->gamma);
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

  // [ground]: each detector's pickup, summed over this process's samples.
  struct GroundStats {
    double sum = 0.0, sum2 = 0.0, min = 1e300, max = -1e300;
    std::uint64_t n = 0;
  };
  const std::vector<GroundStats>& ground_stats() const { return ground_stats_; }

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
      if (!plan.detectors_outermost) {
        // A boresight chunk is checked once, and staged for a device once a slot, for all its
        // detectors (Engine::share).
        pisco::SharedPointing& shared = shared_[std::size_t(j.pointing_slot)];
        if (pointing_.fresh())
          shared = with_view(j.chunk, [&](const auto& view) { return engine_.share(view); });
        j.ticket = engine_.submit(span.detector, shared, t, false, j.chunk.hwp_angle, j.chunk.time);
      } else {
        j.ticket = with_view(j.chunk, [&](const auto& view) {
          return engine_.submit(span.detector, view, t, false, j.chunk.hwp_angle, j.chunk.time);
        });
      }
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

  // [[sources]]: each source's response added to the job's TOD, sample i of the detector's run at time
  // i / rate (docs/sources.md).
  void add_sources(const Job& j, std::span<double> t) {
    const pisco::SurveyChunk& chunk = j.chunk;
    times_.resize(chunk.size());
    for (std::size_t i = 0; i < times_.size(); ++i)
      times_[i] = c_.sample_rate > 0 ? double(j.first + i) / c_.sample_rate : 0.0;
    try {
      with_view(chunk, [&](const auto& view) {
        engine_.add_sources(chunk.detector, view, times_, c_.sources, t, chunk.hwp_angle);
      });
    } catch (const pisco::Error& e) {
      throw pisco::Error(c_.source.string() + ": [[sources]]: " + e.what(), e.kind());
    }
  }

  // [ground]: the ground map convolved with the detector's beam at the boresight's horizon pointing
  // (docs/ground.md), added to the job's TOD.
  void add_ground(const Job& j, std::span<double> t) {
    const pisco::SurveyChunk& chunk = j.chunk;
    ground_tod_.resize(t.size());
    try {
      // A time chunk's horizon pointing is made once and shared by its detectors (Engine::share).
      if (horizon_shared_.size() == 0 || j.first != horizon_first_ || t.size() != horizon_.size()) {
        horizon_shared_ = pisco::SharedPointing{};
        c_.scan.ces.generate_horizon(j.first, t.size(), horizon_);
        horizon_first_ = j.first;
        horizon_shared_ = ground_->share(horizon_.view());
      }
      ground_->wait(
          ground_->submit(chunk.detector, horizon_shared_, ground_tod_, false, chunk.hwp_angle, chunk.time));
    } catch (const pisco::Error& e) {
      throw pisco::Error(c_.source.string() + ": [ground]: " + e.what(), e.kind());
    }
    GroundStats& g = ground_stats_[chunk.detector];
    for (std::size_t i = 0; i < t.size(); ++i) {
      const double x = ground_tod_[i];
      t[i] += x;
      g.sum += x;
      g.sum2 += x * x;
      g.min = std::min(g.min, x);
      g.max = std::max(g.max, x);
    }
    g.n += t.size();
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
    if (!c_.sources.empty()) add_sources(j, t);
    if (ground_) add_ground(j, t);
    // The map-maker takes the boresight's quaternions (one conversion per time chunk for every
    // detector) and applies the detector's offset itself; the detector's angles are made only for the
    // TOD file's pointing or weights, or from a per-detector file.
    const bool tod_pointing = sinks_.tod && (c_.output.tod_pointing || c_.output.tod_weights);
    const bool mapping = sinks_.mapmaker != nullptr;
    const pisco::QuatPointingView boresight =
        mapping && !tod_pointing ? pointing_.boresight_quats(j.pointing_slot, host_) : pisco::QuatPointingView{};
    const bool from_boresight = mapping && !tod_pointing && boresight.size() == count;
    if ((mapping && !from_boresight) || tod_pointing)
      with_view(chunk, [&](const auto& view) {
        pisco::detail::detector_pointing(view, fp_[chunk.detector].offset, own_, host_);
      });
    const pisco::PointingView detector_view = own_.view();
    std::span<const std::uint8_t> fl;
    if (flagging_) fl = flag_samples(chunk);
    if (sinks_.mapmaker)
      sinks_.mapmaker->add({chunk, modelled_[chunk.detector], t,
                            ground_ ? std::span<const double>(ground_tod_.data(), count) : std::span<const double>(), fl,
                            from_boresight ? boresight.subspan(0, count) : pisco::QuatPointingView{}, detector_view});
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
  std::array<pisco::SharedPointing, 2> shared_;  // the boresight chunks as shared, by JobPointing's slot
  std::array<std::vector<double>, 2> tod_;
  std::array<std::vector<double>, 2> hwp_;  // per-detector files: a job's plate angles, by TOD buffer
  std::optional<Job> pending_;
  int next_slot_ = 0;
  pisco::Pointing own_;
  std::vector<double> weights_;
  std::vector<double> times_;  // the sources' sample times of a job
  Engine* ground_ = nullptr;   // [ground]: the engine over the ground map
  pisco::Pointing horizon_;    // a time chunk's boresight in the horizon frame, made once for its jobs
  std::size_t horizon_first_ = 0;
  pisco::SharedPointing horizon_shared_;
  std::vector<double> ground_tod_;
  std::vector<GroundStats> ground_stats_;
  std::vector<std::uint8_t> flags_;
  std::uint64_t flagged_ = 0;
};

// The survey as the deconvolving map-maker replays it each iteration: this process's jobs of `plan`,
// in order, a chunk at a time.
void replay_survey(const JobPlan& plan, const SimulationConfig& c, const FocalPlane& fp, const ScanSource& scan,
                   const std::function<void(const pisco::SurveyChunk&)>& visit);


// The threads of this process's per-sample host work in the stream: the engine's own on the cpu and
// simd backends when they are set, else the host's hardware threads shared by the node's processes.
unsigned stream_host_threads(const SimulationConfig& c, const Engine& engine, const RunContext& cl);

}  // namespace pisco::detail
