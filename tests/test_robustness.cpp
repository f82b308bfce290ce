// The robustness suite (ctest label robustness; docs/validation.md, "Robustness"): malformed simulation
// files, FITS, HDF5 and CSV inputs, generated systematically and each run through `pisco-vk run`. Every
// one must end with exactly one `pisco-vk: error:` line naming the key or file at fault, exit status 2,
// and an empty output directory; corrupted files that still read must never crash the program.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "beam_file_writers.hpp"
#include "cli_runner.hpp"
#include "map_file_writers.hpp"
#include "pisco/pisco.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/scan.hpp"
#include "pisco/tod_file.hpp"

namespace {

namespace fs = std::filesystem;
using pisco_test::CliResult;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// ---- simulation files

const std::string base_config =
    "[sky]\nnside = 8\nlmax = 16\nseed = 3\n"
    "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 10.0\nrho_max_deg = 20.0\n"
    "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
    "[scan]\ntype = \"pixel_centres\"\nnside = 4\n"
    "[engine]\nbackend = \"cpu\"\nthreads = 1\n"
    "[output]\nplots = false\n";

// The track file of the source_file variant: a source crossing the ces variant's 72 s.
const std::string good_track = "time_s,theta_deg,phi_deg,I\n0,45,30,1\n60,45.5,30.5,1.1\n100,46,31,1\n";

// `text` with the table `header` ("[sky]", "[[focal_plane.pairs]]") replaced by `body`.
std::string with_table(const std::string& text, const std::string& header, const std::string& body) {
  const auto at = text.find(header + "\n");
  if (at == std::string::npos) return text + header + "\n" + body;
  const auto start = at + header.size() + 1;
  auto end = start;
  while (end < text.size() && text[end] != '[') end = text.find('\n', end) + 1;
  return text.substr(0, start) + body + text.substr(end);
}

// `text` without the table `header` and its keys.
std::string without_table(const std::string& text, const std::string& header) {
  const auto at = text.find(header + "\n");
  if (at == std::string::npos) return text;
  auto end = at + header.size() + 1;
  while (end < text.size() && text[end] != '[') end = text.find('\n', end) + 1;
  return text.substr(0, at) + text.substr(end);
}

// `text` with `key = value` in table `header` (replacing the key's line if there is one).
std::string with_key(const std::string& text, const std::string& header, const std::string& key,
                     const std::string& value) {
  const auto at = text.find(header + "\n");
  if (at == std::string::npos) return text + header + "\n" + key + " = " + value + "\n";
  const auto start = at + header.size() + 1;
  auto end = start;
  std::string body;
  while (end < text.size() && text[end] != '[') {
    const auto next = text.find('\n', end) + 1;
    const std::string line = text.substr(end, next - end);
    if (line.rfind(key + " =", 0) != 0) body += line;
    end = next;
  }
  return text.substr(0, start) + key + " = " + value + "\n" + body + text.substr(end);
}

// The variants of the base file in which each key is read.
std::string variant(const std::string& name) {
  std::string c = base_config;
  if (name == "base") return c;
  if (name == "r") return with_key(c, "[sky]", "r", "0.1");
  if (name == "point") return with_table(c, "[sky]", "nside = 8\npoint_source = [45, 30, 1, 0.1, 0, 0]\nunits = \"K\"\n");
  if (name == "file_sky") return with_table(c, "[sky]", "file = \"sky.fits\"\n");
  if (name == "elliptical")
    return with_table(c, "[beams.main]", "type = \"elliptical\"\nfwhm_x_deg = 10\nfwhm_y_deg = 12\nangle_deg = 10\nrho_max_deg = 20\n");
  if (name == "file_beam") return with_table(c, "[beams.main]", "type = \"file\"\nfile = \"beam.fits\"\nrho_max_deg = 20\n");
  if (name == "grasp_beam") return with_table(c, "[beams.main]", "type = \"grasp\"\nfile = \"beam.grd\"\nrho_max_deg = 20\nset = 1\n");
  if (name == "blm_beam") return with_table(c, "[beams.main]", "type = \"blm\"\nfile = \"beam_alm.fits\"\nrho_max_deg = 20\n");
  if (name == "split")
    return with_table(c, "[beams.main]", "type = \"gaussian\"\nfwhm_deg = 10.0\nrho_max_deg = 20.0\n"
                                         "sidelobe_split_deg = 12.0\nsidelobe_taper_deg = 3.0\nsidelobe_nside = 4\n");
  if (name == "detectors")
    return with_table(without_table(c, "[[focal_plane.pairs]]"), "[focal_plane]",
                      "[[focal_plane.detectors]]\nname = \"d\"\nbeam = \"main\"\n");
  if (name == "pair_ab")
    return with_table(c, "[[focal_plane.pairs]]", "name = \"p\"\nbeam_a = \"main\"\nbeam_b = \"main\"\n");
  if (name == "fp_file") return with_table(without_table(c, "[[focal_plane.pairs]]"), "[focal_plane]", "file = \"fp.csv\"\n");
  if (name == "random_offsets") return with_table(c, "[scan]", "type = \"random_offsets\"\nnside = 4\n");
  if (name == "raster") return with_table(c, "[scan]", "type = \"raster\"\nnside = 8\ntheta_deg = 60\nradius_deg = 20\n");
  if (name == "ces")
    return with_table(c, "[scan]", "type = \"ces\"\nsample_rate_hz = 2\nduration_hours = 0.02\naz_throw_deg = 40\nnside = 8\n");
  if (name == "satellite")
    return with_table(c, "[scan]", "type = \"satellite\"\nsample_rate_hz = 2\nduration_hours = 0.05\nnside = 8\n");
  if (name == "ces_rotating")  // the boresight turned through several angles
    return with_table(c, "[scan]", "type = \"ces\"\nsample_rate_hz = 2\nduration_hours = 0.02\naz_throw_deg = 40\n"
                                   "nside = 8\nboresight_deg = [-45, 0, 45]\nboresight_period_hours = 0.01\n");
  if (name == "scan_file") return with_table(c, "[scan]", "type = \"file\"\nfile = \"bore.h5\"\n");
  // Half-wave plates: a rotating plate (the scan has no time: the table gives the rate), one by
  // frequency, a stepped one, a Mueller matrix of its own, detectors of their own with plates, and the
  // angles of a pointing file's hwp_angle dataset.
  const std::string plate = "[hwp]\nrpm = 10\nsample_rate_hz = 2\n";
  if (name == "hwp") return c + plate;
  if (name == "hwp_frequency") return c + "[hwp]\nfrequency_hz = 0.5\nsample_rate_hz = 2\n";
  if (name == "hwp_steps") return c + "[hwp]\nsteps_deg = [0, 22.5, 45]\nstep_seconds = 10\nsample_rate_hz = 2\n";
  if (name == "hwp_mueller")
    return c + "[hwp]\nmodel = \"mueller\"\nmueller = [1, 0.01, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1]\n"
               "rpm = 10\nsample_rate_hz = 2\n";
  if (name == "hwp_detectors") return variant("detectors") + plate;
  if (name == "hwp_ces") return variant("ces") + "[hwp]\nrpm = 10\n";  // the scan's own sample rate
  if (name == "hwp_file") return with_table(c, "[scan]", "type = \"file\"\nfile = \"bore_hwp.h5\"\n") + "[hwp]\n";
  if (name == "plate") {  // a beam that turns with the plate, over the hwp_frequency variant's plate
    c = with_table(variant("hwp_frequency"), "[beams.side]", "type = \"gaussian\"\nfwhm_deg = 12.0\nrho_max_deg = 20.0\n");
    c = with_table(c, "[beams.turning]", "type = \"plate\"\nbeams = [\"main\", \"side\", \"main\"]\nperiod_deg = 180\n");
    return with_table(c, "[[focal_plane.pairs]]", "name = \"p\"\nbeam = \"turning\"\n");
  }
  if (name == "sequence") {  // a beam that changes with time over the ces scan's 72 s
    c = with_table(variant("ces"), "[beams.side]", "type = \"gaussian\"\nfwhm_deg = 12.0\nrho_max_deg = 20.0\n");
    c = with_table(c, "[beams.drift]", "type = \"sequence\"\ntimes_s = [0, 100]\nbeams = [\"main\", \"side\"]\n");
    return with_table(c, "[[focal_plane.pairs]]", "name = \"p\"\nbeam = \"drift\"\n");
  }
  // Point sources (integral normalization): one fixed, one moving over the ces scan's 72 s, one from a
  // track file.
  if (name == "source")
    return with_key(c, "[engine]", "normalization", "\"integral\"") +
           "[[sources]]\nname = \"s\"\ntheta_deg = 45\nphi_deg = 30\nI = 1e-3\n";
  if (name == "source_moving")
    return with_key(variant("ces"), "[engine]", "normalization", "\"integral\"") +
           "[[sources]]\nname = \"s\"\ntime_s = [0, 100]\ntheta_deg = [45, 46]\nphi_deg = [30, 31]\nI = [1, 1]\n"
           "Q = [0, 0.1]\n";
  if (name == "source_file")
    return with_key(variant("ces"), "[engine]", "normalization", "\"integral\"") +
           "[[sources]]\nname = \"s\"\nfile = \"track.csv\"\n";
  // The ground through far sidelobes over the ces scan: the model, and a ground map file.
  const std::string far_beam = "type = \"gaussian\"\nfwhm_deg = 10.0\nrho_max_deg = 60.0\nsidelobe_split_deg = 25\n"
                               "far_sidelobe_db = -30\nfar_sidelobe_deg = 45\nfar_sidelobe_width_deg = 8\n"
                               "far_sidelobe_angle_deg = 180\nfar_sidelobe_asymmetry = 0.5\n";
  if (name == "far_sidelobe") return with_key(with_table(c, "[beams.main]", far_beam), "[engine]", "normalization", "\"integral\"");
  if (name == "ground")
    return with_key(with_table(variant("ces"), "[beams.main]", far_beam), "[engine]", "normalization", "\"integral\"") +
           "[ground]\ntemperature_k = 270\nfrequency_ghz = 90\nhorizon_deg = [2, 8, 4]\nhorizon_width_deg = 2\nnside = 8\n";
  if (name == "ground_file")
    return with_key(with_table(variant("ces"), "[beams.main]", far_beam), "[engine]", "normalization", "\"integral\"") +
           "[ground]\nfile = \"ground.fits\"\n";
  ADD_FAILURE() << "no variant " << name;
  return c;
}

enum class Kind { integer, number, string, boolean, numbers, strings, choice, path };

struct Key {
  std::string variant, table, key;
  Kind kind;
  std::vector<std::string> out_of_range;  // values of the right type outside the key's range
  bool empty_valid = false;               // "" is a valid value
};

std::vector<std::string> wrong_values(const Key& k) {
  switch (k.kind) {
    case Kind::integer: return {"\"8\"", "8.5", "true", "[8]", "{ a = 1 }", "nan", "inf", "\"\""};
    case Kind::number: return {"\"1\"", "true", "[1]", "{ a = 1 }", "nan", "inf", "-inf", "\"\""};
    case Kind::boolean: return {"\"true\"", "1", "[true]", "nan", "\"\""};
    case Kind::numbers: return {"1", "\"x\"", "[]", "[\"a\"]", "[nan]", "[inf]", "[[1]]", "\"\"", "[true]"};
    case Kind::strings: return {"1", "\"x\"", "[]", "[1]", "[true]", "[[\"a\"]]", "\"\"", "{ a = 1 }"};
    case Kind::string:
    case Kind::choice:
    case Kind::path: {
      std::vector<std::string> v{"1", "true", "[\"a\"]", "{ a = 1 }", "nan"};
      if (!k.empty_valid) v.push_back("\"\"");
      if (k.kind == Kind::choice) v.push_back("\"nonsense\"");
      if (k.kind == Kind::path) {
        v.push_back("\"missing.file\"");
        v.push_back("\"subdir\"");  // a directory
      }
      return v;
    }
  }
  return {};
}

std::vector<Key> keys() {
  using K = Kind;
  const std::string sky = "[sky]", beam = "[beams.main]", pair = "[[focal_plane.pairs]]",
                    det = "[[focal_plane.detectors]]", fp = "[focal_plane]", scan = "[scan]", engine = "[engine]",
                    out = "[output]", hwp = "[hwp]";
  return {
      {"base", sky, "nside", K::integer, {"0", "3", "-8", "16384", "4294967304"}},
      {"base", sky, "lmax", K::integer, {"-1", "33", "2147483648"}},
      {"base", sky, "seed", K::integer, {"-1"}},
      {"base", sky, "r", K::number, {"-0.5"}},
      {"base", sky, "cl_file", K::path, {}},
      {"r", sky, "bb_template", K::path, {}},
      {"base", sky, "unpolarized", K::boolean, {}},
      {"base", sky, "unseen", K::choice, {"\"zero\""}},
      {"point", sky, "point_source", K::numbers,
       {"[1, 2, 3]", "[200, 0, 1, 0, 0, 0]", "[-1, 0, 1, 0, 0, 0]", "[1, 2, 3, 4, 5, 6, 7]"}},
      {"point", sky, "units", K::string, {"\"" + std::string(69, 'K') + "\""}, true},
      {"file_sky", sky, "file", K::path, {}},
      {"file_sky", sky, "unseen", K::choice, {}},
      {"base", sky, "nonsense_key", K::integer, {"1"}},
      {"base", beam, "type", K::choice, {}},
      {"base", beam, "fwhm_deg", K::number, {"0", "-1", "40", "1e300"}},
      {"base", beam, "rho_max_deg", K::number, {"0", "-1", "90", "1000"}},
      {"base", beam, "grid_step_arcmin", K::number, {"-1", "1e-9"}},
      {"base", beam, "cross_polar", K::number, {}},
      {"base", beam, "cross_polar_pattern", K::choice, {}},
      {"base", beam, "mueller", K::numbers, {"[1, 0, 0]", "[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]"}},
      {"elliptical", beam, "fwhm_x_deg", K::number, {"0", "-1"}},
      {"elliptical", beam, "fwhm_y_deg", K::number, {"0", "-1"}},
      {"elliptical", beam, "angle_deg", K::number, {}},
      {"file_beam", beam, "file", K::path, {}},
      {"grasp_beam", beam, "file", K::path, {}},
      {"grasp_beam", beam, "set", K::integer, {"-1", "2", "1.5"}},
      {"blm_beam", beam, "file", K::path, {}},
      {"split", beam, "sidelobe_split_deg", K::number, {"0", "-1", "20", "30"}},
      {"split", beam, "sidelobe_taper_deg", K::number, {"-1", "13"}},
      {"split", beam, "sidelobe_nside", K::integer, {"3", "-2", "16384"}},
      {"sequence", "[beams.drift]", "times_s", K::numbers, {"[0]", "[5, 1]", "[0, 0]", "[0, 10, 20]"}},
      {"plate", "[beams.turning]", "beams", K::strings,
       {"[\"main\"]", "[\"main\", \"nope\"]", "[\"main\", \"turning\"]", "[\"main\", \"\"]"}},
      {"plate", "[beams.turning]", "period_deg", K::number, {"0", "-180", "721", "1e300"}},
      {"plate", "[beams.turning]", "normalize_by", K::string, {"\"nowhere\"", "\"turning\""}},
      {"sequence", "[beams.drift]", "beams", K::strings,
       {"[\"main\"]", "[\"main\", \"nope\"]", "[\"main\", \"drift\"]", "[\"main\", \"\"]"}},
      {"far_sidelobe", beam, "far_sidelobe_db", K::number, {"1", "-201", "1e300"}},
      {"far_sidelobe", beam, "far_sidelobe_deg", K::number, {"0", "-5", "61", "1e300"}},
      {"far_sidelobe", beam, "far_sidelobe_width_deg", K::number, {"0", "-1", "181"}},
      {"far_sidelobe", beam, "far_sidelobe_angle_deg", K::number, {}},
      {"far_sidelobe", beam, "far_sidelobe_asymmetry", K::number, {"-0.1", "1.5"}},
      {"ground", "[ground]", "temperature_k", K::number, {"-1", "1e5"}},
      {"ground", "[ground]", "frequency_ghz", K::number, {"-1", "1e5"}},
      {"ground", "[ground]", "horizon_deg", K::numbers, {"[]", "[90]", "[0, -95]"}},
      {"ground", "[ground]", "horizon_width_deg", K::number, {"-1", "91"}},
      {"ground", "[ground]", "nside", K::integer, {"0", "3", "16384"}},
      {"ground_file", "[ground]", "file", K::path, {}},
      {"source", "[[sources]]", "name", K::string, {}},
      {"source_moving", "[[sources]]", "time_s", K::numbers, {"[5, 1]", "[0, 0]", "[10, 200]", "[0, 10]"}},
      {"source_moving", "[[sources]]", "theta_deg", K::numbers, {"[190, 45]", "[-1, 45]", "[0, 180]"}},
      {"source_moving", "[[sources]]", "phi_deg", K::numbers, {"[1, 2, 3]"}},
      {"source_moving", "[[sources]]", "I", K::numbers, {"[1]"}},
      {"source_moving", "[[sources]]", "Q", K::numbers, {"[1, 2, 3]"}},
      {"source_file", "[[sources]]", "file", K::path, {}},
      {"base", pair, "name", K::string, {}},
      {"base", pair, "zeta_deg", K::number, {}},
      {"base", pair, "epsilon", K::number, {"-0.1", "1.1"}},
      {"base", pair, "beam", K::string, {"\"side\""}},
      {"pair_ab", pair, "beam_a", K::string, {"\"side\""}},
      {"pair_ab", pair, "beam_b", K::string, {"\"side\""}},
      {"base", pair, "gain_a", K::number, {"0", "-1"}},
      {"base", pair, "gain_b", K::number, {"0", "-1"}},
      {"base", pair, "xi_deg", K::number, {"200"}},
      {"base", pair, "eta_deg", K::number, {"-190"}},
      {"base", pair, "xi_b_deg", K::number, {"200"}},
      {"base", pair, "eta_b_deg", K::number, {"185"}},
      {"base", pair, "gamma_deg", K::number, {}},
      {"detectors", det, "name", K::string, {}},
      {"detectors", det, "zeta_deg", K::number, {}},
      {"detectors", det, "epsilon", K::number, {"-1e-9", "2"}},
      {"detectors", det, "gain", K::number, {"0", "-2"}},
      {"detectors", det, "beam", K::string, {"\"side\""}},
      {"detectors", det, "xi_deg", K::number, {"180"}},
      {"detectors", det, "eta_deg", K::number, {"500"}},
      {"detectors", det, "gamma_deg", K::number, {}},
      {"fp_file", fp, "file", K::path, {}},
      {"fp_file", fp, "beam", K::string, {"\"main\""}},
      {"base", scan, "type", K::choice, {}},
      {"base", scan, "nside", K::integer, {"0", "3", "16384", "-4"}},
      {"base", scan, "psi_deg", K::numbers, {}},
      {"random_offsets", scan, "f", K::number, {"-0.1", "1.5"}},
      {"random_offsets", scan, "symmetric", K::boolean, {}},
      {"random_offsets", scan, "seed", K::integer, {"-1"}},
      {"raster", scan, "theta_deg", K::number, {"-1", "181"}},
      {"raster", scan, "phi_deg", K::number, {}},
      {"raster", scan, "radius_deg", K::number, {"0", "-1", "180"}},
      {"ces", scan, "latitude_deg", K::number, {"-91", "91"}},
      {"ces", scan, "longitude_deg", K::number, {}},
      {"ces", scan, "elevation_deg", K::number, {"0", "90", "-10"}},
      {"ces", scan, "az_centre_deg", K::number, {}},
      {"ces", scan, "az_throw_deg", K::number, {"-1"}},
      {"ces", scan, "az_speed_deg_s", K::number, {"0", "-1", "1e300"}},
      {"ces", scan, "sample_rate_hz", K::number, {"0", "-1"}},
      {"ces", scan, "start", K::string, {"\"yesterday\"", "\"2019-13-01T00:00:00Z\"", "\"2019-06-01T25:00:00Z\"",
                                         "\"99999999999-01-01T00:00:00Z\"", "\"2019-06-01T00:00:nanZ\"",
                                         "\"2019-06-01T-1:00:00Z\""}},
      {"ces", scan, "duration_hours", K::number, {"0", "-1", "1e12", "1e-9"}},
      {"ces", scan, "boresight_deg", K::numbers, {}},
      {"ces", scan, "boresight_period_hours", K::number, {"0", "-1", "1.7e308"}},
      {"ces_rotating", scan, "boresight_period_hours", K::number, {"1e-12"}},
      {"ces", scan, "nside", K::integer, {"0", "6"}},
      {"satellite", scan, "spin_sun_angle_deg", K::number, {"-1", "181"}},
      {"satellite", scan, "spin_boresight_angle_deg", K::number, {"0", "180", "-5"}},
      {"satellite", scan, "precession_period_min", K::number, {"0", "-1", "1.7e308", "1e-12"}},
      {"satellite", scan, "spin_period_min", K::number, {"0", "-1", "1.7e308", "1e-9"}},
      {"satellite", scan, "sample_rate_hz", K::number, {"0", "-1"}},
      {"satellite", scan, "start_time_s", K::number, {"1e20", "-1e20"}},
      {"satellite", scan, "precession_phase_deg", K::number, {}},
      {"satellite", scan, "spin_phase_deg", K::number, {}},
      {"satellite", scan, "frame", K::choice, {}},
      {"satellite", scan, "duration_hours", K::number, {"0", "1e12"}},
      {"scan_file", scan, "file", K::path, {}},
      {"hwp", hwp, "model", K::choice, {}},
      {"hwp_mueller", hwp, "mueller", K::numbers, {"[1, 0, 0]", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, 0]"}},
      {"hwp", hwp, "placement", K::choice, {}},
      {"hwp", hwp, "mapmaker", K::choice, {}},
      {"hwp", hwp, "rpm", K::number, {"1e300", "-1e300", "1e10"}},
      {"hwp_frequency", hwp, "frequency_hz", K::number, {"1e300", "5"}},
      {"hwp_ces", hwp, "rpm", K::number, {"1e300"}},
      {"hwp_ces", hwp, "start_time_s", K::number, {"1e300", "1e20"}},
      {"hwp", hwp, "phase_deg", K::number, {}},
      {"hwp_steps", hwp, "steps_deg", K::numbers, {}},
      {"hwp_steps", hwp, "step_seconds", K::number, {"0", "-1", "1e-9", "1e-300"}},
      {"hwp", hwp, "sample_rate_hz", K::number, {"0", "-2"}},
      {"hwp", hwp, "start_time_s", K::number, {"1e20"}},
      {"hwp_steps", hwp, "start_time_s", K::number, {"1e283"}},
      {"hwp", pair, "hwp", K::boolean, {}},
      {"hwp", pair, "hwp_gamma_deg", K::number, {}},
      {"hwp", pair, "hwp_mueller", K::numbers, {"[1, 0, 0, 0]"}},
      {"hwp_detectors", det, "hwp", K::boolean, {}},
      {"hwp_detectors", det, "hwp_gamma_deg", K::number, {}},
      {"hwp_detectors", det, "hwp_mueller", K::numbers, {"[1, 0, 0, 0]"}},
      {"base", engine, "backend", K::choice, {}},
      {"base", engine, "device", K::string, {}, true},
      {"base", engine, "normalization", K::choice, {}},
      {"base", engine, "arithmetic", K::choice, {}},
      {"base", engine, "threads", K::integer, {"-1", "1000000", "4294967297"}},
      {"base", engine, "chunk_samples", K::integer, {"0", "-1", "10000000000"}},
      {"base", out, "dir", K::string, {}},
      {"base", out, "tod", K::boolean, {}},
      {"base", out, "tod_precision", K::choice, {}},
      {"base", out, "tod_pointing", K::boolean, {}},
      {"base", out, "tod_weights", K::boolean, {}},
      {"base", out, "maps", K::boolean, {}},
      {"base", out, "maps_nside", K::integer, {"-1", "3", "16384"}},
      {"base", out, "rcond_min", K::number, {"-0.1", "1.5"}},
      {"base", out, "spectra", K::boolean, {}},
      {"base", out, "lmax", K::integer, {"-1", "17", "1000000"}},
      {"base", out, "deconvolve_beam", K::boolean, {}},
      {"base", out, "deconvolve_pixel_window", K::boolean, {}},
      {"base", out, "plots", K::boolean, {}},
  };
}

// ---- the fixture: a scratch directory with valid inputs beside the simulation files

class Robustness : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("pisco-robust-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "subdir");
    // A valid sky, beam, focal plane and pointing file, which the variants name.
    pisco::Sky sky(8, "K");
    for (std::size_t p = 0; p < sky.npix(); ++p) sky.I()[p] = 1e-3 * std::cos(0.1 * double(p));
    sky.write_fits(dir_ / "sky.fits");
    pisco::BeamOptions o;
    o.rho_max = 20 * pisco::deg;
    pisco::Beamsor::gaussian(10 * pisco::deg, o).write_healpix_fits(dir_ / "beam.fits", 64);
    // The same beam as a GRASP uv grid and as harmonic coefficients (docs/beams.md).
    const double s10 = 10 * pisco::deg / std::sqrt(8 * std::log(2.0));
    pisco_test::write_uv_grd(
        dir_ / "beam.grd",
        [s10](double rho, double, std::complex<double>& co, std::complex<double>& cx) {
          co = std::exp(-rho * rho / (4 * s10 * s10));
          cx = 0.0;
        },
        std::sin(25 * pisco::deg), 41);
    const pisco::HarmonicBeam blm = pisco_test::gaussian_blm(10 * pisco::deg, 64);
    pisco_test::write_alm_fits(dir_ / "beam_alm.fits", {&blm.t, &blm.e, &blm.b}, 64, 2);
    std::ofstream(dir_ / "fp.csv") << "name,zeta_deg,epsilon,gain,beam\nd1,0,0,1,main\nd2,90,0,1,main\n";
    std::ofstream(dir_ / "track.csv") << good_track;
    pisco::GroundModel ground;
    ground.value = 1e6;
    pisco::ground_sky(8, ground, "uK_CMB").write_fits(dir_ / "ground.fits");
    std::vector<pisco::Quat> q;
    pisco::SatelliteScan sat;
    sat.sample_rate = 1;
    sat.samples = 400;
    sat.generate(0, sat.samples, q);
    pisco::BoresightFile::write(dir_ / "bore.h5", q);
    pisco::BoresightFile::write(dir_ / "bore_hwp.h5", q, {}, plate_angles(q.size()));
  }
  // A plate turning at 1 rad per sample: the hwp_angle dataset of bore_hwp.h5.
  static std::vector<double> plate_angles(std::size_t n) {
    std::vector<double> h(n);
    for (std::size_t i = 0; i < n; ++i) h[i] = double(i);
    return h;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p;
  }
  // `text` with four bytes replaced by random ones, drawn from `rng`.
  static std::string with_random_bytes(std::string text, std::mt19937_64& rng) {
    for (int j = 0; j < 4; ++j) text[std::uniform_int_distribution<std::size_t>(0, text.size() - 1)(rng)] = char(rng());
    return text;
  }
  static std::string read(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

  // Runs `config` (written as case.toml) and checks the contract: one error line mentioning `needle`,
  // status 2, nothing in the output directory. Returns whether it held.
  static bool expect_clean_error(const std::string& what, const std::string& config, const std::string& needle) {
    const fs::path cfg = write("case.toml", config);
    const fs::path out = dir_ / "out";
    fs::remove_all(out);
    const CliResult r = pisco_test::run_cli({"run", "-q", cfg.string(), "-o", out.string()}, {}, 60);
    auto left = pisco_test::files_under(out);
    // The directory the run made is gone again, with its lock file.
    if (fs::exists(out)) left.push_back(out.filename().string() + "/ (the directory itself)");
    const bool ok = r.exited && r.status == 2 && r.error_lines() == 1 && left.empty() &&
                    (needle.empty() || contains(r.error_line(), needle));
    ++cases_;
    if (!ok) {
      ADD_FAILURE() << what << ": " << r.describe() << ", " << r.error_lines() << " error lines, left ["
                    << pisco_test::joined(left) << "], expected the error to mention '" << needle << "'\n"
                    << r.output << "\n--- case.toml:\n"
                    << config;
    }
    return ok;
  }

  // A corrupted input that may still read: no crash and no hang, at most one error line, and on an
  // error nothing in the output directory.
  static void expect_no_crash(const std::string& what, const std::string& config) {
    const fs::path cfg = write("case.toml", config);
    const fs::path out = dir_ / "out";
    fs::remove_all(out);
    const CliResult r = pisco_test::run_cli({"run", "-q", cfg.string(), "-o", out.string()}, {}, 60);
    ++cases_;
    // Status 4: the corrupted pointing solves no map pixel, which the run reports as such.
    const bool ok = r.exited && (r.status == 0 || r.status == 4 ||
                                 (r.status == 2 && r.error_lines() == 1 && pisco_test::files_under(out).empty()));
    if (!ok) ADD_FAILURE() << what << ": " << r.describe() << "\n" << r.output;
  }

  static fs::path dir_;
  static int cases_;
};

fs::path Robustness::dir_;
int Robustness::cases_ = 0;

// Every variant runs as it is: the failures below are the bad value's alone.
TEST_F(Robustness, VariantsRun) {
  for (const std::string v : {"base", "r", "point", "file_sky", "elliptical", "file_beam", "grasp_beam", "blm_beam",
                              "split", "detectors", "pair_ab",
                              "fp_file", "random_offsets", "raster", "ces", "satellite", "scan_file", "hwp",
                              "hwp_frequency", "hwp_steps", "hwp_mueller", "hwp_detectors", "hwp_file", "ces_rotating",
                              "hwp_ces", "sequence", "plate", "source", "source_moving", "source_file",
                              "far_sidelobe", "ground", "ground_file"}) {
    const fs::path cfg = write("variant.toml", variant(v));
    const CliResult r = pisco_test::run_cli({"run", "-q", cfg.string(), "-o", (dir_ / "variant-out").string()}, {}, 60);
    EXPECT_TRUE(r.exited && r.status == 0) << v << ": " << r.describe() << "\n" << r.output << "\n" << variant(v);
  }
}

// Every key: each wrong type, NaN and infinity, the empty value, and values outside its range.
TEST_F(Robustness, EveryKeyMalformed) {
  int n = 0;
  for (const Key& k : keys()) {
    std::vector<std::string> values = wrong_values(k);
    values.insert(values.end(), k.out_of_range.begin(), k.out_of_range.end());
    for (const std::string& v : values) {
      const std::string config = with_key(variant(k.variant), k.table, k.key, v);
      expect_clean_error(k.table + " " + k.key + " = " + v + " (" + k.variant + ")", config, k.key);
      ++n;
    }
  }
  std::cout << n << " malformed keys, each one clear error naming its key\n";
}

// Whole files and tables: missing, empty, duplicated, unknown, not TOML.
TEST_F(Robustness, MalformedFiles) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {"", "missing [sky]"},
      {"\n\n# nothing\n", "missing [sky]"},
      {std::string("\x89HDF\r\n\x1a\n\0\0\xff", 12), "not valid TOML"},
      {"[sky\nnside = 8\n", "not valid TOML"},
      {base_config + "[sky]\nnside = 8\n", "not valid TOML"},
      {"sky = 1\n" + base_config.substr(base_config.find("[beams")), "[top level] sky: expected a table"},
      {without_table(base_config, "[scan]"), "missing [scan]"},
      {base_config.substr(0, base_config.find("[beams")) + base_config.substr(base_config.find("[focal_plane]")),
       "missing [beams.NAME]"},
      {base_config + "[extra]\n", "unknown key 'extra'"},
      {base_config + "[beams.side]\nfwhm_deg = 'x'\n", "[beams.side] fwhm_deg"},
      {with_table(base_config, "[focal_plane]", "beam = \"main\"\n"), "[focal_plane]"},
      {without_table(base_config, "[[focal_plane.pairs]]"), "[focal_plane] detectors"},
      {with_table(base_config, "[[focal_plane.pairs]]", "beam = \"main\"\n"), "name"},
      {base_config + "[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n", "detector 'pa' is also defined"},
      {"\xff\xfe[sky]\n", "not valid TOML"},
  };
  for (const auto& [text, needle] : cases) expect_clean_error("file " + text.substr(0, 40), text, needle);
}

