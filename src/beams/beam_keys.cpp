// The keys that several kinds of [beams.NAME] table share (beam_kind.hpp), each checked where it is
// read so that its error names it.
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {

constexpr double arcmin = deg / 60;

// The library's check of the options read so far (pisco::check_beam_options, the one check of each
// option), its errors named by this table's keys.
void check_options(const Table& t, const BeamOptions& options) {
  try {
    pisco::check_beam_options(options);
  } catch (const Error& e) {
    t.fail_checked(e,
                   {{"rho_max", "rho_max_deg"},
                    {"grid_step", "grid_step_arcmin"},
                    {"split.rho_main", "sidelobe_split_deg"},
                    {"split.taper", "sidelobe_taper_deg"},
                    {"split.nside", "sidelobe_nside"},
                    {"cross_polar", "cross_polar"},
                    {"mueller", "mueller"},
                    {"far_sidelobe.radius", "far_sidelobe_deg"},
                    {"far_sidelobe.width", "far_sidelobe_width_deg"},
                    {"far_sidelobe.angle", "far_sidelobe_angle_deg"},
                    {"far_sidelobe.asymmetry", "far_sidelobe_asymmetry"}},
                   "beam: ");
  }
}

// The beam's disc and grid step.
void read_beam_grid(Table& t, BeamConfig& b) {
  b.options.rho_max = t.number("rho_max_deg", 5.0) * deg;
  b.options.grid_step = t.number("grid_step_arcmin", 0.0) * arcmin;
  check_options(t, b.options);
  // A grid has at least five nodes across the disc: a coarser one does not sample the beam.
  if (b.options.grid_step > b.options.rho_max / 2)
    t.fail("grid_step_arcmin", "a step of " + Table::format(b.options.grid_step / arcmin) +
                                   " arcmin is coarser than half of rho_max_deg = " +
                                   Table::format(b.options.rho_max / deg) +
                                   ": the grid would not sample the beam (0 for the default step)");
}

// A Gaussian's width: its half-maximum radius within rho_max, and a grid of at most
// Beamsor::max_grid_nodes nodes a side at the step it implies (by default 1/16 of the smallest FWHM on a
// 2D grid, 1/20 for a round beam's radial profile; 1/20 here, the finer of the two).
double read_width(Table& t, const BeamConfig& b, const std::string& key) {
  const double fwhm = t.number(key, 1.5) * deg;
  try {
    pisco::check_beam_width(fwhm, b.options.rho_max, key);
  } catch (const Error& e) {
    t.fail_checked(e, {{key, key}}, "beam: ");
  }
  // At least two nodes within the FWHM: a coarser grid makes the beam another beam (TOD off by factors).
  if (b.options.grid_step > fwhm / 2)
    t.fail("grid_step_arcmin", "a step of " + Table::format(b.options.grid_step / arcmin) +
                                   " arcmin is coarser than half of " + key + " = " + Table::format(fwhm / deg) +
                                   " deg: the grid would not resolve the beam (0 for the default step, FWHM / 16)");
  const double step = b.options.grid_step > 0 ? b.options.grid_step : fwhm / 20;
  if (std::ceil(2 * std::sin(b.options.rho_max) / step) + 1 > pisco::Beamsor::max_grid_nodes)
    t.fail(b.options.grid_step > 0 ? "grid_step_arcmin" : key,
           "a grid step of " + Table::format(step / arcmin) + " arcmin needs more than " +
               std::to_string(pisco::Beamsor::max_grid_nodes) + " nodes a side within rho_max_deg = " +
               Table::format(b.options.rho_max / deg) + " (set a larger grid_step_arcmin)");
  return fwhm;
}

// Sidelobes (docs/beams.md, "Sidelobes"): a main part within sidelobe_split_deg on the sky's pixels, the
// rest on a band-limited coarser sky.
void read_sidelobe_split(Table& t, BeamConfig& b) {
  if (!(t.has("sidelobe_split_deg") || t.has("sidelobe_taper_deg") || t.has("sidelobe_nside"))) return;
  if (b.kind == BeamKind::file)
    t.fail(t.has("sidelobe_split_deg") ? "sidelobe_split_deg" : t.has("sidelobe_taper_deg") ? "sidelobe_taper_deg" : "sidelobe_nside",
           "a HEALPix beamsor file (type \"file\") cannot be split; give the beam as grasp, blm, gaussian or elliptical");
  if (!t.has("sidelobe_split_deg"))
    t.fail(t.has("sidelobe_taper_deg") ? "sidelobe_taper_deg" : "sidelobe_nside",
           "only with sidelobe_split_deg, the radius of the beam's main part");
  // Given, the main part's radius is positive (the library's 0 is no split at all).
  b.options.split.rho_main = t.positive("sidelobe_split_deg", 1.0) * deg;
  b.options.split.taper = t.number("sidelobe_taper_deg", 0.0) * deg;
  const double nside = t.number("sidelobe_nside", 0.0);
  if (!(nside >= -1e9 && nside <= 1e9 && nside == std::floor(nside)))  // converted only within range
    t.fail("sidelobe_nside", "expected an integer, a power of two up to 8192 (or 0: chosen from the sidelobes' band limit)");
  b.options.split.nside = static_cast<int>(nside);
  check_options(t, b.options);
}

// A far sidelobe ring (docs/beams.md, "Far sidelobes"): its keys only with far_sidelobe_db.
static void read_far_sidelobe(Table& t, BeamConfig& b) {
  if (!t.has("far_sidelobe_db")) {
    for (const char* key : {"far_sidelobe_deg", "far_sidelobe_width_deg", "far_sidelobe_angle_deg", "far_sidelobe_asymmetry"})
      if (t.has(key)) t.fail(key, "a far sidelobe needs far_sidelobe_db");
    return;
  }
  // The level in dB (the library's is a power ratio); the rest the library checks.
  const double db = t.number("far_sidelobe_db", 0.0);
  if (!(db <= 0.0 && db >= -200.0)) t.fail("far_sidelobe_db", "expected a level in [-200, 0] dB of the main beam's peak");
  pisco::FarSidelobe& far = b.options.far_sidelobe;
  far.level = std::pow(10.0, db / 10.0);
  far.radius = t.number("far_sidelobe_deg", 0.0) * deg;
  far.width = t.number("far_sidelobe_width_deg", 0.0) * deg;
  far.angle = t.number("far_sidelobe_angle_deg", 0.0) * deg;
  far.asymmetry = t.number("far_sidelobe_asymmetry", 0.0);
}

// An analytic beam's polarization: its cross-polar part, far sidelobe and Mueller matrix.
void read_analytic_beam(Table& t, BeamConfig& b) {
  b.options.cross_polar = t.number("cross_polar", 0.0);
  b.options.cross_polar_pattern =
      t.choice("cross_polar_pattern", "uniform", {"uniform", "quadrupole"}) == "uniform"
          ? pisco::CrossPolarPattern::uniform
          : pisco::CrossPolarPattern::quadrupole;
  read_far_sidelobe(t, b);
  const std::vector<double> m = t.numbers("mueller", {});
  if (!m.empty()) {
    if (m.size() != 16) t.fail("mueller", "expected 16 numbers (a 4x4 Mueller matrix, row by row)");
    for (int i = 0; i < 16; ++i) b.options.mueller[i / 4][i % 4] = m[i];
  }
  check_options(t, b.options);
}

void read_beam_file(Table& t, BeamConfig& b, const std::string& needs) {
  b.file = t.input_file("file");
  if (b.file.empty()) t.fail("file", needs);
}

}  // namespace pisco::detail
