// Simulation files (docs/config.md): TOML read key by key into pisco::SimulationConfig, every error naming
// the file and key.
#include "pisco/simulation_config.hpp"

#include <functional>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>

#include "io/focal_plane_file.hpp"
#include "io/toml_table.hpp"
#include "beams/beam_kind.hpp"
#include "core/registry.hpp"
#include "pipeline/mapmaker_kind.hpp"
#include "scans/scan_kind.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/spectra.hpp"
#include "pisco/time_ranges.hpp"
#include "pisco/units.hpp"

namespace pisco {

const char* beam_kind_name(BeamKind kind) noexcept {
  const detail::BeamKindEntry* k = detail::registered_kind(detail::beam_kinds(), kind);
  return k ? k->name : "?";
}

bool BeamConfig::combines_beams() const { return detail::beam_kind(kind).combines_beams; }
bool BeamConfig::turns_with_detector() const { return detail::beam_kind(kind).turns_with_detector; }

const char* scan_kind_name(ScanKind kind) noexcept {
  const detail::ScanKindEntry* k = detail::registered_kind(detail::scan_kinds(), kind);
  return k ? k->name : "?";
}

namespace {

using namespace detail;
using pisco::deg;

SkyConfig read_sky(Table t) {
  SkyConfig s;
  s.file = t.input_file("file");
  if (t.has("point_source")) {
    const std::vector<double> p = t.numbers("point_source", {});
    if (p.size() != 6) t.fail("point_source", "expected [theta_deg, phi_deg, I, Q, U, V]");
    if (p[0] < 0 || p[0] > 180)
      t.fail("point_source", "theta_deg = " + Table::format(p[0]) + " is outside [0, 180] (the colatitude)");
    s.point_source = {p[0] * deg, p[1] * deg, p[2], p[3], p[4], p[5]};
    s.units = t.string("units", "K");
    if (s.units.size() > 68 || std::any_of(s.units.begin(), s.units.end(), [](char ch) { return ch < ' ' || ch > '~'; }))
      t.fail("units", "expected at most 68 printable ASCII characters (a FITS TUNIT), got \"" + s.units + "\"");
  }
  s.nside = t.nside("nside", 128);
  s.lmax = static_cast<int>(t.integer_in("lmax", 0, 0, 4LL * s.nside, "0 (2 nside) or a multipole up to 4 nside = " +
                                                                            std::to_string(4LL * s.nside)));
  s.r = t.number("r", 0.0);
  s.seed = static_cast<std::uint64_t>(t.integer_in("seed", 1, 0, INT64_MAX, "a non-negative integer"));
  if (t.has("unseen") && s.file.empty())
    t.fail("unseen", "only for a map file (file = \"map.fits\"): what to do with its UNSEEN pixels");
  try {
    s.unseen = pisco::unseen_policy_from(t.string("unseen", "error"));  // the engine's names, one list
  } catch (const pisco::Error& e) {
    t.fail("unseen", e.what());
  }
  s.unpolarized = t.boolean("unpolarized", false);
  s.cl_file = t.input_file("cl_file");
  s.bb_template = t.input_file("bb_template");
  if (s.r < 0 || !std::isfinite(s.r)) t.fail("r", "expected r >= 0");
  if (!s.file.empty() && (t.has("nside") || t.has("seed") || t.has("cl_file") || t.has("r") || t.has("point_source")))
    t.fail("file", "give either a map file or the synthesis keys (nside, seed, cl_file, r), not both");
  if (!s.point_source.empty() && (t.has("seed") || t.has("cl_file") || t.has("r")))
    t.fail("point_source", "a point source takes nside and units only");
  if (s.cl_file.empty()) s.cl_file = pisco::default_cl_file();
  t.finish();
  return s;
}

// [beams.NAME]: its type, then that kind's keys (beams/beam_kind.hpp: one reader a kind).
BeamConfig read_beam(Table t, const std::string& name) {
  BeamConfig b;
  b.name = name;
  const detail::BeamKindEntry& kind =
      *detail::beam_kind_named(t.choice("type", "gaussian", detail::registered_names(detail::beam_kinds())));
  b.kind = kind.kind;
  kind.read(t, b);
  t.finish();
  return b;
}

// The beams that change with time or turn with the plate: each of their beams a [beams] table that
// combines none, and a scan whose samples have times or an [hwp] table that gives the plate's angles.
void check_combined_beams(const SimulationConfig& c, const toml::table& beams, const fs::path& file) {
  for (const BeamConfig& b : c.beams) {
    if (!b.combines_beams()) continue;
    Table t(*beams.get(b.name)->as_table(), "beams." + b.name, file);
    for (std::size_t k = 0; k < b.nodes.size(); ++k) {
      const auto it = std::find_if(c.beams.begin(), c.beams.end(), [&](const BeamConfig& x) { return x.name == b.nodes[k]; });
      if (it == c.beams.end()) {
        std::string names;
        for (const BeamConfig& x : c.beams)
          if (!x.combines_beams()) names += (names.empty() ? "" : ", ") + x.name;
        t.fail("beams", "beam " + std::to_string(k) + " is \"" + b.nodes[k] + "\", which is not a [beams] table (expected one of: " +
                            names + ")");
      }
      if (it->combines_beams())
        t.fail("beams", "beam " + std::to_string(k) + " is \"" + b.nodes[k] + "\", itself a " +
                            (it->kind == BeamKind::sequence ? "beam that changes with time" : "beam that turns with the plate") +
                            "; name fixed beams");
    }
    if (b.kind == BeamKind::plate && !b.plate_normalize_by.empty()) {
      const auto it = std::find_if(c.beams.begin(), c.beams.end(),
                                   [&](const BeamConfig& x) { return x.name == b.plate_normalize_by; });
      if (it == c.beams.end() || it->combines_beams())
        t.fail("normalize_by", "\"" + b.plate_normalize_by + "\" is not a [beams] table of a fixed beam (the beam "
                               "without the plate, whose Omega~ keeps the plate's losses)");
    }
    if (b.kind == BeamKind::plate) {
      if (!c.hwp.enabled)
        t.fail("type", "a beam that turns with the plate needs the plate's angles: an [hwp] table (rpm, frequency_hz or "
                       "steps_deg, or a pointing file's angles); the plate itself is in the beams");
      continue;
    }
    if (c.sample_rate <= 0)
      t.fail("type", "a beam that changes with time needs each sample's time: a ces or satellite scan (sample i at i / "
                     "its sample rate), not " + std::string(scan_kind_name(c.scan.kind)));
  }
}

// [scan]: its type, then that kind's keys (scans/scan_kind.hpp: one reader a kind).
ScanConfig read_scan(Table t) {
  ScanConfig s;
  const detail::ScanKindEntry& kind =
      *detail::scan_kind_named(t.choice("type", "pixel_centres", detail::registered_names(detail::scan_kinds())));
  s.kind = kind.kind;
  kind.read(t, s);
  t.finish();
  return s;
}

// The TOD is streamed in chunks of at most this many samples (two buffers of 128 MiB at float64).
constexpr std::int64_t max_chunk_samples = std::int64_t(1) << 24;

EngineConfig read_engine(Table t) {
  EngineConfig e;
  // Each setting as pisco::set_engine_option takes it; its errors name their key.
  const auto set = [&](const char* key, const pisco::EngineValue& value) {
    try {
      pisco::set_engine_option(e.options, key, value);
    } catch (const pisco::Error& err) {
      t.fail(err.key().empty() ? key : err.key(), err.what());
    }
  };
  set("backend", t.string("backend", "auto"));
  // Then every other setting of the engine's table by its name, but two: chunk_samples here is the
  // stream's chunk (below; the device backends fit theirs), and unseen belongs to the [sky] map.
  for (const pisco::EngineSetting& s : pisco::engine_settings()) {
    const std::string key = s.name;
    if (key == "backend" || key == "chunk_samples" || key == "unseen" || !t.has(key)) continue;
    if (s.number) set(s.name, static_cast<long long>(t.integer(key, 0)));
    else set(s.name, t.string(key, ""));
  }
  const auto chunk = t.integer_in("chunk_samples", 1 << 16, 1, max_chunk_samples,
                                  "a number of samples from 1 to " + std::to_string(max_chunk_samples));
  e.chunk_samples = static_cast<std::size_t>(chunk);
  t.finish();
  return e;
}

}  // namespace

void EngineConfig::set_backend(const std::string& name, const std::filesystem::path& source) {
  try {
    pisco::set_engine_option(options, "backend", name);  // checks the file's settings against it
  } catch (const pisco::Error& err) {
    throw pisco::Error((source.empty() ? std::string("simulation") : source.string()) + ": " + err.named("[engine] ") +
                           "; the backend was named after the file (" + name + ")",
                       err.kind());
  }
}

namespace {

OutputConfig read_output(Table t) {
  OutputConfig o;
  o.dir = t.string("dir", "pisco-out");  // relative to the working directory, not to the file
  if (o.dir.empty()) t.fail("dir", "expected a directory name");
  o.tod = t.boolean("tod", true);
  o.tod_precision = t.choice("tod_precision", "float64", {"float64", "float32"}) == "float64"
                        ? pisco::TodPrecision::float64
                        : pisco::TodPrecision::float32;
  o.tod_pointing = t.boolean("tod_pointing", false);
  o.tod_weights = t.boolean("tod_weights", false);
  o.maps = t.boolean("maps", true);
  const std::int64_t maps_nside = t.integer("maps_nside", 0);
  if (maps_nside != 0 && !pisco::valid_nside(maps_nside))
    t.fail("maps_nside", "expected a power of two from 1 to " + std::to_string(pisco::max_nside) +
                             " (or 0: the scan's), got " + std::to_string(maps_nside));
  o.maps_nside = static_cast<int>(maps_nside);
  o.rcond_min = t.number_in("rcond_min", 1e-3, 0, 1, "a reciprocal condition number in [0, 1]");
  o.spectra = t.boolean("spectra", true);
  o.lmax = static_cast<int>(t.integer_in("lmax", 0, 0, 4LL * pisco::max_nside,
                                         "0 (2 maps_nside) or a multipole up to 4 maps_nside"));
  o.deconvolve_beam = t.boolean("deconvolve_beam", true);
  o.deconvolve_pixel_window = t.boolean("deconvolve_pixel_window", false);
  o.plots = t.boolean("plots", true);
  if (o.spectra && !o.maps) t.fail("spectra", "spectra are computed from the maps: set maps = true");
  t.finish();
  return o;
}

// [mapmaker] (docs/config.md).
// [mapmaker]: its type, through the registry of kinds (pipeline/mapmaker_kind.hpp), and that kind's
// keys; another kind's key is an error naming that kind.
MapmakerConfig read_mapmaker(Table t) {
  MapmakerConfig m;
  const detail::MapmakerKindEntry& kind =
      *detail::mapmaker_kind_named(t.choice("type", "binned", detail::registered_names(detail::mapmaker_kinds())));
  m.kind = kind.kind;
  for (const detail::MapmakerKindEntry* other : detail::mapmaker_kinds())
    for (const char* key : other->keys)
      if (t.has(key) && std::find_if(kind.keys.begin(), kind.keys.end(), [&](const char* k) {
                          return std::string_view(k) == key;
                        }) == kind.keys.end())
        t.fail(key, std::string("only for type = \"") + other->name + "\"");
  kind.read(t, m);
  t.finish();
  return m;
}

// The samples' rate of a scan that has one (ces, satellite: sample i at time i / rate); 0 for the others.
double scan_sample_rate(const ScanConfig& scan) { return detail::scan_kind(scan.kind).sample_rate(scan); }

// [hwp] (docs/config.md): the plate model and its angle stream.

HwpConfig read_hwp(Table t, const ScanConfig& scan) {
  HwpConfig h;
  h.enabled = true;
  const std::string model = t.choice("model", "ideal", {"ideal", "mueller"});
  if (model == "mueller") {
    if (!t.has("mueller")) t.fail("mueller", "model = \"mueller\" needs the plate's 16 Mueller elements, row by row");
    const std::vector<double> m = t.numbers("mueller", {});
    if (m.size() != 16) t.fail("mueller", "expected 16 numbers, row by row, got " + std::to_string(m.size()));
    for (int i = 0; i < 16; ++i) {
      if (!std::isfinite(m[i])) t.fail("mueller", "entry " + std::to_string(i) + " is not finite");
      h.plate.mueller[i / 4][i % 4] = m[i];
    }
  } else if (t.has("mueller")) {
    t.fail("mueller", "only with model = \"mueller\"");
  }
  h.plate.placement = t.choice("placement", "aperture", {"aperture", "detector"}) == "aperture"
                          ? pisco::HwpPlacement::aperture
                          : pisco::HwpPlacement::detector;
  h.ideal_mapmaker = t.choice("mapmaker", "same", {"same", "ideal"}) == "ideal";
  const bool rotating = t.has("rpm") || t.has("frequency_hz");
  const bool stepped = t.has("steps_deg") || t.has("step_seconds");
  if (t.has("rpm") && t.has("frequency_hz")) t.fail("rpm", "give rpm or frequency_hz, not both");
  if (rotating && stepped) t.fail("steps_deg", "a plate either rotates (rpm, frequency_hz) or steps (steps_deg, step_seconds)");
  // The sample rate of the plate's angle stream: the scan's, or the table's own for scans without time.
  double rate = scan_sample_rate(scan);
  if (t.has("sample_rate_hz")) rate = t.positive("sample_rate_hz", 1.0);
  h.stream.sample_rate = rate;
  h.stream.start_time = t.number("start_time_s", 0.0);
  if (!std::isfinite(h.stream.start_time)) t.fail("start_time_s", "expected a finite number of seconds");
  if (rotating) {
    h.stream.kind = pisco::HwpAngleStream::Kind::continuous;
    h.rate_key = t.has("rpm") ? "rpm" : "frequency_hz";
    h.stream.frequency_hz = t.has("rpm") ? t.number("rpm", 0.0) / 60.0 : t.number("frequency_hz", 0.0);
    if (!std::isfinite(h.stream.frequency_hz)) t.fail(t.has("rpm") ? "rpm" : "frequency_hz", "expected a finite number");
  } else if (stepped) {
    h.stream.kind = pisco::HwpAngleStream::Kind::stepped;
    for (double a : t.numbers("steps_deg", {})) h.stream.steps.push_back(a * deg);
    if (h.stream.steps.empty()) t.fail("steps_deg", "a stepped plate needs at least one angle");
    for (std::size_t i = 0; i < h.stream.steps.size(); ++i)
      if (!std::isfinite(h.stream.steps[i])) t.fail("steps_deg", "angle " + std::to_string(i) + " is not finite");
    if (!t.has("step_seconds")) t.fail("step_seconds", "a stepped plate needs the time each angle is held");
    h.stream.step_seconds = t.positive("step_seconds", 1.0);
  } else if (scan.kind == ScanKind::file) {
    h.angles_from_file = true;  // the pointing file's hwp_angle dataset
  } else {
    t.fail("rpm", "expected the plate's rotation (rpm or frequency_hz) or its steps (steps_deg, step_seconds)");
  }
  h.stream.phase = t.number("phase_deg", 0.0) * deg;
  if (!std::isfinite(h.stream.phase)) t.fail("phase_deg", "expected a finite angle");
  if (!h.angles_from_file && !(h.stream.sample_rate > 0))
    t.fail("sample_rate_hz", "the scan has no sample rate (type = \"" + std::string(scan_kind_name(scan.kind)) +
                                 "\"): give the rate at which the plate's angle is sampled");
  t.finish();
  return h;
}

// Every detector gets the [hwp] plate unless its row says hwp = false, with its own gamma (its row's
// hwp_gamma_deg, a TOAST table's gamma, else its polarization angle in the focal plane: the offset's
// gamma plus zeta) and Mueller matrix (its row's hwp_mueller, else [hwp]'s).
void assign_plates(SimulationConfig& c, const fs::path& file) {
  c.detector_hwp.resize(c.detectors.size());
  for (std::size_t i = 0; i < c.detectors.size(); ++i) {
    pisco::Detector& d = c.detectors[i];
    const DetectorHwp& o = c.detector_hwp[i];
    const bool has_keys = o.enabled.has_value() || o.mueller.has_value() || o.gamma_key;
    if (!c.hwp.enabled) {
      if (has_keys && o.enabled.value_or(true))
        throw pisco::Error(file.string() + ": detector '" + d.name +
                           "' has half-wave plate keys (hwp, hwp_gamma_deg, hwp_mueller) but there is no [hwp] table");
      continue;
    }
    if (!o.enabled.value_or(true)) continue;
    pisco::HalfWavePlate plate = c.hwp.plate;
    if (o.mueller) plate.mueller = *o.mueller;
    plate.gamma = o.gamma.value_or(default_hwp_gamma(d));
    d.hwp = plate;
  }
}

}  // namespace

// [[sources]] (docs/config.md, docs/sources.md): each source's name, its times (time_s, seconds from the
// run's first sample) and at each time its direction (theta_deg, phi_deg) and flux (I, Q, U, V); a
// source without time_s is fixed, its values single numbers or arrays of one. Moving sources need the
// samples' times: a scan with a sample rate. `file` instead reads the track from a CSV file
// (SourceTrack::read_csv).
std::vector<SourceTrack> read_sources(const toml::array& list, const fs::path& file, double rate, std::size_t samples) {
  // A moving source's track must span the run's samples, at 0 to (samples - 1) / rate seconds.
  const auto check_span = [&](Table& t, const SourceTrack& s, const std::string& key) {
    if (s.time.size() < 2 || samples == 0 || !(rate > 0)) return;
    const double last = double(samples - 1) / rate;
    if (s.time.front() > 0.0 || s.time.back() < last)
      t.fail(key, "the track spans " + Table::format(s.time.front()) + " to " + Table::format(s.time.back()) +
                      " s, but the run's samples are at 0 to " + Table::format(last) +
                      " s (sample i at i / sample_rate_hz); extend it, with zero flux where the source is absent");
  };
  std::vector<SourceTrack> out;
  std::size_t i = 0;
  for (const auto& node : list) {
    const std::string where = "sources[" + std::to_string(i++) + "]";
    Table t(*node.as_table(), where, file);
    SourceTrack s;
    const auto name = t.string("name");
    if (!name || name->empty()) t.fail("name", "every source needs a name");
    s.name = *name;
    if (t.has("file")) {
      for (const char* key : {"time_s", "theta_deg", "phi_deg", "I", "Q", "U", "V"})
        if (t.has(key)) t.fail(key, "a source read from a track file (file) takes name and file only");
      s = SourceTrack::read_csv(t.input_file("file"), s.name);
      if (s.time.size() > 1 && !(rate > 0))
        t.fail("file", "a moving source needs the samples' times, which only a ces or satellite scan gives");
      check_span(t, s, "file");
      t.finish();
      out.push_back(std::move(s));
      continue;
    }
    const auto values = [&](const std::string& key, bool required) {
      const auto v = t.numbers_or_number(key);
      if (!v && required) t.fail(key, "missing: give a number, or an array with one value per time");
      return v.value_or(std::vector<double>{});
    };
    const bool moving = t.has("time_s");
    s.time = moving ? t.numbers("time_s", {}) : std::vector<double>{0.0};
    for (double& x : s.theta = values("theta_deg", true)) x *= deg;
    for (double& x : s.phi = values("phi_deg", true)) x *= deg;
    s.I = values("I", true);
    s.Q = values("Q", false);
    s.U = values("U", false);
    s.V = values("V", false);
    try {
      s.check(file.string() + ": [" + where + "]");
    } catch (const pisco::Error& e) {
      throw pisco::Error(std::string(e.what()) + " (keys time_s, theta_deg, phi_deg, I, Q, U, V)", e.kind());
    }
    if (moving && s.time.size() > 1 && !(rate > 0))
      t.fail("time_s", "a moving source needs the samples' times, which only a ces or satellite scan gives; use "
                       "one, or a fixed source");
    check_span(t, s, "time_s");
    t.finish();
    out.push_back(std::move(s));
  }
  return out;
}

// [ground] (docs/config.md, docs/ground.md): a map file in the horizon frame, or the model's keys.
GroundConfig read_ground(Table t, const ScanConfig& scan, const fs::path& file) {
  GroundConfig g;
  g.enabled = true;
  if (scan.kind != ScanKind::ces)
    throw pisco::Error(file.string() + ": [ground]: the ground is seen from constant-elevation scans; [scan] type is \"" +
                       std::string(scan_kind_name(scan.kind)) + "\" (expected \"ces\")");
  if (t.has("backend")) {
    std::vector<std::string> backends = pisco::Engine::backend_names();
    backends.push_back("auto");
    g.backend = t.choice("backend", "", backends);
  }
  g.file = t.input_file("file");
  if (!g.file.empty()) {
    for (const char* key : {"temperature_k", "frequency_ghz", "horizon_deg", "horizon_width_deg", "nside"})
      if (t.has(key)) t.fail(key, "a ground map file (file) takes no model keys");
    t.finish();
    return g;
  }
  g.temperature = t.number("temperature_k", 300.0);
  if (!(g.temperature >= 0.0 && g.temperature <= 1e4)) t.fail("temperature_k", "expected kelvin in [0, 1e4]");
  g.frequency_ghz = t.number("frequency_ghz", 0.0);
  if (!(g.frequency_ghz >= 0.0 && g.frequency_ghz <= 1e4)) t.fail("frequency_ghz", "expected GHz in (0, 1e4]");
  const std::vector<double> horizon = t.numbers("horizon_deg", {0.0});
  if (horizon.empty() || horizon.size() > 36000)
    t.fail("horizon_deg", "expected an array of 1 to 36000 elevations at equally spaced azimuths from north");
  g.model.horizon.clear();
  for (double h : horizon) {
    if (!(h > -90.0 && h < 90.0)) t.fail("horizon_deg", "expected elevations within (-90, 90) deg, got " + Table::format(h));
    g.model.horizon.push_back(h * deg);
  }
  g.model.width = t.number("horizon_width_deg", 1.0) * deg;
  if (!(g.model.width >= 0.0 && g.model.width <= 90.0 * deg))
    t.fail("horizon_width_deg", "expected a width in [0, 90] deg (0: a sharp edge)");
  const double nside = t.number("nside", 128.0);
  const int n = nside >= 1 && nside <= 8192 ? static_cast<int>(nside) : -1;
  if (!(n >= 1 && nside == n && (n & (n - 1)) == 0)) t.fail("nside", "expected a power of two in [1, 8192]");
  g.nside = n;
  t.finish();
  return g;
}

SimulationConfig read_simulation_file(const fs::path& file) {
  SimulationConfig c;
  c.source = file;
  const toml::table root = parse(file, &c.text);
  Table t(root, "top level", file);
  const toml::table* sky = t.table("sky");
  if (!sky) t.fail("sky", "missing [sky] table");
  c.sky = read_sky(Table(*sky, "sky", file));

  const toml::table* beams = t.table("beams");
  if (!beams || beams->empty()) t.fail("beams", "missing [beams.NAME] tables");
  for (const auto& [name, node] : *beams) {
    if (!node.is_table()) Table(*beams, "beams", file).fail(std::string(name.str()), "expected a table [beams." + std::string(name.str()) + "]");
    c.beams.push_back(read_beam(Table(*node.as_table(), "beams." + std::string(name.str()), file), std::string(name.str())));
  }

  std::vector<std::string> beam_names;
  for (const auto& b : c.beams) beam_names.push_back(b.name);
  const toml::table* fp = t.table("focal_plane");
  if (!fp) t.fail("focal_plane", "missing [focal_plane] table");
  Table fpt(*fp, "focal_plane", file);
  const fs::path fp_file = fpt.input_file("file");
  if (!fp_file.empty()) {
    if (fp->contains("detectors") || fp->contains("pairs")) fpt.fail("file", "give either a file or detectors/pairs, not both");
    if (is_hdf5_focal_plane(fp_file)) {
      // A TOAST table has no beam column: one beam for all its detectors.
      if (!fpt.has("beam") && c.beams.size() != 1)
        fpt.fail("beam", "a TOAST focal plane gives all its detectors one beam: name one of the [beams] tables");
      const pisco::ToastFocalPlane toast = pisco::read_toast_focal_plane(fp_file, beam_index(fpt, "beam", beam_names, true));
      c.detectors = toast.detectors;
      for (std::size_t i = 0; i < toast.gamma.size(); ++i) {  // TOAST's plate angle origin per detector
        c.detector_hwp.resize(c.detectors.size());
        c.detector_hwp[i].gamma = toast.gamma[i];
      }
    } else {
      if (fpt.has("beam"))
        fpt.fail("beam", "only for a TOAST focal plane (HDF5); a CSV or TOML table names each detector's beam itself");
      c.detectors = read_focal_plane_file(fp_file, beam_names, &c.detector_hwp);
    }
    fpt.finish();
  } else {
    read_detectors(*fp, "focal_plane", file, beam_names, c.detectors, &c.detector_hwp);
    if (c.detectors.empty()) fpt.fail("detectors", "no [[focal_plane.detectors]] or [[focal_plane.pairs]]");
  }

  const toml::table* scan = t.table("scan");
  if (!scan) t.fail("scan", "missing [scan] table");
  c.scan = read_scan(Table(*scan, "scan", file));
  const toml::table* engine = t.table("engine");
  c.engine = engine ? read_engine(Table(*engine, "engine", file)) : EngineConfig{};
  const toml::table* output = t.table("output");
  c.output = output ? read_output(Table(*output, "output", file)) : OutputConfig{};
  if (const toml::table* hwp = t.table("hwp")) c.hwp = read_hwp(Table(*hwp, "hwp", file), c.scan);
  if (const toml::table* mapmaker = t.table("mapmaker")) {
    Table mt(*mapmaker, "mapmaker", file);
    c.mapmaker = read_mapmaker(mt);
    detail::mapmaker_kind(c.mapmaker.kind).check(c, mt);  // what the kind refuses of the rest of the file
  }
  assign_plates(c, file);
  c.sample_rate = scan_sample_rate(c.scan);
  check_combined_beams(c, *beams, file);
  if (const toml::table* ground = t.table("ground")) c.ground = read_ground(Table(*ground, "ground", file), c.scan, file);
  if (const toml::array* sources = t.array_of_tables("sources")) {
    const std::size_t samples = detail::scan_kind(c.scan.kind).samples(c.scan);
    c.sources = read_sources(*sources, file, c.sample_rate, samples);
    if (c.engine.options.normalization != pisco::Normalization::integral)
      t.fail("sources", "point sources need [engine] normalization = \"integral\"");
  }
  t.finish();
  return c;
}

void check_hwp_times(const SimulationConfig& c, std::size_t samples) {
  if (!c.hwp.enabled || c.hwp.angles_from_file) return;
  try {
    c.hwp.stream.check(samples);
  } catch (const pisco::Error& e) {
    const std::string key = e.key() == "start_time" ? "start_time_s" : e.key() == "frequency" ? c.hwp.rate_key : e.key();
    throw pisco::Error(c.source.string() + ": [hwp] " + (key.empty() ? "" : key + ": ") + e.what() + " (over the run's " +
                       std::to_string(samples) + " samples)");
  }
}

}  // namespace pisco