// Half-wave plates: keys that each read but do not go together, plate keys without a plate, and a
// pointing file whose angles are missing or not finite.
TEST_F(Robustness, MalformedHalfWavePlates) {
  const std::string c = base_config;
  const std::string rate = "sample_rate_hz = 2\n";
  const std::vector<std::pair<std::string, std::string>> cases{
      {c + "[hwp]\n" + rate, "expected the plate's rotation (rpm or frequency_hz) or its steps"},
      {c + "[hwp]\nrpm = 10\nfrequency_hz = 1\n" + rate, "[hwp] rpm: give rpm or frequency_hz, not both"},
      {c + "[hwp]\nrpm = 10\nsteps_deg = [0, 45]\nstep_seconds = 1\n" + rate, "[hwp] steps_deg: a plate either rotates"},
      {c + "[hwp]\nsteps_deg = [0, 45]\n" + rate, "[hwp] step_seconds: a stepped plate needs the time"},
      {c + "[hwp]\nstep_seconds = 1\n" + rate, "[hwp] steps_deg: a stepped plate needs at least one angle"},
      {c + "[hwp]\nmodel = \"mueller\"\nrpm = 10\n" + rate, "[hwp] mueller: model = \"mueller\" needs"},
      {c + "[hwp]\nmueller = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1]\nrpm = 10\n" + rate,
       "[hwp] mueller: only with model = \"mueller\""},
      {c + "[hwp]\nrpm = 10\n", "[hwp] sample_rate_hz: the scan has no sample rate"},
      {with_key(c, "[[focal_plane.pairs]]", "hwp", "true"), "detector 'pa' has half-wave plate keys"},
      {with_key(c, "[[focal_plane.pairs]]", "hwp_mueller", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1]"),
       "but there is no [hwp] table"},
      {with_key(c, "[[focal_plane.pairs]]", "hwp_gamma_deg", "10"), "detector 'pa' has half-wave plate keys"},
      {with_key(variant("scan_file"), "[hwp]", "phase_deg", "10"), "no rotation or steps, and the pointing file has no "
                                                                   "'hwp_angle' dataset"},
  };
  for (const auto& [text, needle] : cases) expect_clean_error("[hwp]: " + needle, text, needle);
  // The pointing file's plate angles: one not finite.
  std::vector<pisco::Quat> q;
  pisco::BoresightFile(dir_ / "bore_hwp.h5").read(0, 400, q);
  std::vector<double> h = plate_angles(q.size());
  h[321] = std::nan("");
  pisco::BoresightFile::write(dir_ / "bore_hwp.h5", q, {}, h);
  expect_clean_error("a NaN plate angle", variant("hwp_file"), "'/hwp_angle' sample 321 is not finite");
  pisco::BoresightFile::write(dir_ / "bore_hwp.h5", q, {}, plate_angles(q.size()));
}

