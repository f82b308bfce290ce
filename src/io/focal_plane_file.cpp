// Focal plane tables (docs/config.md, "[focal_plane]"): CSV, TOML ([[detectors]], [[pairs]]) and
// TOAST's HDF5 tables, each detector's beam named by a [beams] table.
#include "io/csv_text.hpp"
#include "io/focal_plane_file.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>

#include "io/input_file.hpp"
#include "pisco/units.hpp"

namespace pisco {
namespace detail {

namespace {
using pisco::deg;

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

}  // namespace

std::size_t beam_index(Table& t, const std::string& key, const std::vector<std::string>& beams, bool required) {
  const auto name = t.string(key);
  if (!name) {
    if (required && beams.size() != 1) t.fail(key, "expected the name of one of the [beams] tables");
    return 0;
  }
  for (std::size_t i = 0; i < beams.size(); ++i)
    if (beams[i] == *name) return i;
  t.fail(key, "no beam named \"" + *name + "\" in [beams]");
}

void read_detectors(const toml::table& root, const std::string& where, const fs::path& file,
                    const std::vector<std::string>& beams, std::vector<pisco::Detector>& out,
                    std::vector<DetectorHwp>* hwp) {
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
      b.zeta = zeta - std::numbers::pi / 2;  // the pair partner (docs/config.md, focal_plane.pairs)
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

// Whether a focal plane file is a TOAST table (HDF5): by its extension, else by the HDF5 signature at
// its start.
bool is_hdf5_focal_plane(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".h5" || ext == ".hdf5" || ext == ".he5" || ext == ".hdf") return true;
  std::ifstream in(file, std::ios::binary);
  char head[8] = {};
  return in.read(head, sizeof head) && std::string(head, sizeof head) == std::string("\x89HDF\r\n\x1a\n", 8);
}

}  // namespace detail

using namespace detail;

std::vector<Detector> read_focal_plane_file(const fs::path& file, const std::vector<std::string>& beams,
                                            std::vector<DetectorHwp>* hwp) {
  std::vector<pisco::Detector> out;
  pisco::detail::require_regular_file(file, "a focal plane file: CSV, TOML or TOAST HDF5");
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
  std::size_t lineno = 0;
  std::map<std::string, int> line_of;  // each detector's line
  while (std::getline(in, line)) {
    if (!csv_content_line(line, ++lineno)) continue;
    const auto f = csv_fields(line);
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
        if (const std::optional<double> v = csv_number(s)) return *v;
        throw pisco::Error(where + "column '" + header[i] + "': expected a number, got '" + s + "'");
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
        auto it = std::find(beams.begin(), beams.end(), f[i]);
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

}  // namespace pisco
