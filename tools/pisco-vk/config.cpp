#include "config.hpp"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>

#include <toml++/toml.h>

#include "pisco/time_ranges.hpp"
#include "pisco/units.hpp"

namespace pisco_cli {
namespace {

namespace fs = std::filesystem;
using pisco::deg;
constexpr double arcmin = deg / 60;

// Levenshtein distance: insertions, deletions and substitutions, one each.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

// Whether an unknown key looks like a misspelling of a known one: a few edits apart (a third of the
// longer name, at least 2), or the one a prefix of the other (fwhm for fwhm_deg).
bool resembles(const std::string& unknown, const std::string& known) {
  if (unknown.empty() || known.empty()) return false;
  const std::size_t longer = std::max(unknown.size(), known.size());
  if (edit_distance(unknown, known) <= std::max<std::size_t>(2, longer / 3)) return true;
  const std::string& shorter = unknown.size() < known.size() ? unknown : known;
  const std::string& other = unknown.size() < known.size() ? known : unknown;
  return shorter.size() >= 3 && other.compare(0, shorter.size(), shorter) == 0;
}

// A TOML table with the context for error messages; finish() rejects keys nobody asked for, so a
// misspelt key is an error rather than a silently ignored setting.
class Table {
 public:
  Table(const toml::table& t, std::string where, const fs::path& file) : t_(t), where_(std::move(where)), file_(file) {}

  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    // A misspelt key leaves the key it stands for absent (missing, or at a default that the error may
    // be about): an unknown key of this table close to an absent one it asked for is the error.
    std::set<std::string> absent{key};
    for (const auto& u : used_) absent.insert(u);
    for (const auto& [k, v] : t_) {
      const std::string name(k.str());
      if (used_.count(name) || name == key) continue;
      for (const auto& a : absent)
        if (!t_.contains(a) && resembles(name, a))
          throw pisco::Error(file_.string() + ": [" + where_ + "] unknown key '" + name + "' (did you mean '" + a +
                             "'?)");
    }
    throw pisco::Error(file_.string() + ": [" + where_ + "] " + key + ": " + what);
  }
  bool has(const std::string& key) const { return t_.contains(key); }

  std::optional<double> number(const std::string& key) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return std::nullopt;
    if (auto v = n->value<double>()) {
      if (!std::isfinite(*v)) fail(key, "expected a finite number, got " + std::to_string(*v));
      return *v;
    }
    fail(key, "expected a number");
  }
  double number(const std::string& key, double fallback) { return number(key).value_or(fallback); }
  // A number within [lo, hi]; `what` says what the value means, for the error.
  double number_in(const std::string& key, double fallback, double lo, double hi, const std::string& what) {
    const double v = number(key, fallback);
    if (v < lo || v > hi) fail(key, "expected " + what + ", got " + format(v));
    return v;
  }
  static std::string format(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.9g", v);
    return buf;
  }
  double positive(const std::string& key, double fallback) {
    const double v = number(key, fallback);
    if (!(v > 0) || !std::isfinite(v)) fail(key, "expected a positive number, got " + format(v));
    return v;
  }
  // A positive number times `scale` (a unit: 60 for minutes), which must stay finite.
  double positive(const std::string& key, double fallback, double scale) {
    const double v = positive(key, fallback);
    if (!std::isfinite(v * scale)) fail(key, "expected at most " + format(std::numeric_limits<double>::max() / scale) + ", got " + format(v));
    return v * scale;
  }
  // An error of the table as a whole (a library check of several keys together).
  [[noreturn]] void fail_table(const std::string& what) const {
    throw pisco::Error(file_.string() + ": [" + where_ + "] " + what);
  }
  std::int64_t integer(const std::string& key, std::int64_t fallback) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return fallback;
    if (auto v = n->value_exact<std::int64_t>()) return *v;
    fail(key, "expected an integer");
  }
  // An integer within [lo, hi]; `what` says what it means, for the error.
  std::int64_t integer_in(const std::string& key, std::int64_t fallback, std::int64_t lo, std::int64_t hi,
                          const std::string& what) {
    const std::int64_t v = integer(key, fallback);
    if (v < lo || v > hi) fail(key, "expected " + what + ", got " + std::to_string(v));
    return v;
  }
  // An NSIDE: read as a 64-bit integer, then checked to be a power of two in [1, max_nside].
  int nside(const std::string& key, std::int64_t fallback) {
    const std::int64_t n = integer(key, fallback);
    if (!pisco::valid_nside(n))
      fail(key, "expected a power of two from 1 to " + std::to_string(pisco::max_nside) + ", got " + std::to_string(n));
    return static_cast<int>(n);
  }

  bool boolean(const std::string& key, bool fallback) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return fallback;
    if (auto v = n->value_exact<bool>()) return *v;
    fail(key, "expected true or false");
  }
  std::optional<std::string> string(const std::string& key) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return std::nullopt;
    if (auto v = n->value_exact<std::string>()) return *v;
    fail(key, "expected a string");
  }
  std::string string(const std::string& key, const std::string& fallback) { return string(key).value_or(fallback); }
  std::string choice(const std::string& key, const std::string& fallback, const std::vector<std::string>& allowed) {
    const std::string v = string(key, fallback);
    for (const auto& a : allowed)
      if (a == v) return v;
    std::string list;
    for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
    fail(key, "expected one of " + list + ", got \"" + v + "\"");
  }
  std::vector<double> numbers(const std::string& key, std::vector<double> fallback) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return fallback;
    const toml::array* a = n->as_array();
    if (!a || a->empty()) fail(key, "expected a non-empty array of numbers");
    std::vector<double> out;
    for (const auto& e : *a) {
      auto v = e.value<double>();
      if (!v) fail(key, "expected a non-empty array of numbers");
      if (!std::isfinite(*v))
        fail(key + "[" + std::to_string(out.size()) + "]", "expected a finite number, got " + std::to_string(*v));
      out.push_back(*v);
    }
    return out;
  }
  const toml::table* table(const std::string& key) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return nullptr;
    if (!n->is_table()) fail(key, "expected a table");
    return n->as_table();
  }
  const toml::array* array_of_tables(const std::string& key) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return nullptr;
    if (!n->is_array_of_tables()) fail(key, "expected an array of tables ([[" + where_ + "." + key + "]])");
    return n->as_array();
  }
  fs::path path(const std::string& key) {
    const auto s = string(key);
    if (!s) return {};
    const fs::path p(*s);
    return p.is_absolute() ? p : file_.parent_path() / p;
  }
  // An input file: a path that exists and is not a directory (empty when the key is absent).
  fs::path input_file(const std::string& key) {
    const fs::path p = path(key);
    if (p.empty()) return p;
    if (string(key)->empty()) fail(key, "expected a file name, got \"\"");
    std::error_code ec;
    const auto st = fs::status(p, ec);
    if (!fs::exists(st)) fail(key, p.string() + ": no such file");
    if (fs::is_directory(st)) fail(key, p.string() + ": is a directory (expected a file)");
    return p;
  }
  void finish() const {
    for (const auto& [k, v] : t_) {
      const std::string name(k.str());
      if (used_.count(name)) continue;
      // The keys this table's reader asked for are the ones it knows: the nearest is suggested.
      std::string nearest;
      std::size_t best = std::string::npos;
      for (const auto& known : used_)
        if (const std::size_t d = edit_distance(name, known); d < best && resembles(name, known)) {
          best = d;
          nearest = known;
        }
      throw pisco::Error(file_.string() + ": [" + where_ + "] unknown key '" + name + "'" +
                         (nearest.empty() ? std::string() : " (did you mean '" + nearest + "'?)"));
    }
  }
  const std::string& where() const { return where_; }

 private:
  const toml::table& t_;
  std::string where_;
  const fs::path& file_;
  std::set<std::string> used_;
};