// Source track files (docs/formats.md, "Source tracks"): every kind of bad header and row, each named
// by the file, its line and the column.
TEST_F(Robustness, MalformedTrackFiles) {
  const std::string cfg = variant("source_file");
  const std::vector<std::pair<std::string, std::string>> csv{
      {"", "track.csv: no header"},
      {"# nothing but this\n", "track.csv: no header"},
      {"time_s,theta_deg,phi_deg,I\n", "track.csv: no rows after the header"},
      {"time_s,theta_deg,phi_deg,flux\n", "track.csv:1: unknown column 'flux'"},
      {"time_s,theta_deg,I\n0,1,2\n", "track.csv:1: the header needs a 'phi_deg' column"},
      {"time_s,theta_deg,phi_deg,I,I\n", "track.csv:1: column 'I' appears twice"},
      {"time_s,theta_deg,phi_deg,I\n0,10,20\n", "track.csv:2: expected 4 fields, got 3"},
      {"time_s,theta_deg,phi_deg,I\n0,10,20,x\n", "track.csv:2: column 'I': expected a finite number, got 'x'"},
      {"time_s,theta_deg,phi_deg,I\n0,10,nan,1\n", "track.csv:2: column 'phi_deg'"},
      {"time_s,theta_deg,phi_deg,I\n0,10,inf,1\n", "track.csv:2: column 'phi_deg'"},
      {"time_s,theta_deg,phi_deg,I\n0,181,20,1\n", "track.csv:2: column 'theta_deg': 181 is outside [0, 180]"},
      {"time_s,theta_deg,phi_deg,I\n0,10,20,1\n0,10,20,1\n", "track.csv:3: column 'time_s': 0 does not follow"},
      {"time_s,theta_deg,phi_deg,I\n0,30,0,1\n100,150,180,1\n", "opposite the previous point's"},
      {"time_s,theta_deg,phi_deg,I\n10,30,0,1\n100,31,0,1\n", "[sources[0]] file: the track spans 10 to 100 s, but the run's samples are at 0 to 71.5 s"},
      {std::string("\0\1\2\3\xff,\n", 7), "track.csv:1"},
  };
  for (const auto& [text, needle] : csv) {
    write("track.csv", text);
    expect_clean_error("track.csv: " + text.substr(0, 30), cfg, needle);
  }
  write("track.csv", good_track);
}

