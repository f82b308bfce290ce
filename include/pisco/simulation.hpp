// A whole simulation, as `pisco-vk run` does it (docs/library.md): sky -> beams -> focal plane -> scan ->
// engine -> TOD file -> binned maps -> spectra, streaming the TOD chunk by chunk through the map-maker
// and the TOD file, so that memory stays bounded whatever the length of the scan. Simulation::run()
// chains the parts declared here (make_sky, make_beams, make_engine, write_maps, write_spectra_files), which
// a framework may also call one by one.
//
// The library knows nothing of MPI: a run of several processes (docs/scaling.md) goes through a
// RunContext, which pisco-vk implements over MPI; the default is one process. What a run says (its log
// lines, its progress) goes to a RunObserver. Every file is written under a temporary name and renamed
// when whole (output_file.hpp): an error leaves no half-written output.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/simulation_config.hpp"
#include "pisco/sky.hpp"
#include "pisco/spectra.hpp"

namespace pisco {

// The processes of a run and what they do together. The default is one process: every call below is
// then trivial. An implementation over MPI (pisco-vk's, docs/scaling.md) makes each call collective:
// every process makes the same calls in the same order.
class RunContext {
 public:
  virtual ~RunContext() = default;
  virtual int rank() const { return 0; }
  virtual int size() const { return 1; }
  virtual int node_rank() const { return 0; }  // among the processes of this node
  virtual int node_size() const { return 1; }
  bool leader() const { return rank() == 0; }
  bool parallel() const { return size() > 1; }