toml::table parse(const fs::path& file, std::string* text) {
  std::error_code ec;
  if (fs::is_directory(file, ec)) throw pisco::Error(file.string() + ": is a directory (expected a TOML file)");
  std::ifstream in(file);
  if (!in) throw pisco::Error(file.string() + ": cannot open the file");
  std::stringstream ss;
  ss << in.rdbuf();
  if (text) *text = ss.str();
  try {
    return toml::parse(ss.str(), file.string());
  } catch (const toml::parse_error& e) {
    std::ostringstream m;
    m << file.string() << ":" << e.source().begin.line << ":" << e.source().begin.column << ": not valid TOML: "
      << e.description();
    throw pisco::Error(m.str());
  }
}

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
  const std::string unseen = t.choice("unseen", "error", {"error", "zero", "flag"});
  s.unseen = unseen == "error" ? pisco::UnseenPolicy::error
             : unseen == "zero" ? pisco::UnseenPolicy::zero
                                : pisco::UnseenPolicy::flag;
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

BeamConfig read_beam(Table t, const std::string& name) {
  BeamConfig b;
  b.name = name;
  b.type = t.choice("type", "gaussian", {"gaussian", "elliptical", "file", "grasp", "blm"});
  b.options.rho_max = t.positive("rho_max_deg", 5.0) * deg;
  if (b.options.rho_max >= std::numbers::pi / 2) t.fail("rho_max_deg", "expected less than 90 deg");
  b.options.grid_step = t.number("grid_step_arcmin", 0.0) * arcmin;
  if (b.options.grid_step < 0) t.fail("grid_step_arcmin", "expected a positive step (or 0 for the default)");
  // A Gaussian's width: its half-maximum radius within rho_max, and a grid of at most
  // Beamsor::max_grid_nodes nodes a side at the step it implies (1/20 of the smallest FWHM by default).
  auto width = [&](const std::string& key) {
    const double fwhm = t.positive(key, 1.5) * deg;
    if (fwhm / 2 >= b.options.rho_max)
      t.fail(key, "a FWHM of " + Table::format(fwhm / deg) + " deg is wider than the beam grid: its half-maximum "
                  "radius must fit within rho_max_deg = " + Table::format(b.options.rho_max / deg));
    const double step = b.options.grid_step > 0 ? b.options.grid_step : fwhm / 20;
    if (std::ceil(2 * std::sin(b.options.rho_max) / step) + 1 > pisco::Beamsor::max_grid_nodes)
      t.fail(b.options.grid_step > 0 ? "grid_step_arcmin" : key,
             "a grid step of " + Table::format(step / arcmin) + " arcmin needs more than " +
                 std::to_string(pisco::Beamsor::max_grid_nodes) + " nodes a side within rho_max_deg = " +
                 Table::format(b.options.rho_max / deg) + " (set a larger grid_step_arcmin)");
    return fwhm;
  };
  if (b.type == "gaussian") {
    b.fwhm = width("fwhm_deg");
  } else if (b.type == "elliptical") {
    b.fwhm_x = width("fwhm_x_deg");
    b.fwhm_y = width("fwhm_y_deg");
    b.angle = t.number("angle_deg", 0.0) * deg;
  } else {
    b.file = t.input_file("file");
    if (b.file.empty())
      t.fail("file", b.type == "grasp" ? "a beam of type \"grasp\" needs file = \"beam.grd\" (or a .cut file)"
                     : b.type == "blm" ? "a beam of type \"blm\" needs file = \"beam_alm.fits\" (healpy.write_alm)"
                                       : "a beam of type \"file\" needs file = \"beamsor.fits\"");
    if (b.type == "grasp") {
      const double set = t.number("set", 0.0);
      if (!(set >= 0 && set <= 1e6 && set == std::floor(set)))
        t.fail("set", "expected the number of one of the file's beams (1, 2, ...)");
      b.set = static_cast<int>(set);
    }
  }
  // Sidelobes (docs/beams.md, "Sidelobes"): a main part within sidelobe_split_deg on the sky's pixels, the
  // rest on a band-limited coarser sky.
  if (t.has("sidelobe_split_deg") || t.has("sidelobe_taper_deg") || t.has("sidelobe_nside")) {
    if (b.type == "file")
      t.fail(t.has("sidelobe_split_deg") ? "sidelobe_split_deg" : t.has("sidelobe_taper_deg") ? "sidelobe_taper_deg" : "sidelobe_nside",
             "a HEALPix beamsor file (type \"file\") cannot be split; give the beam as grasp, blm, gaussian or elliptical");
    if (!t.has("sidelobe_split_deg"))
      t.fail(t.has("sidelobe_taper_deg") ? "sidelobe_taper_deg" : "sidelobe_nside",
             "only with sidelobe_split_deg, the radius of the beam's main part");
    b.options.split.rho_main = t.positive("sidelobe_split_deg", 1.0) * deg;
    if (!(b.options.split.rho_main < b.options.rho_max))
      t.fail("sidelobe_split_deg", "expected less than rho_max_deg = " + Table::format(b.options.rho_max / deg) +
                                       ": the main part lies within the beam's disc");
    b.options.split.taper = t.number("sidelobe_taper_deg", 0.0) * deg;
    if (!(b.options.split.taper >= 0 && b.options.split.taper <= b.options.split.rho_main))
      t.fail("sidelobe_taper_deg", "expected a width in [0, sidelobe_split_deg] (0: a quarter of it)");
    const double nside = t.number("sidelobe_nside", 0.0);
    const int n = nside >= 0 && nside <= 8192 ? static_cast<int>(nside) : -1;  // converted only within range
    if (!(n >= 0 && nside == n && (n & (n - 1)) == 0))
      t.fail("sidelobe_nside", "expected a power of two up to 8192 (or 0: chosen from the sidelobes' band limit)");
    b.options.split.nside = n;
  }
  if (b.type == "gaussian" || b.type == "elliptical") {
    b.options.cross_polar = t.number("cross_polar", 0.0);
    b.options.cross_polar_pattern =
        t.choice("cross_polar_pattern", "uniform", {"uniform", "quadrupole"}) == "uniform"
            ? pisco::CrossPolarPattern::uniform
            : pisco::CrossPolarPattern::quadrupole;
    const std::vector<double> m = t.numbers("mueller", {});
    if (!m.empty()) {
      if (m.size() != 16) t.fail("mueller", "expected 16 numbers (a 4x4 Mueller matrix, row by row)");
      if (!(m[0] > 0)) t.fail("mueller", "the first element (T to T) must be positive: the beam's total response");
      for (int i = 0; i < 16; ++i) b.options.mueller[i / 4][i % 4] = m[i];
    }
  }
  t.finish();
  return b;
}