// Focal-plane tables: CSV and TOML files with every kind of bad row.
TEST_F(Robustness, MalformedFocalPlaneTables) {
  const std::string cfg = variant("fp_file");
  const std::vector<std::pair<std::string, std::string>> csv{
      {"", "no detectors"},
      {"name,zeta_deg,beam\n", "no detectors"},
      {"zeta_deg,beam\n0,main\n", "'name' column"},
      {"name,zeta,beam\nd,0,main\n", "unknown column 'zeta'"},
      {"name,zeta_deg,beam\nd,0\n", "expected 3 fields"},
      {"name,zeta_deg,beam\nd,abc,main\n", "column 'zeta_deg'"},
      {"name,zeta_deg,beam\nd,nan,main\n", "column 'zeta_deg'"},
      {"name,zeta_deg,beam\nd,inf,main\n", "column 'zeta_deg'"},
      {"name,zeta_deg,beam\nd,1e999,main\n", "column 'zeta_deg'"},
      {"name,epsilon,beam\nd,1.5,main\n", "column 'epsilon'"},
      {"name,epsilon,beam\nd,-0.5,main\n", "column 'epsilon'"},
      {"name,gain,beam\nd,0,main\n", "column 'gain'"},
      {"name,gain,beam\nd,-1,main\n", "column 'gain'"},
      {"name,xi_deg,beam\nd,200,main\n", "'xi_deg'"},
      {"name,beam\nd,side\n", "no beam named 'side'"},
      {"name,beam\n,main\n", "empty detector name"},
      {"name,beam\nd,main\nd,main\n", "detector 'd' is also on line 2"},
      {"name,hwp,beam\nd,maybe,main\n", "column 'hwp'"},
      {"name,hwp_gamma_deg,beam\nd,abc,main\n", "column 'hwp_gamma_deg'"},
      {"name,hwp_gamma_deg,beam\nd,nan,main\n", "column 'hwp_gamma_deg'"},
      {"name,hwp,beam\nd,1,main\n", "detector 'd' has half-wave plate keys"},
      {std::string("\0\1\2\3\xff,\n", 7), "fp.csv:1"},
  };
  for (const auto& [text, needle] : csv) {
    write("fp.csv", text);
    expect_clean_error("fp.csv: " + text.substr(0, 30), cfg, needle);
  }
  write("fp.csv", "name,zeta_deg,epsilon,gain,beam\nd1,0,0,1,main\nd2,90,0,1,main\n");
  const std::string toml_cfg = with_table(without_table(base_config, "[[focal_plane.pairs]]"), "[focal_plane]",
                                          "file = \"fp.toml\"\n");
  const std::vector<std::pair<std::string, std::string>> toml{
      {"", "no [[detectors]] or [[pairs]]"},
      {"[[pairs]]\nname = \"p\"\nbeam = \"main\"\n[[detectors]]\nname = \"pa\"\nbeam = \"main\"\n", "detector 'pa'"},
      {"[[detectors]]\nname = \"d\"\nbeam = \"main\"\nepsilon = 3\n", "epsilon"},
      {"[[detectors]]\nname = \"d\"\nbeam = \"main\"\ngain = nan\n", "gain"},
      {"[[detectors]]\nname = \"d\"\nbeam = \"side\"\n", "no beam named \"side\""},
      {"[detectors]\nname = \"d\"\n", "detectors"},
  };
  for (const auto& [text, needle] : toml) {
    write("fp.toml", text);
    expect_clean_error("fp.toml: " + text.substr(0, 30), toml_cfg, needle);
  }
}