  // Runs f. With several processes, every step that can fail on one of them is a step: an exception
  // is passed to the others, so that every process ends with the message of the lowest failing one.
  virtual void step(const std::function<void()>& f) { f(); }
  // Every process passes its error (none: nullopt); when any has one, every process throws.
  virtual void agree(const std::optional<std::string>& error);
  virtual std::string broadcast(const std::string& text_of_leader) { return text_of_leader; }
  virtual void barrier() {}
  virtual double max(double v) { return v; }
  virtual std::uint64_t sum(std::uint64_t v) { return v; }
  virtual double sum_of(double v) { return v; }
  // Adds every process's normal equations into the leader's map-maker; returns the bytes sent.
  virtual std::uint64_t reduce(BinnedMapmaker& /*mapper*/) { return 0; }
  // Replaces `values` on every process by their sum over the processes, the same bits on each (the
  // deconvolving map-maker's maps, DeconvolutionOptions::reduce).
  virtual void sum_in_place(std::span<double> /*values*/) {}
  // For SharedTodOptions::mpi_communicator (tod_file.hpp): the communicator's address, or null.
  virtual const void* mpi_communicator() const { return nullptr; }
  // Early stop on an error elsewhere: post_check(failed) after each job of this process, stop() says
  // whether a completed check saw a failure, finish_checks(total, failed) posts the rest and waits.
  virtual void post_check(bool /*failed*/) {}
  virtual bool stop() { return false; }
  virtual void finish_checks(std::size_t /*total*/, bool /*failed*/) {}
  // Whether this process fails on purpose after its first job (fault injection for the tests).
  virtual bool inject_failure() const { return false; }
};

// The one-process context.
RunContext& serial_run_context();

// What a run says as it goes. log() receives each line of the run's account (with its '\n', as
// `pisco-vk run` prints them: "sky: ...", "beam ...", "backend: ...", "scan: ...", "maps: ..."), on
// the leading process only; the convolution's progress comes in samples of this process.
class RunObserver {
 public:
  virtual ~RunObserver() = default;
  virtual void log(const std::string& /*line*/) {}
  virtual void begin_convolution(std::uint64_t /*samples*/) {}
  virtual void advance(std::uint64_t /*samples*/) {}
  virtual void end_convolution() {}
};

struct SimulationOptions {
  // Holds assets/spectra/tensor_bb_r1.txt, the tensor BB template of [sky] r > 0 without bb_template;
  // empty: default_data_dir().
  std::filesystem::path data_dir;
  // Whether run() takes the output directory's OutputLock (include/pisco/output_file.hpp) for its
  // duration. false: the caller holds it already (pisco-vk does, from before the run to after its
  // plots); run() checks that it does.
  bool lock_output = true;
};

// $PISCO_DATA_DIR, else the installed share/pisco, else the source tree the library was built from.
std::filesystem::path default_data_dir();

// The sky of [sky]: a map file, a point source, or a synthesis from C_l (with r and the tensor
// template under data_dir/assets/spectra when [sky] names none).
Sky make_sky(const SkyConfig& sky, const std::filesystem::path& data_dir);

// One [beams] table as a beamsor; `angle` turns GRASP and b_lm beams (a detector's zeta). Errors name
// `source` (the simulation file) and the table.
// `progress`, when given, is told of a build that takes more than a few seconds (FileBeamOptions).
Beamsor make_beam(const BeamConfig& beam, const std::filesystem::path& source, double angle = 0.0,
                  const std::function<void(const std::string&)>& progress = {});

// The beamsors of a run and its detectors pointed at them. GRASP and b_lm beams turn with their
// detectors (docs/beams.md, "Which way a beam points"): one beamsor per beam and detector angle zeta.
struct SimulationBeams {
  std::vector<Beamsor> beams;
  std::vector<std::string> names;   // the [beams] table of each beamsor
  std::vector<Detector> detectors;  // the configuration's, each pointed at its beamsor
};
// `log` receives one line per beamsor made ("beam NAME: ...").
SimulationBeams make_beams(const SimulationConfig& config,
                           const std::function<void(const std::string&)>& log = {});

// [ground]'s map in the horizon frame (docs/ground.md), in the sky's units: the file's (whose units, when
// it gives them, must be the sky's), or the model at its NSIDE with its temperature in those units.
Sky make_ground_sky(const GroundConfig& ground, const Sky& sky, const std::filesystem::path& origin);

// The engine of a run: [engine]'s options with [sky] unseen. With several processes on a node, they
// share it out: the cpu and simd backends' hardware threads, or the devices of a GPU backend, process
// k on the node taking device k modulo their number.
Engine make_engine(const SkyView& sky, const std::vector<Beamsor>& beams, const FocalPlane& focal_plane,
                   const SimulationConfig& config, const RunContext& context = serial_run_context());

// The cost model that shares a run out between processes (docs/scaling.md, "How a run is shared out"):
// the sky pixels a sample of this beam sums, (1 - cos rho_max) / 2 * 12 NSIDE^2 (at least 1), plus a
// split beam's outer part on the sidelobe sky (Engine::sidelobe_nside). A job costs its samples times it.
double disc_pixels(const Beamsor& beam, int sky_nside, int sidelobe_nside);

// The NSIDE of the maps: [output] maps_nside, else the scan's (the sky's for pointing files).
int maps_nside(const SimulationConfig& config, const Sky& sky);

// The Gaussian beam window the spectra are divided by: exact for a Gaussian, the Gaussian of the
// geometric-mean width for an elliptical beam; none for beams from files.
std::optional<double> window_fwhm(const BeamConfig& beam);

// maps.fits (I, Q, U in the sky's units) and hits.fits in `dir`, each written whole or not at all.
// Returns the pixels solved.
std::size_t write_maps(const std::filesystem::path& dir, const BinnedMaps& maps, int nside, const std::string& units);

// A spectra file: a header line, then l and D_l = l(l+1)C_l/2pi of TT EE BB TE EB TB for l = 2..lmax,
// written whole or not at all.
void write_spectra(const std::filesystem::path& file, const Spectra& spectra, int lmax, const std::string& header);

// The spectra of a run's maps (spectra.txt: divided by window_fwhm's Gaussian window of the first
// detector's beam with [output] deconvolve_beam, by the pixel window with deconvolve_pixel_window) and
// of its input sky (input_spectra.txt), in [output] dir, up to [output] lmax (default 2 maps_nside).
// Returns the two files.
std::vector<std::filesystem::path> write_spectra_files(const SimulationConfig& config, const Sky& sky,
                                                       const BinnedMaps& maps, int maps_nside);

// What a run did.
struct SimulationResult {
  std::uint64_t samples = 0;             // of every detector and process
  std::size_t detectors = 0;
  std::size_t samples_per_detector = 0;
  double mean_disc_pixels = 0;           // over every process's samples
  double convolution_seconds = 0;        // the slowest process's
  double seconds = 0;                    // run() from start to end
  std::string backend, device;           // the engine's
  std::uint64_t flagged = 0;             // samples flagged ([sky] unseen = "flag")
  std::uint64_t reduced_bytes = 0;       // normal equations sent between processes
  std::filesystem::path tod_file;        // empty: no TOD file
  std::vector<std::filesystem::path> written;  // every file written, in order
  std::size_t solved_pixels = 0;
  // [mapmaker] type = "deconvolve": its iterations and final ||r|| / ||A^T d||, and whether it
  // reached the tolerance.
  int deconvolution_iterations = 0;
  double deconvolution_residual = 0.0;
  bool deconvolution_converged = true;
  // What the run finished with but should not be trusted without a look, a line each: a
  // deconvolution that did not converge, maps whose polarization no pixel's angles constrain.
  // pisco-vk prints each as a warning and exits with status 5.
  std::vector<std::string> warnings;
  // Not empty when the maps solve no pixel: why (maps.fits is all UNSEEN; no spectra were made).
  std::string nothing_solved;
  // [ground]: what the detectors picked up from the ground (docs/ground.md), in the sky's units over
  // every detector's samples: its mean, its scan-synchronous part (the RMS about each detector's own
  // mean, over the detectors) and the largest peak to peak of a detector's.
  double ground_mean = 0.0, ground_rms = 0.0, ground_peak_to_peak = 0.0;
};

class Simulation {
 public:
  explicit Simulation(SimulationConfig config, SimulationOptions options = {});
  // read_simulation_file(file): throws pisco::Error naming the file and key.
  static Simulation from_file(const std::filesystem::path& file, SimulationOptions options = {});

  const SimulationConfig& config() const noexcept { return config_; }
  SimulationConfig& config() noexcept { return config_; }  // e.g. output.dir, engine.options.backend
  const SimulationOptions& options() const noexcept { return options_; }

  // Runs it: the output directory is made when missing, the TOD file, maps and spectra written into
  // it. Throws pisco::Error naming the file, key or sample (each output written whole or not at all).
  SimulationResult run(RunContext& context, RunObserver* observer = nullptr) const;
  SimulationResult run(RunObserver* observer = nullptr) const { return run(serial_run_context(), observer); }

 private:
  SimulationConfig config_;
  SimulationOptions options_;
};

}  // namespace pisco