std::size_t beam_index(Table& t, const std::string& key, const std::vector<BeamConfig>& beams, bool required) {
  const auto name = t.string(key);
  if (!name) {
    if (required && beams.size() != 1) t.fail(key, "expected the name of one of the [beams] tables");
    return 0;
  }
  for (std::size_t i = 0; i < beams.size(); ++i)
    if (beams[i].name == *name) return i;
  t.fail(key, "no beam named \"" + *name + "\" in [beams]");
}

// The physical ranges of a detector's numbers (the library checks them too, naming the detector).
double efficiency_leak(Table& t, const std::string& key) {
  return t.number_in(key, 0.0, 0.0, 1.0, "a cross-polar leakage in [0, 1] (polarization efficiency 1 - epsilon)");
}
double responsivity(Table& t, const std::string& key) {
  const double g = t.number(key, 1.0);
  if (!(g > 0)) t.fail(key, "expected a positive responsivity, got " + Table::format(g));
  return g;
}
// Offsets (xi, eta): a direction from the boresight, less than 180 deg away.
void check_offset(Table& t, const std::string& keys, double xi, double eta) {
  if (std::hypot(xi, eta) >= std::numbers::pi)
    t.fail(keys, "the offset sqrt(xi^2 + eta^2) = " + Table::format(std::hypot(xi, eta) / deg) +
                     " deg is not less than 180 deg from the boresight");
}