// Messages that name what is wrong: a misspelt key as unknown (with the nearest known key) even where
// the key it stands for is required, control characters from a file escaped, a byte-order mark
// skipped, a focal-plane table without beams where there are several, an empty -o.
TEST_F(Robustness, MessagesNameWhatIsWrong) {
  const std::string c = base_config;
  const std::vector<std::pair<std::string, std::string>> cases{
      {with_table(c, "[sky]", "nsid = 8\nlmax = 16\n"), "[sky] unknown key 'nsid' (did you mean 'nside'?)"},
      {with_table(c, "[beams.main]", "type = \"gaussian\"\nfwhm = 10.0\nrho_max_deg = 20.0\n"),
       "[beams.main] unknown key 'fwhm' (did you mean 'fwhm_deg'?)"},
      {with_table(c, "[beams.main]", "type = \"gaussian\"\nfwhm_deg = 10.0\nrho_max_dg = 20.0\n"),
       "unknown key 'rho_max_dg' (did you mean 'rho_max_deg'?)"},
      {without_table(c, "[scan]") + "[scna]\ntype = \"pixel_centres\"\n", "unknown key 'scna' (did you mean 'scan'?)"},
      {with_key(c, "[output]", "plots_x", "false"), "unknown key 'plots_x' (did you mean 'plots'?)"},
      {with_key(c, "[output]", "colour", "1"), "[output] unknown key 'colour'"},
      // A setting the named backend does not have (base_config's backend is cpu).
      {with_key(c, "[engine]", "device", "\"0\""),
       "[engine] device: the cpu backend has no device setting (it applies to simd, vulkan and cuda)"},
      {with_key(c, "[engine]", "arithmetic", "\"float64\""),
       "[engine] arithmetic: the cpu backend has no arithmetic setting (it applies to vulkan)"},
      {with_table(c, "[engine]", "backend = \"vulkan\"\nthreads = 2\n"),
       "[engine] threads: the vulkan backend has no threads setting (it applies to cpu and simd)"},
      // Values the table of settings does not take (pisco::set_engine_option): the same words as Python's
      // and the command line's, behind the file's own prefix.
      {with_key(c, "[engine]", "normalization", "\"per-sample\""),
       "[engine] normalization: expected \"integral\" or \"per_sample\", got \"per-sample\""},
      {with_key(c, "[engine]", "quadrature", "\"exact\""), "[engine] quadrature: expected \"corrected\" or \"plain\", got \"exact\""},
      {with_table(c, "[engine]", "backend = \"vulkan\"\narithmetic = \"double\"\n"),
       "[engine] arithmetic: expected \"auto\", \"float64\" or \"float-float\", got \"double\""},
      {with_key(c, "[engine]", "threads", "-2"), "[engine] threads: expected a number of zero or more, got -2"},
      {with_key(c, "[engine]", "threads", "\"four\""), "[engine] threads: expected an integer"},
  };
  for (const auto& [text, needle] : cases) expect_clean_error(needle, text, needle);

  // A control character from a file: shown as \x1B, never written raw to the terminal.
  const std::string fp_cfg = variant("fp_file");
  write("fp.csv", "name\x1b[31m,beam\nd,main\n");
  expect_clean_error("an escape sequence in a CSV header", fp_cfg, "unknown column 'name\\x1B[31m'");
  // Several beams, no beam column: an error, not every detector on the first beam.
  write("fp.csv", "name,zeta_deg\nd1,0\nd2,90\n");
  expect_clean_error("no beam column with two beams",
                     fp_cfg + "[beams.side]\ntype = \"gaussian\"\nfwhm_deg = 8.0\nrho_max_deg = 16.0\n",
                     "the header needs a 'beam' column: the configuration defines 2 beams");
  // A byte-order mark (spreadsheets write one): read as the header's first column.
  write("fp.csv", "\xEF\xBB\xBFname,zeta_deg,beam\nd1,0,main\nd2,90,main\n");
  const fs::path cfg = write("bom.toml", fp_cfg);
  const CliResult bom = pisco_test::run_cli({"run", "-q", cfg.string(), "-o", (dir_ / "bom-out").string()}, {}, 60);
  EXPECT_TRUE(bom.exited && bom.status == 0) << bom.describe() << "\n" << bom.output;
  // -o "": an error, not the configuration's directory.
  const CliResult empty = pisco_test::run_cli({"run", "-q", cfg.string(), "-o", ""}, {}, 60);
  EXPECT_TRUE(empty.exited && empty.status == 2 && empty.error_lines() == 1 &&
              contains(empty.error_line(), "-o/--output: expected a directory name, got an empty string"))
      << empty.describe() << "\n" << empty.output;
}

