// A run's map-maker as one interface (docs/library.md, "How to add a map-maker"): the stream gives it
// each job's TOD, the run sums it over the processes and solves it, and the leading process writes its
// maps. A kind is one file in mapmakers/ and one line in mapmaker_kinds.cpp; the simulation file's
// reader and the run know kinds only through their entry. Internal.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "io/toml_table.hpp"
#include "pipeline/run_outputs.hpp"
#include "pisco/deconvolution.hpp"
#include "pisco/engine.hpp"
#include "pisco/simulation.hpp"
#include "pisco/simulation_config.hpp"

namespace pisco::detail {

struct JobPlan;     // pipeline/survey.hpp
class ScanSource;   // pipeline/survey.hpp

// One job's data as the map-makers take it (JobStream::finish).
struct MapmakerJob {
  const SurveyChunk& chunk;             // the detector, its pointing as the engine took it, plate angles
  const Detector& modelled;             // the detector as the map-makers model it ([hwp] mapmaker = "ideal")
  std::span<const double> tod;          // the sky's TOD (with sources and ground)
  std::span<const double> ground;       // [ground]: the ground's TOD alone; empty without
  std::span<const std::uint8_t> flags;  // [sky] unseen = "flag": the samples to leave out; empty: none
  // The pointing: the boresight's quaternions, the map-maker applying the detector's offset itself,
  // or, where `boresight` is empty, the detector's own angles.
  QuatPointingView boresight;
  PointingView detector;
};

// What a kind is made with, once the engine is made.
struct MapmakerSetup {
  const SimulationConfig& c;
  const Sky& sky;
  Engine& engine;
  int maps_nside;
  unsigned host_threads;  // the stream's host threads, for its per-sample work
  bool ground;            // [ground]: bin its TOD beside the sky's
  RunContext& cl;
};

// What a map-maker's solve and write see, after the stream.
struct MapmakerEnd {
  const SimulationConfig& c;
  const Sky& sky;
  int maps_nside;
  bool flagging;  // samples were flagged ([sky] unseen = "flag")
  const JobPlan& plan;
  const FocalPlane& fp;
  const ScanSource& scan;
  const std::function<void(const std::string&)>& say;  // a line of the run's account (the leader's)
  const std::function<void(const std::string&)>& log;  // a line of the account, from this process
  SimulationResult& result;
};

class RunMapmaker {
 public:
  virtual ~RunMapmaker() = default;
  // A job's TOD, on the stream's thread, in the order of the process's jobs.
  virtual void add(const MapmakerJob& job) = 0;
  // After the stream, on every process: sums what the processes added (RunContext::reduce); returns
  // the bytes every process sent, summed.
  virtual std::uint64_t reduce(RunContext& cl) = 0;
  // After the reduction, on every process: what the kind solves beyond it (it may replay the survey).
  virtual void solve(const MapmakerEnd&) {}
  // On the leading process: writes its maps and their spectra.
  virtual MapOutputs write(const MapmakerEnd& end) = 0;
};

// One kind of map-maker: its name (the [mapmaker] type), its keys and how it is made.
struct MapmakerKindEntry {
  MapmakerKind kind;
  const char* name;
  std::vector<const char*> keys;                 // its keys of the [mapmaker] table beside type
  void (*read)(Table& t, MapmakerConfig& m);     // reads them (type is read already)
  // What it refuses of the rest of the simulation file once it is read, named on [mapmaker]'s `t`.
  void (*check)(const SimulationConfig& c, const Table& t);
  // The NSIDE of its maps ([output] maps_nside, or what the kind solves at); throws naming the key.
  int (*maps_nside)(const SimulationConfig& c, const Sky& sky);
  std::unique_ptr<RunMapmaker> (*make)(const MapmakerSetup& s);
};

// Every kind, in the order of MapmakerKind; the kind of a name or of a MapmakerKind.
std::span<const MapmakerKindEntry* const> mapmaker_kinds();
const MapmakerKindEntry& mapmaker_kind(MapmakerKind kind);
const MapmakerKindEntry* mapmaker_kind_named(const std::string& name);

// The kinds (src/pipeline/mapmakers/), each one entry.
extern const MapmakerKindEntry binned_mapmaker_kind, deconvolve_mapmaker_kind;

}  // namespace pisco::detail