// Detector names must be unique: the first repeated name as (first index, second index), if any.
std::optional<std::pair<std::size_t, std::size_t>> repeated_name(const std::vector<pisco::Detector>& dets) {
  std::map<std::string, std::size_t> seen;
  for (std::size_t i = 0; i < dets.size(); ++i) {
    const auto [it, fresh] = seen.emplace(dets[i].name, i);
    if (!fresh) return std::pair{it->second, i};
  }
  return std::nullopt;
}

// A detector's plate keys (hwp, hwp_gamma_deg, hwp_mueller), read from its table.
DetectorHwp read_detector_hwp(Table& t) {
  DetectorHwp h;
  if (t.has("hwp")) h.enabled = t.boolean("hwp", true);
  if (const auto g = t.number("hwp_gamma_deg")) {
    h.gamma = *g * deg;
    h.gamma_key = true;
  }
  if (t.has("hwp_mueller")) {
    const std::vector<double> m = t.numbers("hwp_mueller", {});
    if (m.size() != 16) t.fail("hwp_mueller", "expected 16 numbers, row by row, got " + std::to_string(m.size()));
    pisco::Mueller mm{};
    for (int i = 0; i < 16; ++i) {
      if (!std::isfinite(m[i])) t.fail("hwp_mueller", "entry " + std::to_string(i) + " is not finite");
      mm[i / 4][i % 4] = m[i];
    }
    h.mueller = mm;
  }
  return h;
}

void read_detectors(const toml::table& root, const std::string& where, const fs::path& file,
                    const std::vector<BeamConfig>& beams, std::vector<pisco::Detector>& out,
                    std::vector<DetectorHwp>* hwp = nullptr) {
  std::vector<std::string> origins(out.size());  // the table that defined each detector
  Table t(root, where, file);
  if (const toml::array* dets = t.array_of_tables("detectors")) {
    std::size_t i = 0;
    for (const auto& node : *dets) {
      Table d(*node.as_table(), where + ".detectors[" + std::to_string(i++) + "]", file);
      pisco::Detector det;
      const auto name = d.string("name");
      if (!name || name->empty()) d.fail("name", "every detector needs a name");
      det.name = *name;
      det.zeta = d.number("zeta_deg", 0.0) * deg;
      det.epsilon = efficiency_leak(d, "epsilon");
      det.gain = responsivity(d, "gain");
      det.beam = beam_index(d, "beam", beams, true);
      const double xi = d.number("xi_deg", 0.0) * deg, eta = d.number("eta_deg", 0.0) * deg;
      check_offset(d, "xi_deg, eta_deg", xi, eta);
      det.set_offset(xi, eta, d.number("gamma_deg", 0.0) * deg);
      const DetectorHwp dh = read_detector_hwp(d);
      d.finish();
      if (hwp) {
        hwp->resize(out.size());
        hwp->push_back(dh);
      }
      out.push_back(det);
      origins.push_back("[" + d.where() + "]");
    }
  }
  if (const toml::array* pairs = t.array_of_tables("pairs")) {
    std::size_t i = 0;
    for (const auto& node : *pairs) {
      Table p(*node.as_table(), where + ".pairs[" + std::to_string(i++) + "]", file);
      const auto name = p.string("name");
      if (!name || name->empty()) p.fail("name", "every pair needs a name");
      const double zeta = p.number("zeta_deg", 0.0) * deg;
      const double eps = efficiency_leak(p, "epsilon");
      std::size_t ba = 0, bb = 0;
      if (p.has("beam")) {
        ba = bb = beam_index(p, "beam", beams, true);
      } else {
        ba = beam_index(p, "beam_a", beams, true);
        bb = beam_index(p, "beam_b", beams, true);
      }
      const double ga = responsivity(p, "gain_a"), gb = responsivity(p, "gain_b");
      // A pair shares its position; xi_b, eta_b give detector b its own (pointing mismatch).
      const double xi = p.number("xi_deg", 0.0) * deg, eta = p.number("eta_deg", 0.0) * deg;
      const double xi_b = p.number("xi_b_deg").value_or(xi / deg) * deg, eta_b = p.number("eta_b_deg").value_or(eta / deg) * deg;
      const double gamma = p.number("gamma_deg", 0.0) * deg;
      check_offset(p, "xi_deg, eta_deg", xi, eta);
      check_offset(p, "xi_b_deg, eta_b_deg", xi_b, eta_b);
      const DetectorHwp dh = read_detector_hwp(p);
      p.finish();
      if (hwp) {
        hwp->resize(out.size());
        hwp->push_back(dh);
        hwp->push_back(dh);
        if (dh.gamma) hwp->back().gamma = *dh.gamma - std::numbers::pi / 2;  // b: its axis 90 deg from a's
      }
      pisco::Detector a, b;
      a.name = *name + "a";
      b.name = *name + "b";
      a.zeta = zeta;
      b.zeta = zeta - std::numbers::pi / 2;  // paper eq. copol_bolo
      a.epsilon = b.epsilon = eps;
      a.gain = ga;
      b.gain = gb;
      a.beam = ba;
      b.beam = bb;
      a.set_offset(xi, eta, gamma);
      b.set_offset(xi_b, eta_b, gamma);
      out.push_back(a);
      out.push_back(b);
      origins.push_back("[" + p.where() + "]");
      origins.push_back("[" + p.where() + "]");
    }
  }
  t.string("file");  // handled by the caller
  t.finish();
  if (const auto r = repeated_name(out))
    throw pisco::Error(file.string() + ": " + origins[r->second] + " detector '" + out[r->second].name +
                       "' is also defined by " + origins[r->first] + " (expected unique detector names)");
}