// FITS inputs (sky maps and beamsor files): truncated, with broken headers, NaN and UNSEEN pixels,
// not FITS at all; and, through a fixed set of random byte changes, corruptions that may still read.
TEST_F(Robustness, CorruptedFitsFiles) {
  const std::string sky = read(dir_ / "sky.fits"), beam = read(dir_ / "beam.fits");
  ASSERT_GT(sky.size(), 2880u * 3);
  auto header_with = [&](const std::string& key, const std::string& card) {
    std::string s = sky;
    for (std::size_t at = 2880; at + 80 <= s.size(); at += 80)
      if (s.compare(at, key.size(), key) == 0 && (s[at + key.size()] == ' ' || s[at + key.size()] == '=')) {
        std::string c = card;
        c.resize(80, ' ');
        s.replace(at, 80, c);
        break;
      }
    return s;
  };
  const std::string sky_cfg = variant("file_sky"), beam_cfg = variant("file_beam");
  const std::vector<std::pair<std::string, std::string>> skies{
      {"", "sky.fits"},
      {"not a FITS file at all\n", "sky.fits"},
      {sky.substr(0, 100), "sky.fits"},
      {sky.substr(0, 2880), "sky.fits"},
      {sky.substr(0, 2880 + 800), "sky.fits"},
      {sky.substr(0, 2 * 2880 + 1000), "sky.fits"},
      {header_with("NSIDE", "NSIDE   =                   12"), "NSIDE = 12"},
      {header_with("NSIDE", "NSIDE   =                    0"), "NSIDE = 0"},
      {header_with("NSIDE", "NSIDE   = 'eight'"), "NSIDE"},
      {header_with("NSIDE", "NSIDX   =                    8"), "NSIDE"},
      {header_with("ORDERING", "ORDERING= 'SPIRAL  '"), "ORDERING"},
      {header_with("POLCCONV", "POLCCONV= 'SIDEWAYS'"), "POLCCONV"},
      {header_with("INDXSCHM", "INDXSCHM= 'EXPLICIT'"), "cut-sky"},
      {header_with("TFORM1", "TFORM1  = '1024A   '"), "sky.fits"},
  };
  for (const auto& [text, needle] : skies) {
    write("sky.fits", text);
    expect_clean_error("sky.fits of " + std::to_string(text.size()) + " bytes", sky_cfg, needle);
  }
  // NaN and UNSEEN pixels in an otherwise valid map.
  pisco::Sky bad(8, "K");
  bad.Q()[17] = std::nan("");
  pisco_test::write_unchecked_sky(bad, dir_ / "sky.fits");  // the library's writer refuses a NaN
  expect_clean_error("a NaN pixel", sky_cfg, "pixel 17");
  bad.Q()[17] = pisco::unseen;
  bad.write_fits(dir_ / "sky.fits");
  expect_clean_error("an UNSEEN pixel", sky_cfg, "column 2 (Q_STOKES) has 1 UNSEEN pixel");
  const std::vector<std::size_t> beam_cuts{0, 100, 2880, 2880 + 400, beam.size() / 2};
  for (std::size_t cut : beam_cuts) {
    write("beam.fits", beam.substr(0, cut));
    expect_clean_error("beam.fits cut at " + std::to_string(cut), beam_cfg, "beam.fits");
  }
  // Random byte changes in the headers and the data: read or refused, never a crash.
  std::mt19937_64 rng(2024);
  for (int k = 0; k < 12; ++k) {
    write("sky.fits", with_random_bytes(sky, rng));
    expect_no_crash("sky.fits with random bytes, draw " + std::to_string(k), sky_cfg);
    write("beam.fits", with_random_bytes(beam, rng));
    expect_no_crash("beam.fits with random bytes, draw " + std::to_string(k), beam_cfg);
  }
  write("sky.fits", sky);
  write("beam.fits", beam);
}

