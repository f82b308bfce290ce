// A simulation file (docs/config.md): one TOML file naming the sky, beams, focal plane, scan, engine and
// outputs of a run, read into the structs below. pisco::Simulation (simulation.hpp) runs it, as
// `pisco-vk run` does; docs/config.md documents every key, docs/library.md the C++ and Python calls.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/engine.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/ground.hpp"
#include "pisco/sources.hpp"
#include "pisco/focal_plane_file.hpp"
#include "pisco/hwp.hpp"
#include "pisco/scan.hpp"
#include "pisco/sky.hpp"
#include "pisco/tod_file.hpp"

namespace pisco {

struct SkyConfig {
  std::filesystem::path file;    // a HEALPix FITS map, or empty to synthesize
  std::filesystem::path cl_file; // C_l table for synthesis
  int nside = 128;
  int lmax = 0;                  // 0: 2 nside
  double r = 0.0;
  std::filesystem::path bb_template;  // tensor BB D_l table for r = 1 (columns l, BB); empty: the bundled one
  std::uint64_t seed = 1;
  bool unpolarized = false;      // Q = U = 0 after synthesis or loading
  std::vector<double> point_source;  // theta, phi (rad), I, Q, U, V: one non-zero pixel (paper 6.1)
  std::string units;
  UnseenPolicy unseen = UnseenPolicy::error;  // a map file's UNSEEN pixels
};

// [beams.NAME] type.
enum class BeamKind { gaussian, elliptical, file, grasp, blm, sequence, plate };
// Its name in simulation files ("gaussian", ...).
const char* beam_kind_name(BeamKind kind) noexcept;

struct BeamConfig {
  std::string name;
  BeamKind kind = BeamKind::gaussian;
  double fwhm = 0, fwhm_x = 0, fwhm_y = 0, angle = 0;  // radians
  BeamOptions options;
  std::filesystem::path file;
  int set = 0;                   // grasp: the beam of the file (1-based; 0 = its only one)
  bool temperature_only = false; // blm: a T-only file meant for polarized detectors (else an error)
  // sequence: a beam that changes with time (docs/changing.md), the beams named `nodes` (other [beams]
  // tables, neither sequences nor plate beams) at `node_times` (seconds from the run's first sample),
  // interpolated linearly. plate: a beam that turns with the half-wave plate, the beams named `nodes`
  // at plate angles k plate_period / N from each detector's plate gamma, interpolated trigonometrically.
  std::vector<double> node_times;
  std::vector<std::string> nodes;
  double plate_period = 3.14159265358979323846;  // radians
  // plate: the [beams] table whose Omega~ normalizes the plate beams (PlateBeams::omega: the beam without
  // the plate, which keeps the plate's losses); empty: their mean Omega~.
  std::string plate_normalize_by;
  // sequence and plate: made of other tables' beams
  bool combines_beams() const;
  // grasp and blm: the beam turns with each detector (its co-polar axis along the detector's zeta)
  bool turns_with_detector() const;
};

// [scan] type.
enum class ScanKind { pixel_centres, random_offsets, raster, ces, satellite, file };
// Its name in simulation files ("pixel_centres", ...).
const char* scan_kind_name(ScanKind kind) noexcept;

struct ScanConfig {
  ScanKind kind = ScanKind::pixel_centres;
  int nside = 64;
  std::vector<double> psi;       // radians
  double f = 0.1;
  bool symmetric = false;
  std::uint64_t seed = 1;
  double theta = 0, phi = 0, radius = 0;  // raster centre and radius, radians
  std::filesystem::path file;
  CesScan ces;                   // kind ces
  SatelliteScan satellite;       // kind satellite
};

// [hwp]: one half-wave plate model for the focal plane, with per-detector overrides.
struct HwpConfig {
  bool enabled = false;                  // an [hwp] table is present
  HalfWavePlate plate;                   // M0 and placement (gamma: per detector)
  HwpAngleStream stream;                 // continuous or stepped; sample_rate from the scan or the table
  bool angles_from_file = false;         // the pointing file's per-sample `hwp_angle`
  bool ideal_mapmaker = false;           // bin the maps with an ideal plate's model (mapmaker = "ideal")
  std::string rate_key;                  // the key that gave the rotation: rpm or frequency_hz
};

struct EngineConfig {
  EngineOptions options;
  std::size_t chunk_samples = 1 << 16;
  // Names the backend after the file was read (pisco-vk run -b, Python's backend=): the settings the
  // file gave are checked against it again, and one it does not have is an error naming `source`'s key, as
  // the file form's own refusal ("the vulkan backend has no threads setting (it applies to cpu and
  // simd)"), instead of a setting silently dropped.
  void set_backend(const std::string& name, const std::filesystem::path& source);
};

struct OutputConfig {
  std::filesystem::path dir = "pisco-out";
  bool tod = true;
  TodPrecision tod_precision = TodPrecision::float64;
  bool tod_pointing = false;
  bool tod_weights = false;  // each sample's (I, Q, U) weights in the TOD file
  bool maps = true;
  int maps_nside = 0;            // 0: the scan's NSIDE (or the sky's for pointing files)
  double rcond_min = 1e-3;
  bool spectra = true;
  int lmax = 0;                  // 0: 2 maps_nside
  bool deconvolve_beam = true;
  bool deconvolve_pixel_window = false;
  bool plots = true;             // for pisco-vk run's plotting tool; the library makes no plots
};

// [mapmaker] (docs/config.md): the binned map-maker (the default), or the beam-deconvolving one
// (pisco::DeconvolvingMapmaker) with its options.
enum class MapmakerKind { binned, deconvolve };
struct MapmakerConfig {
  MapmakerKind kind = MapmakerKind::binned;
  int iterations = 40;          // deconvolve: the most conjugate-gradient iterations
  double tolerance = 1e-6;      // deconvolve: ||r|| / ||A^T d|| to stop at
  double regularization = 1e-3; // deconvolve: lambda as a fraction of A^T A's Rayleigh quotient
  bool regularize_polarization_only = false;  // deconvolve: lambda on Q, U, V only
  double target_fwhm = 0.0;     // deconvolve: radians; > 0: maps.fits reconvolved with this Gaussian
};

// [ground]: the ground through the far sidelobes of a ces scan (docs/ground.md): a map in the horizon
// frame, read from `file` (in the sky's units) or made from the model (its brightness `temperature`
// kelvin Rayleigh-Jeans, converted to the sky's units at `frequency_ghz`), at `nside`.
struct GroundConfig {
  bool enabled = false;
  std::filesystem::path file;
  GroundModel model;              // value filled from temperature when the run makes the map
  double temperature = 300.0;     // K (Rayleigh-Jeans)
  double frequency_ghz = 0.0;     // for skies in K_CMB or uK_CMB
  int nside = 128;
  // The ground engine's backend; empty: the run's own ([engine] backend).
  std::string backend;
};

struct SimulationConfig {
  std::filesystem::path source;  // the simulation file ("" for built-in defaults)
  std::string text;              // its contents, recorded as provenance
  SkyConfig sky;
  std::vector<BeamConfig> beams;
  std::vector<Detector> detectors;
  std::vector<DetectorHwp> detector_hwp;  // parallel to detectors (entries may be empty)
  HwpConfig hwp;
  ScanConfig scan;
  EngineConfig engine;
  OutputConfig output;
  MapmakerConfig mapmaker;
  // [[sources]]: point sources added to every detector's TOD (docs/sources.md), their times seconds
  // from the run's first sample.
  std::vector<SourceTrack> sources;
  GroundConfig ground;
  // The samples' rate (Hz) that gives each sample's time, i / sample_rate, for the sources and for beams
  // that change with time (the scan's; 0 when the scan has none, which only fixed sources and beams allow).
  double sample_rate = 0.0;
};

// Reads and checks a simulation file (docs/config.md). Relative paths inside it are relative to its
// directory ([output] dir excepted: relative to the working directory). Throws pisco::Error naming
// the file and the key on anything unexpected, unknown keys included.
SimulationConfig read_simulation_file(const std::filesystem::path& file);

// What float64 carries over a run of `samples` samples with the [hwp] plate's angle stream
// (docs/formats.md, "Times, rates and angles"): throws pisco::Error naming the file and [hwp] key.
void check_hwp_times(const SimulationConfig& c, std::size_t samples);

}  // namespace pisco