// "YYYY-MM-DDTHH:MM:SSZ" (UTC) to seconds since 1970-01-01.
double parse_utc(Table& t, const std::string& key, const std::string& text) {
  int y, mo, d, h, mi;
  double sec;
  char z = 0;
  // Field widths keep every integer within int; the seconds must be a number in [0, 61).
  if (std::sscanf(text.c_str(), "%4d-%2d-%2dT%2d:%2d:%lf%c", &y, &mo, &d, &h, &mi, &sec, &z) != 7 || z != 'Z' || mo < 1 ||
      mo > 12 || d < 1 || d > 31 || h < 0 || h > 23 || mi < 0 || mi > 59 || !(sec >= 0 && sec < 61))
    t.fail(key, "expected a UTC time like \"2019-06-01T00:00:00Z\", got \"" + text + "\"");
  // Days from civil (proleptic Gregorian), Howard Hinnant's algorithm.
  y -= mo <= 2;
  const int era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (mo + (mo > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  const long days = era * 146097L + static_cast<long>(doe) - 719468L;
  return days * 86400.0 + h * 3600.0 + mi * 60.0 + sec;
}

// [scan] type = "satellite": a spinning, precessing spacecraft (pisco::SatelliteScan; every key is
// checked here so that its error names it).
void read_satellite(Table& t, ScanConfig& s) {
  pisco::SatelliteScan& c = s.satellite;
  auto angle = [&](const std::string& key, double fallback, bool open_interval) {
    const double v = t.number(key, fallback);
    if (!std::isfinite(v) || v < 0 || v > 180 || (open_interval && (v == 0 || v == 180)))
      t.fail(key, std::string("expected an angle within ") + (open_interval ? "(0, 180)" : "[0, 180]") + " deg, got " +
                      std::to_string(v));
    return v * deg;
  };
  auto finite = [&](const std::string& key, double fallback) {
    const double v = t.number(key, fallback);
    if (!std::isfinite(v)) t.fail(key, "expected a finite number");
    return v;
  };
  c.spin_sun_angle = angle("spin_sun_angle_deg", 45.0, false);
  c.spin_boresight_angle = angle("spin_boresight_angle_deg", 50.0, true);
  c.precession_period = t.positive("precession_period_min", 192.348, 60);
  c.spin_period = t.positive("spin_period_min", 20.0, 60);
  c.sample_rate = t.positive("sample_rate_hz", 19.0);
  c.start_time = finite("start_time_s", 0.0);
  c.precession_phase = finite("precession_phase_deg", 0.0) * deg;
  c.spin_phase = finite("spin_phase_deg", 0.0) * deg;
  const std::string frame = t.choice("frame", "ecliptic", {"ecliptic", "equatorial", "galactic"});
  c.frame = frame == "ecliptic"     ? pisco::SatelliteScan::Frame::ecliptic
            : frame == "equatorial" ? pisco::SatelliteScan::Frame::equatorial
                                    : pisco::SatelliteScan::Frame::galactic;
  const double hours = t.positive("duration_hours", 1.0);
  const double samples = std::round(hours * 3600 * c.sample_rate);
  if (!(samples >= 1)) t.fail("duration_hours", "shorter than one sample at sample_rate_hz");
  if (samples > 1e15) t.fail("duration_hours", "more than 1e15 samples at sample_rate_hz");
  c.samples = static_cast<std::size_t>(samples);
  s.nside = t.nside("nside", 64);  // the maps' default NSIDE
  // What float64 carries over the run (docs/formats.md, "Times, rates and angles"), by key.
  if (const auto p = c.time_problem()) {
    if (p->field == "start_time") t.fail("start_time_s", p->what);
    if (p->field == "spin_period") t.fail("spin_period_min", p->what);
    if (p->field == "precession_period") t.fail("precession_period_min", p->what);
  }
  try {
    c.check();
  } catch (const pisco::Error& e) {
    t.fail_table(e.what());
  }
}

ScanConfig read_scan(Table t) {
  ScanConfig s;
  s.type = t.choice("type", "pixel_centres", {"pixel_centres", "random_offsets", "raster", "ces", "satellite", "file"});
  if (s.type != "ces" && s.type != "satellite" && s.type != "file")
    for (double p : t.numbers("psi_deg", {0.0, 45.0, 90.0})) s.psi.push_back(p * deg);
  if (s.type == "ces") {
    pisco::CesScan& c = s.ces;
    c.latitude = t.number_in("latitude_deg", -22.96, -90, 90, "a latitude in [-90, 90] deg") * deg;
    c.longitude = t.number("longitude_deg", -67.79) * deg;
    const double elevation = t.number("elevation_deg", 45.0);
    if (!(elevation > 0 && elevation < 90)) t.fail("elevation_deg", "expected an elevation within (0, 90) deg, got " + Table::format(elevation));
    c.elevation = elevation * deg;
    c.az_centre = t.number("az_centre_deg", 180.0) * deg;
    c.az_throw = t.number_in("az_throw_deg", 720.0, 0, 1e9, "a non-negative azimuth throw") * deg;
    c.az_speed = t.positive("az_speed_deg_s", 1.0) * deg;
    c.sample_rate = t.positive("sample_rate_hz", 20.0);
    c.start_unix = parse_utc(t, "start", t.string("start", "2019-06-01T00:00:00Z"));
    const double hours = t.positive("duration_hours", 1.0);
    const double samples = std::round(hours * 3600 * c.sample_rate);
    if (!(samples >= 1)) t.fail("duration_hours", "shorter than one sample at sample_rate_hz");
    if (samples > 1e15) t.fail("duration_hours", "more than 1e15 samples at sample_rate_hz");
    c.samples = static_cast<std::size_t>(samples);
    c.boresight_angles.clear();
    for (double b : t.numbers("boresight_deg", {0.0})) c.boresight_angles.push_back(b * deg);
    c.boresight_period = t.positive("boresight_period_hours", 24.0, 3600);
    s.nside = t.nside("nside", 128);  // the maps' default NSIDE
    // What float64 carries over the run (docs/formats.md, "Times, rates and angles"), by key.
    if (const auto p = c.time_problem()) {
      if (p->field == "start_unix") t.fail("start", p->what);
      if (p->field == "az_speed") t.fail("az_speed_deg_s", p->what);
      if (p->field == "boresight_period") t.fail("boresight_period_hours", p->what);
    }
    try {
      c.check();
    } catch (const pisco::Error& e) {
      t.fail_table(e.what());
    }
  } else if (s.type == "satellite") {
    read_satellite(t, s);
  } else if (s.type == "file") {
    s.file = t.input_file("file");
    if (s.file.empty()) t.fail("file", "a scan of type \"file\" needs file = \"pointing.h5\"");
  } else {
    s.nside = t.nside("nside", 64);
  }
  if (s.type == "random_offsets") {
    s.f = t.number_in("f", 0.1, 0, 1, "a fraction of the pixel size in [0, 1]");
    s.symmetric = t.boolean("symmetric", false);
    s.seed = static_cast<std::uint64_t>(t.integer_in("seed", 1, 0, INT64_MAX, "a non-negative integer"));
  }
  if (s.type == "raster") {
    s.theta = t.number_in("theta_deg", 45.0, 0, 180, "a colatitude in [0, 180] deg") * deg;
    s.phi = t.number("phi_deg", 0.0) * deg;
    const double radius = t.positive("radius_deg", 5.0);
    if (radius >= 180) t.fail("radius_deg", "expected a radius below 180 deg, got " + Table::format(radius));
    s.radius = radius * deg;
  }
  t.finish();
  return s;
}

// The TOD is streamed in chunks of at most this many samples (two buffers of 128 MiB at float64).
constexpr std::int64_t max_chunk_samples = std::int64_t(1) << 24;

EngineConfig read_engine(Table t) {
  EngineConfig e;
  e.options.backend = t.string("backend", "auto");
  e.options.device = t.string("device", "auto");
  e.options.arithmetic = t.choice("arithmetic", "auto", {"auto", "float64", "float-float"});
  e.options.normalization = t.choice("normalization", "integral", {"integral", "per_sample"}) == "integral"
                                ? pisco::Normalization::integral
                                : pisco::Normalization::per_sample;
  e.options.quadrature = t.choice("quadrature", "corrected", {"corrected", "plain"}) == "corrected"
                             ? pisco::Quadrature::corrected
                             : pisco::Quadrature::plain;
  const unsigned max_threads = pisco::Engine::max_threads();
  e.options.threads = static_cast<unsigned>(t.integer_in(
      "threads", 0, 0, max_threads,
      "0 (all hardware threads) or a number of threads up to " + std::to_string(max_threads) +
          " (64 per hardware thread of this machine)"));
  const auto chunk = t.integer_in("chunk_samples", 1 << 16, 1, max_chunk_samples,
                                  "a number of samples from 1 to " + std::to_string(max_chunk_samples));
  e.chunk_samples = static_cast<std::size_t>(chunk);
  t.finish();
  return e;
}

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

}  // namespace

namespace {

// Whether a focal plane file is a TOAST table (HDF5): by its extension, else by the HDF5 signature at
// its start.
bool is_hdf5_focal_plane(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".h5" || ext == ".hdf5" || ext == ".he5" || ext == ".hdf") return true;
  std::ifstream in(file, std::ios::binary);
  char head[8] = {};
  return in.read(head, sizeof head) && std::string(head, sizeof head) == std::string("\x89HDF\r\n\x1a\n", 8);
}


}  // namespace