// GRASP and harmonic beam files (docs/beams.md): truncated, with broken numbers, NaN fields, wrong
// component counts, and random byte changes that may still read.
TEST_F(Robustness, CorruptedBeamFiles) {
  const std::string grd = read(dir_ / "beam.grd"), alm = read(dir_ / "beam_alm.fits");
  const std::string grasp_cfg = variant("grasp_beam"), blm_cfg = variant("blm_beam");
  // Line by line: the header lines, then cuts through the grid's rows.
  std::vector<std::string> lines;
  for (std::size_t at = 0; at < grd.size();) {
    const std::size_t end = grd.find('\n', at);
    lines.push_back(grd.substr(at, end - at));
    at = end + 1;
  }
  auto joined_lines = [](const std::vector<std::string>& l) {
    std::string t;
    for (const auto& x : l) t += x + "\n";
    return t;
  };
  for (std::size_t keep : {0ul, 2ul, 4ul, 5ul, 6ul, 7ul, 8ul, 9ul, 10ul, 11ul, 500ul, lines.size() - 1}) {
    write("beam.grd", joined_lines(std::vector<std::string>(lines.begin(), lines.begin() + std::ptrdiff_t(keep))));
    expect_clean_error("beam.grd cut after line " + std::to_string(keep), grasp_cfg, "beam.grd");
  }
  const std::vector<std::pair<std::size_t, std::string>> edits{
      {5, "2"}, {5, "x"}, {6, "1 1 2 1"}, {6, "1 3 9 1"}, {6, "1 3 2 9"}, {6, "0 3 2 1"}, {8, "0 0 0 0"},
      {9, "41 41 7"}, {9, "1 41 0"}, {9, "41 -3 0"}, {20, "nan 0 0 0"}, {20, "1 0 0"}, {20, "1 0 0 0 0"},
      {20, "1e999 0 0 0"}, {20, "a b c d"}};
  for (const auto& [line, text] : edits) {
    auto l = lines;
    l[line] = text;
    write("beam.grd", joined_lines(l));
    expect_clean_error("beam.grd line " + std::to_string(line + 1) + " = '" + text + "'", grasp_cfg, "beam.grd");
  }
  for (std::size_t cut : {std::size_t(0), std::size_t(100), std::size_t(2880), std::size_t(2880 + 500), alm.size() / 2}) {
    write("beam_alm.fits", alm.substr(0, cut));
    expect_clean_error("beam_alm.fits cut at " + std::to_string(cut), blm_cfg, "beam_alm.fits");
  }
  std::mt19937_64 rng(77);
  for (int k = 0; k < 10; ++k) {
    write("beam.grd", with_random_bytes(grd, rng));
    expect_no_crash("beam.grd with random bytes, draw " + std::to_string(k), grasp_cfg);
    write("beam_alm.fits", with_random_bytes(alm, rng));
    expect_no_crash("beam_alm.fits with random bytes, draw " + std::to_string(k), blm_cfg);
  }
  write("beam.grd", grd);
  write("beam_alm.fits", alm);
}