std::vector<pisco::Detector> load_focal_plane(const fs::path& file, const std::vector<BeamConfig>& beams,
                                              std::vector<DetectorHwp>* hwp) {
  std::vector<pisco::Detector> out;
  std::error_code ec;
  if (fs::is_directory(file, ec))
    throw pisco::Error(file.string() + ": is a directory (expected a focal plane file: CSV, TOML or TOAST HDF5)");
  if (is_hdf5_focal_plane(file)) {
    if (beams.size() != 1)
      throw pisco::Error(file.string() + ": a TOAST focal plane gives every detector one beam: name it with "
                                         "[focal_plane] beam (there are " + std::to_string(beams.size()) + " beams)");
    const pisco::ToastFocalPlane toast = pisco::read_toast_focal_plane(file, 0);
    if (hwp) {
      hwp->assign(toast.detectors.size(), DetectorHwp{});
      for (std::size_t i = 0; i < toast.gamma.size(); ++i) (*hwp)[i].gamma = toast.gamma[i];
    }
    return toast.detectors;
  }
  if (file.extension() == ".toml") {
    const toml::table root = parse(file, nullptr);
    read_detectors(root, "focal plane", file, beams, out, hwp);
    if (out.empty()) throw pisco::Error(file.string() + ": no [[detectors]] or [[pairs]]");
    return out;
  }
  std::ifstream in(file);
  if (!in) throw pisco::Error(file.string() + ": cannot open the focal plane file");
  std::string line;
  std::vector<std::string> header;
  auto split = [](const std::string& s) {
    std::vector<std::string> f;
    std::stringstream ss(s);
    std::string x;
    while (std::getline(ss, x, ',')) {
      const auto b = x.find_first_not_of(" \t\r"), e = x.find_last_not_of(" \t\r");
      f.push_back(b == std::string::npos ? "" : x.substr(b, e - b + 1));
    }
    return f;
  };
  int lineno = 0;
  std::map<std::string, int> line_of;  // each detector's line
  while (std::getline(in, line)) {
    ++lineno;
    // Spreadsheets save CSV with a UTF-8 byte-order mark first.
    if (lineno == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[line.find_first_not_of(" \t")] == '#') continue;
    const auto f = split(line);
    const std::string where = file.string() + ":" + std::to_string(lineno) + ": ";
    if (header.empty()) {
      header = f;
      for (const auto& h : header)
        if (h != "name" && h != "zeta_deg" && h != "epsilon" && h != "gain" && h != "beam" && h != "xi_deg" &&
            h != "eta_deg" && h != "gamma_deg" && h != "hwp" && h != "hwp_gamma_deg")
          throw pisco::Error(where + "unknown column '" + h +
                             "'; expected name, zeta_deg, epsilon, gain, beam, xi_deg, eta_deg, gamma_deg, hwp, "
                             "hwp_gamma_deg");
      if (std::find(header.begin(), header.end(), "name") == header.end())
        throw pisco::Error(where + "the header needs a 'name' column");
      if (beams.size() > 1 && std::find(header.begin(), header.end(), "beam") == header.end())
        throw pisco::Error(where + "the header needs a 'beam' column: the configuration defines " +
                           std::to_string(beams.size()) + " beams, and each detector must name one");
      continue;
    }
    if (f.size() != header.size())
      throw pisco::Error(where + "expected " + std::to_string(header.size()) + " fields, got " + std::to_string(f.size()));
    pisco::Detector d;
    double xi = 0.0, eta = 0.0, gamma = 0.0;
    DetectorHwp plate;  // the row's plate keys (hwp, hwp_gamma_deg)
    for (std::size_t i = 0; i < f.size(); ++i) {
      auto num = [&](const std::string& s) {
        try {
          std::size_t used = 0;
          const double v = std::stod(s, &used);
          if (used != s.size() || !std::isfinite(v)) throw std::invalid_argument(s);
          return v;
        } catch (const std::exception&) {
          throw pisco::Error(where + "column '" + header[i] + "': expected a number, got '" + s + "'");
        }
      };
      if (header[i] == "name") d.name = f[i];
      else if (header[i] == "zeta_deg") d.zeta = num(f[i]) * deg;
      else if (header[i] == "epsilon") {
        d.epsilon = num(f[i]);
        if (d.epsilon < 0 || d.epsilon > 1)
          throw pisco::Error(where + "column 'epsilon': expected a cross-polar leakage in [0, 1], got '" + f[i] + "'");
      } else if (header[i] == "gain") {
        d.gain = num(f[i]);
        if (!(d.gain > 0)) throw pisco::Error(where + "column 'gain': expected a positive responsivity, got '" + f[i] + "'");
      }
      else if (header[i] == "xi_deg") xi = num(f[i]) * deg;
      else if (header[i] == "eta_deg") eta = num(f[i]) * deg;
      else if (header[i] == "gamma_deg") gamma = num(f[i]) * deg;
      else if (header[i] == "hwp") {
        if (f[i] == "1" || f[i] == "true") plate.enabled = true;
        else if (f[i] == "0" || f[i] == "false") plate.enabled = false;
        else throw pisco::Error(where + "column 'hwp': expected 1, 0, true or false, got '" + f[i] + "'");
      } else if (header[i] == "hwp_gamma_deg") {
        plate.gamma = num(f[i]) * deg;
        plate.gamma_key = true;
      }
      else {
        auto it = std::find_if(beams.begin(), beams.end(), [&](const BeamConfig& b) { return b.name == f[i]; });
        if (it == beams.end()) throw pisco::Error(where + "no beam named '" + f[i] + "' in [beams]");
        d.beam = static_cast<std::size_t>(it - beams.begin());
      }
    }
    if (d.name.empty()) throw pisco::Error(where + "empty detector name");
    if (std::hypot(xi, eta) >= std::numbers::pi)
      throw pisco::Error(where + "columns 'xi_deg', 'eta_deg': the offset is not less than 180 deg from the boresight");
    d.set_offset(xi, eta, gamma);
    if (const auto [it, fresh] = line_of.emplace(d.name, lineno); !fresh)
      throw pisco::Error(where + "detector '" + d.name + "' is also on line " + std::to_string(it->second) +
                         " (expected unique detector names)");
    out.push_back(d);
    if (hwp) {
      hwp->resize(out.size() - 1);
      hwp->push_back(plate);
    }
  }
  if (out.empty()) throw pisco::Error(file.string() + ": no detectors in the focal plane table");
  return out;
}

namespace {

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
  double rate = scan.type == "ces" ? scan.ces.sample_rate : scan.type == "satellite" ? scan.satellite.sample_rate : 0.0;
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
  } else if (scan.type == "file") {
    h.angles_from_file = true;  // the pointing file's hwp_angle dataset
  } else {
    t.fail("rpm", "expected the plate's rotation (rpm or frequency_hz) or its steps (steps_deg, step_seconds)");
  }
  h.stream.phase = t.number("phase_deg", 0.0) * deg;
  if (!std::isfinite(h.stream.phase)) t.fail("phase_deg", "expected a finite angle");
  if (!h.angles_from_file && !(h.stream.sample_rate > 0))
    t.fail("sample_rate_hz", "the scan has no sample rate (type = \"" + scan.type +
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
    double xi = 0, eta = 0, gamma = 0;
    d.offset_xi_eta_gamma(xi, eta, gamma);
    plate.gamma = o.gamma.value_or(gamma + d.zeta);
    d.hwp = plate;
  }
}

}  // namespace

SimulationConfig load_config(const fs::path& file) {
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
      const pisco::ToastFocalPlane toast = pisco::read_toast_focal_plane(fp_file, beam_index(fpt, "beam", c.beams, true));
      c.detectors = toast.detectors;
      for (std::size_t i = 0; i < toast.gamma.size(); ++i) {  // TOAST's plate angle origin per detector
        c.detector_hwp.resize(c.detectors.size());
        c.detector_hwp[i].gamma = toast.gamma[i];
      }
    } else {
      if (fpt.has("beam"))
        fpt.fail("beam", "only for a TOAST focal plane (HDF5); a CSV or TOML table names each detector's beam itself");
      c.detectors = load_focal_plane(fp_file, c.beams, &c.detector_hwp);
    }
    fpt.finish();
  } else {
    read_detectors(*fp, "focal_plane", file, c.beams, c.detectors, &c.detector_hwp);
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
  assign_plates(c, file);
  t.finish();
  return c;
}

void check_hwp_times(const SimulationConfig& c, std::size_t samples) {
  if (!c.hwp.enabled || c.hwp.angles_from_file) return;
  if (const auto p = c.hwp.stream.time_problem(samples)) {
    const std::string key = p->field == "start_time" ? "start_time_s" : p->field == "frequency" ? c.hwp.rate_key : p->field;
    throw pisco::Error(c.source.string() + ": [hwp] " + key + ": " + p->what + " (over the run's " +
                       std::to_string(samples) + " samples)");
  }
}

}  // namespace pisco_cli