// HDF5 inputs (pointing files and TOAST focal planes): truncated, without their datasets, with bad
// samples, and with random byte changes.
TEST_F(Robustness, CorruptedHdf5Files) {
  const std::string bore = read(dir_ / "bore.h5");
  const std::string cfg = variant("scan_file");
  for (std::size_t cut : {std::size_t(0), std::size_t(7), std::size_t(100), std::size_t(1000), bore.size() / 2,
                          bore.size() - 100}) {
    write("bore.h5", bore.substr(0, cut));
    expect_clean_error("bore.h5 cut at " + std::to_string(cut), cfg, "bore.h5");
  }
  std::string sig = bore;
  sig[1] = 'X';
  write("bore.h5", sig);
  expect_clean_error("bore.h5 without its signature", cfg, "bore.h5");
  std::vector<pisco::Quat> q(50, pisco::Quat{0, 0, 0, 1});
  q[33] = {0, 0, 0, 2};
  pisco::BoresightFile::write(dir_ / "bore.h5", q);
  expect_clean_error("a non-unit quaternion", cfg, "sample 33");
  q[33] = {0, 0, std::nan(""), 1};
  pisco::BoresightFile::write(dir_ / "bore.h5", q);
  expect_clean_error("a NaN quaternion", cfg, "sample 33");
  // A TOD file as a pointing file, without pointing datasets.
  pisco::FocalPlane fp;
  fp.add_pair("p", 0, 0, 0);
  {
    pisco::TodWriter w(dir_ / "bore.h5", fp, 4, pisco::TodPrecision::float64, false, {});
    const std::vector<double> s(4, 0.0);
    w.write(0, 0, s);
    w.write(1, 0, s);
    w.commit();
  }
  expect_clean_error("a TOD file without pointing", cfg, "bore.h5");
  // TOAST focal planes: the bundled table truncated, and with random bytes.
  const std::string toast = read(fs::path(PISCO_TEST_ASSETS_DIR) / "focalplanes" / "toast_hex7.h5");
  const std::string toast_cfg = with_table(without_table(base_config, "[[focal_plane.pairs]]"), "[focal_plane]",
                                           "file = \"fp.h5\"\n");
  write("fp.h5", toast);
  const CliResult whole = pisco_test::run_cli({"run", "-q", write("case.toml", toast_cfg).string(), "-o", (dir_ / "out").string()});
  EXPECT_EQ(whole.status, 0) << whole.output;
  for (std::size_t cut : {std::size_t(10), std::size_t(600), toast.size() / 3, toast.size() - 10}) {
    write("fp.h5", toast.substr(0, cut));
    expect_clean_error("fp.h5 cut at " + std::to_string(cut), toast_cfg, "fp.h5");
  }
  std::mt19937_64 rng(7);
  pisco::SatelliteScan sat;
  sat.sample_rate = 1;
  sat.samples = 200;
  std::vector<pisco::Quat> scan;
  sat.generate(0, sat.samples, scan);
  pisco::BoresightFile::write(dir_ / "bore.h5", scan);
  const std::string good_bore = read(dir_ / "bore.h5");
  for (int k = 0; k < 8; ++k) {
    std::string b = good_bore;
    for (int j = 0; j < 3; ++j) b[std::uniform_int_distribution<std::size_t>(0, b.size() - 1)(rng)] = char(rng());
    write("bore.h5", b);
    expect_no_crash("bore.h5 with random bytes, draw " + std::to_string(k), cfg);
  }
  write("bore.h5", bore);
  write("fp.h5", toast);
}

// Other input files: C_l tables and tensor templates.
TEST_F(Robustness, MalformedTables) {
  for (const auto& [text, needle] : std::vector<std::pair<std::string, std::string>>{
           {"", "cl.txt"}, {"2 abc 3 4 5\n", "cl.txt:1"}, {std::string("\0\0\0", 3), "cl.txt"}}) {
    write("cl.txt", text);
    expect_clean_error("cl.txt: " + text.substr(0, 20), with_key(base_config, "[sky]", "cl_file", "\"cl.txt\""), needle);
  }
  for (const auto& [text, needle] : std::vector<std::pair<std::string, std::string>>{
           {"2 nan\n", "bb.txt:1"}, {"x y\n", "bb.txt:1"}, {"-3 1\n", "bb.txt:1"}}) {
    write("bb.txt", text);
    expect_clean_error("bb.txt: " + text, with_key(variant("r"), "[sky]", "bb_template", "\"bb.txt\""), needle);
  }
  std::cout << cases_ << " robustness cases so far\n";
}

}  // namespace
