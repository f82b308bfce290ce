// TICRA GRASP far fields (docs/beams.md, "GRASP files"): .grd grid files and .cut cut files, read into
// GraspBeam, and their Stokes patterns interpolated onto a beamsor's grid.
//
// .grd: free text up to a line starting with "++++" (a line "FREQUENCIES [unit]:" is followed by the
// frequencies, one a field set), then KTYPE (1), "NSET ICOMP NCOMP IGRID", NSET lines "IX IY" (each
// set's centre in grid steps), and per set "XS YS XE YE", "NX NY KLIMIT" and NY rows of NX points, x
// fastest (with KLIMIT = 1 each row starts with "IS IN": its IN points start at column IS), each point
// NCOMP complex components as 2 NCOMP reals. Grid point (i, j) (from 1) lies at
// x = (IX + i - 1) DX + XS, DX = (XE - XS) / (NX - 1), the same in y.
// .cut: per cut one text line, then "V_INI V_INC V_NUM C ICOMP ICUT NCOMP" and V_NUM rows of 2 NCOMP
// reals; a polar cut (ICUT 1) holds phi = C and runs theta from V_INI by V_INC (degrees). A file's cuts
// at increasing phi form one beam; a cut whose phi is not above the previous one starts the next beam
// (the next frequency).
#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "io/input_file.hpp"
#include "core/text.hpp"
#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace {

namespace fs = std::filesystem;
using cd = std::complex<double>;
constexpr double pi = std::numbers::pi;

class Lines {
 public:
  explicit Lines(const fs::path& file)
      : file_(file), size_(detail::require_regular_file(file, "a TICRA GRASP .grd or .cut file")), in_(file) {
    if (!in_) throw Error(file.string() + ": cannot be opened for reading; expected a TICRA GRASP .grd or .cut file");
  }
  // The bytes after the lines read so far: what the rest of the file can hold.
  std::uintmax_t remaining() {
    const auto at = in_.tellg();
    return at < 0 || std::uintmax_t(at) > size_ ? 0 : size_ - std::uintmax_t(at);
  }
  // The next line, or false at the end of the file.
  bool next(std::string& line) {
    if (!std::getline(in_, line)) return false;
    ++number_;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  }
  // The next line that is not blank; fails naming `what` at the end of the file.
  std::string require(const std::string& what) {
    std::string line;
    while (next(line))
      if (line.find_first_not_of(" \t") != std::string::npos) return line;
    fail("ends before " + what);
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw Error(file_.string() + ": line " + std::to_string(number_) + ": " + what);
  }
  int number() const { return number_; }
  const fs::path& file() const { return file_; }

 private:
  fs::path file_;
  std::uintmax_t size_;
  std::ifstream in_;
  int number_ = 0;
};

// The numbers of a line; nullopt where a field is not a number (Fortran's D exponents accepted).
std::optional<std::vector<double>> numbers(std::string line) {
  std::replace(line.begin(), line.end(), ',', ' ');
  std::vector<double> out;
  std::istringstream s(line);
  std::string token;
  while (s >> token) {
    for (char& c : token)
      if (c == 'D' || c == 'd') c = 'E';
    double v = 0;
    const char* first = token.data();
    const char* last = token.data() + token.size();
    if (*first == '+') ++first;
    const auto [end, ec] = std::from_chars(first, last, v);
    if (ec != std::errc() || end != last) {
      // NaN and Inf as Fortran and C print them.
      std::string u = token;
      std::transform(u.begin(), u.end(), u.begin(), ::toupper);
      if (u == "NAN" || u == "-NAN" || u == "+NAN") v = std::nan("");
      else if (u == "INF" || u == "+INF" || u == "INFINITY") v = HUGE_VAL;
      else if (u == "-INF" || u == "-INFINITY") v = -HUGE_VAL;
      else return std::nullopt;
    }
    out.push_back(v);
  }
  return out;
}

std::vector<double> expect_numbers(Lines& in, const std::string& what, std::size_t count) {
  const std::string line = in.require(what);
  const auto v = numbers(line);
  if (!v || v->size() < count)
    in.fail("expected " + what + " (" + std::to_string(count) + " numbers), got \"" + line.substr(0, 80) + "\"");
  return *v;
}

int as_int(Lines& in, double v, const std::string& name, int lo, int hi) {
  if (!(v == std::floor(v) && v >= lo && v <= hi))
    in.fail(name + " = " + std::to_string(v) + ": expected an integer in " + std::to_string(lo) + ".." + std::to_string(hi));
  return static_cast<int>(v);
}

const char* icomp_text(int icomp) {
  switch (icomp) {
    case 1: return "E_theta and E_phi";
    case 2: return "right- and left-hand circular components";
    case 3: return "linear co- and cross-polar components (Ludwig 3)";
    case 4: return "the polarization ellipse's major and minor axes";
    case 9: return "total power and sqrt(rhc/lhc)";
    default: return "components of another kind";
  }
}

void check_icomp(Lines& in, int icomp, int ncomp) {
  if (icomp != 3)
    in.fail("ICOMP = " + std::to_string(icomp) + " (" + icomp_text(icomp) +
            "): expected ICOMP = 3, the linear co- and cross-polar components (Ludwig 3) a beamsor is made of");
  if (ncomp != 2 && ncomp != 3)
    in.fail("NCOMP = " + std::to_string(ncomp) + ": expected 2 or 3 field components (co, cx and optionally a third, ignored)");
}

// One row of field values: 2 ncomp numbers, all finite.
void read_point(Lines& in, int ncomp, const std::string& where, cd& co, cd& cx) {
  const std::string line = in.require(where);
  const auto v = numbers(line);
  const std::size_t want = 2 * static_cast<std::size_t>(ncomp);
  if (!v || v->size() != want)
    in.fail(where + ": expected " + std::to_string(want) + " numbers (NCOMP = " + std::to_string(ncomp) +
            " complex components), got \"" + line.substr(0, 80) + "\"");
  for (double x : *v)
    if (!std::isfinite(x)) in.fail(where + ": the field is not finite (\"" + line.substr(0, 80) + "\")");
  co = cd((*v)[0], (*v)[1]);
  cx = cd((*v)[2], (*v)[3]);
}

std::vector<GraspBeam> read_grid(const fs::path& file) {
  Lines in(file);
  std::string line;
  std::vector<double> frequencies;
  bool found = false;
  while (in.next(line)) {
    if (line.rfind("++++", 0) == 0) {
      found = true;
      break;
    }
    std::string upper = line;
    std::transform(upper.begin(), upper.end(), upper.begin(), ::toupper);
    if (upper.find("FREQUENCIES") != std::string::npos) {
      std::string values;
      if (!in.next(values)) break;
      if (values.rfind("++++", 0) == 0) {
        found = true;
        break;
      }
      if (auto v = numbers(values)) frequencies = *v;
    }
  }
  if (!found) in.fail("no line starting with \"++++\" ends the header; expected a TICRA GRASP .grd file");
  const int ktype = as_int(in, expect_numbers(in, "KTYPE", 1)[0], "KTYPE", 0, 1000);
  if (ktype != 1) in.fail("KTYPE = " + std::to_string(ktype) + ": expected 1 (the grid format GRASP writes)");
  const auto head = expect_numbers(in, "NSET ICOMP NCOMP IGRID", 4);
  const int nset = as_int(in, head[0], "NSET", 1, 100000);
  const int icomp = as_int(in, head[1], "ICOMP", 1, 100);
  const int ncomp = as_int(in, head[2], "NCOMP", 1, 100);
  const int igrid = as_int(in, head[3], "IGRID", 1, 100);
  check_icomp(in, icomp, ncomp);
  GraspBeam::Grid grid;
  switch (igrid) {
    case 1: grid = GraspBeam::Grid::uv; break;
    case 4: grid = GraspBeam::Grid::elevation_over_azimuth; break;
    case 5: grid = GraspBeam::Grid::elevation_and_azimuth; break;
    case 6: grid = GraspBeam::Grid::azimuth_over_elevation; break;
    case 7: grid = GraspBeam::Grid::theta_phi; break;
    default:
      in.fail("IGRID = " + std::to_string(igrid) +
              ": expected 1 (uv grid), 4 (elevation over azimuth), 5 (elevation and azimuth), 6 (azimuth over "
              "elevation) or 7 (theta-phi grid); export the beam from GRASP on one of these");
  }
  std::vector<std::pair<double, double>> centre;
  for (int s = 0; s < nset; ++s) {
    const auto c = expect_numbers(in, "the centre \"IX IY\" of field set " + std::to_string(s + 1), 2);
    if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || std::abs(c[0]) > 1e6 || std::abs(c[1]) > 1e6)
      in.fail("the centre \"IX IY\" of field set " + std::to_string(s + 1) +
              " must be finite grid offsets (at most 1e6 steps), got " + detail::number_text(c[0]) + " " +
              detail::number_text(c[1]));
    centre.emplace_back(c[0], c[1]);
  }
  std::vector<GraspBeam> beams;
  for (int s = 0; s < nset; ++s) {
    const std::string set = "field set " + std::to_string(s + 1) + " of " + std::to_string(nset);
    const auto ext = expect_numbers(in, "XS YS XE YE of " + set, 4);
    for (double x : ext)
      if (!std::isfinite(x)) in.fail("XS YS XE YE of " + set + " must be finite");
    const auto size = expect_numbers(in, "NX NY KLIMIT of " + set, 3);
    const int nx = as_int(in, size[0], "NX", 2, 100000);
    const int ny = as_int(in, size[1], "NY", 2, 100000);
    const int klimit = as_int(in, size[2], "KLIMIT", 0, 1);
    if (static_cast<double>(nx) * ny > 1e8) in.fail("NX NY = " + std::to_string(nx) + " x " + std::to_string(ny) + ": more than 1e8 points");
    // Declared against what the rest of the file can hold, before the grid is allocated (32 bytes a
    // point): a point's line holds 2 NCOMP numbers, each at least a digit and a separator. Rows with
    // limits (KLIMIT = 1) may hold part of the grid: up to four times what the file holds, plus 1e6.
    {
      const double holdable = static_cast<double>(in.remaining()) / (4.0 * ncomp);
      const double points = static_cast<double>(nx) * ny;
      if (points > (klimit == 1 ? 4.0 * holdable + 1e6 : holdable))
        in.fail("NX NY = " + std::to_string(nx) + " x " + std::to_string(ny) + " of " + set + " declares " +
                detail::count_text(points) + " points (" + detail::bytes_text(32.0 * points) + " in memory), but the " +
                std::to_string(in.remaining()) + " bytes left in the file hold at most " + detail::count_text(holdable) +
                "; expected a grid the file holds");
    }
    if (ext[2] == ext[0] || ext[3] == ext[1]) in.fail("XS YS XE YE of " + set + ": the grid has no extent");
    GraspBeam b;
    b.grid = grid;
    b.nx = nx;
    b.ny = ny;
    const double dx = (ext[2] - ext[0]) / (nx - 1), dy = (ext[3] - ext[1]) / (ny - 1);
    const double unit = grid == GraspBeam::Grid::uv ? 1.0 : pi / 180;
    b.xs = (ext[0] + centre[static_cast<std::size_t>(s)].first * dx) * unit;
    b.xe = (ext[2] + centre[static_cast<std::size_t>(s)].first * dx) * unit;
    b.ys = (ext[1] + centre[static_cast<std::size_t>(s)].second * dy) * unit;
    b.ye = (ext[3] + centre[static_cast<std::size_t>(s)].second * dy) * unit;
    b.co.assign(static_cast<std::size_t>(nx) * ny, cd{});
    b.cx.assign(static_cast<std::size_t>(nx) * ny, cd{});
    for (int j = 0; j < ny; ++j) {
      int first = 1, count = nx;
      if (klimit == 1) {
        const auto lim = expect_numbers(in, "the row limits \"IS IN\" of row " + std::to_string(j + 1) + " of " + set, 2);
        first = as_int(in, lim[0], "IS", 1, nx);
        count = as_int(in, lim[1], "IN", 0, nx - first + 1);
      }
      for (int i = first; i < first + count; ++i) {
        const std::string where = "point " + std::to_string(i) + " of row " + std::to_string(j + 1) + " of " + set +
                                  " (" + std::to_string(nx) + " x " + std::to_string(ny) + " points)";
        const std::size_t k = static_cast<std::size_t>(j) * nx + (i - 1);
        read_point(in, ncomp, where, b.co[k], b.cx[k]);
      }
    }
    b.source = file.string() + (nset > 1 ? " (beam " + std::to_string(s + 1) + " of " + std::to_string(nset) + ")" : "");
    if (static_cast<std::size_t>(s) < frequencies.size()) b.frequency = frequencies[static_cast<std::size_t>(s)];
    beams.push_back(std::move(b));
  }
  return beams;
}

std::vector<GraspBeam> read_cuts(const fs::path& file) {
  Lines in(file);
  struct Cut {
    double vini, vinc, phi;
    int vnum, line;
    std::vector<cd> co, cx;
  };
  std::vector<std::vector<Cut>> groups;
  std::string text;
  while (true) {
    // The cut's text line (any text), then its parameters.
    bool more = false;
    while (in.next(text))
      if (text.find_first_not_of(" \t") != std::string::npos) {
        more = true;
        break;
      }
    if (!more) break;
    const auto p = expect_numbers(in, "the cut parameters \"V_INI V_INC V_NUM C ICOMP ICUT NCOMP\"", 7);
    Cut c;
    c.line = in.number();
    c.vini = p[0];
    c.vinc = p[1];
    c.vnum = as_int(in, p[2], "V_NUM", 2, 10000000);
    c.phi = p[3];
    const int icomp = as_int(in, p[4], "ICOMP", 1, 100);
    const int icut = as_int(in, p[5], "ICUT", 1, 100);
    const int ncomp = as_int(in, p[6], "NCOMP", 1, 100);
    if (!std::isfinite(c.vini) || !std::isfinite(c.vinc) || !(c.vinc != 0) || !std::isfinite(c.phi))
      in.fail("V_INI, V_INC and C must be finite and V_INC non-zero");
    if (icut != 1)
      in.fail("ICUT = " + std::to_string(icut) + ": expected 1 (a polar cut: phi = C fixed, theta varying); conical cuts are not read");
    check_icomp(in, icomp, ncomp);
    if (const double holdable = static_cast<double>(in.remaining()) / (4.0 * ncomp); c.vnum > holdable)
      in.fail("V_NUM = " + std::to_string(c.vnum) + " declares " + detail::bytes_text(32.0 * c.vnum) +
              " of points, but the " + std::to_string(in.remaining()) + " bytes left in the file hold at most " +
              detail::count_text(holdable) + " points; expected a cut the file holds");
    c.co.resize(static_cast<std::size_t>(c.vnum));
    c.cx.resize(static_cast<std::size_t>(c.vnum));
    for (int k = 0; k < c.vnum; ++k)
      read_point(in, ncomp, "point " + std::to_string(k + 1) + " of " + std::to_string(c.vnum) + " of the cut at phi = " +
                                std::to_string(c.phi) + " deg", c.co[static_cast<std::size_t>(k)], c.cx[static_cast<std::size_t>(k)]);
    if (groups.empty() || c.phi <= groups.back().back().phi) groups.emplace_back();
    groups.back().push_back(std::move(c));
  }
  if (groups.empty()) in.fail("holds no cut; expected a TICRA GRASP .cut file");
  std::vector<GraspBeam> beams;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    const auto& cuts = groups[g];
    GraspBeam b;
    b.grid = GraspBeam::Grid::cuts;
    b.nx = static_cast<int>(cuts.size());
    b.ny = cuts[0].vnum;
    b.ys = cuts[0].vini * pi / 180;
    b.ye = (cuts[0].vini + (cuts[0].vnum - 1) * cuts[0].vinc) * pi / 180;
    for (const Cut& c : cuts) {
      if (c.vnum != cuts[0].vnum || c.vini != cuts[0].vini || c.vinc != cuts[0].vinc)
        throw Error(file.string() + ": line " + std::to_string(c.line) + ": the cut at phi = " + std::to_string(c.phi) +
                    " deg samples theta differently from the cut at phi = " + std::to_string(cuts[0].phi) +
                    " deg; expected the same V_INI, V_INC and V_NUM in every cut of a beam");
      b.x_values.push_back(c.phi * pi / 180);
    }
    b.xs = b.x_values.front();
    b.xe = b.x_values.back();
    b.co.resize(static_cast<std::size_t>(b.nx) * b.ny);
    b.cx.resize(b.co.size());
    for (int i = 0; i < b.nx; ++i)
      for (int j = 0; j < b.ny; ++j) {
        b.co[static_cast<std::size_t>(j) * b.nx + i] = cuts[static_cast<std::size_t>(i)].co[static_cast<std::size_t>(j)];
        b.cx[static_cast<std::size_t>(j) * b.nx + i] = cuts[static_cast<std::size_t>(i)].cx[static_cast<std::size_t>(j)];
      }
    b.source = file.string() + (groups.size() > 1 ? " (beam " + std::to_string(g + 1) + " of " + std::to_string(groups.size()) + ")" : "");
    beams.push_back(std::move(b));
  }
  return beams;
}

// ---- interpolation ------------------------------------------------------------------------------

using Stokes = std::array<double, 4>;

Stokes stokes_of(cd co, cd cx) {
  const cd x = co * std::conj(cx);
  return {std::norm(co) + std::norm(cx), std::norm(co) - std::norm(cx), 2 * x.real(), 2 * x.imag()};
}

// Lagrange weights of the `points` nodes first, first + 1, ... at position t (in node units), on a
// line of n nodes of the file `source`.
int lagrange(double t, int n, int points, double* w, const std::string& source) {
  // Callers ask within the nodes (t in [0, n - 1], to rounding); anything else, a NaN included, is a
  // bug that must not reach the cast to int.
  if (!(t >= -1.0 && t <= n))
    throw Error(source + ": interpolation at node position " + detail::number_text(t) + " outside the file's " +
                std::to_string(n) + " nodes along an axis (expected 0 to " + std::to_string(n - 1) + ")");
  int first = static_cast<int>(std::floor(t)) - (points / 2 - 1);
  first = std::clamp(first, 0, n - points);
  for (int a = 0; a < points; ++a) {
    double v = 1.0;
    for (int b = 0; b < points; ++b)
      if (b != a) v *= (t - (first + b)) / static_cast<double>(a - b);
    w[a] = v;
  }
  return first;
}

// A regular grid of Stokes values in (x, y), x fastest: 6-point Lagrange along each axis.
struct RegularStokes {
  std::string source;
  int nx = 0, ny = 0;
  double xs = 0, ys = 0, dx = 0, dy = 0;
  std::vector<Stokes> s;
  bool inside(double x, double y) const {
    const double u = (x - xs) / dx, v = (y - ys) / dy;
    return u >= -1e-9 && v >= -1e-9 && u <= nx - 1 + 1e-9 && v <= ny - 1 + 1e-9;
  }
  Stokes at(double x, double y) const {
    const int px = std::min(6, nx), py = std::min(6, ny);
    double wx[6], wy[6];
    const int i0 = lagrange((x - xs) / dx, nx, px, wx, source);
    const int j0 = lagrange((y - ys) / dy, ny, py, wy, source);
    Stokes out{};
    for (int b = 0; b < py; ++b)
      for (int a = 0; a < px; ++a) {
        const Stokes& v = s[static_cast<std::size_t>(j0 + b) * nx + (i0 + a)];
        const double w = wx[a] * wy[b];
        for (int k = 0; k < 4; ++k) out[k] += w * v[k];
      }
    return out;
  }
};

// Half-lines from the beam axis at evenly spaced phi, sampled at theta = 0, dtheta, ...:
// 6-point Lagrange in theta (continued through the axis onto the opposite half-line), then
// trigonometric interpolation in phi.
struct PolarStokes {
  std::string source;
  int nphi = 0, ntheta = 0;
  double phi0 = 0, dtheta = 0;
  std::vector<Stokes> s;  // [k * ntheta + j]
  double theta_max() const { return (ntheta - 1) * dtheta; }
  Stokes at(double theta, double phi) const {
    const bool through = nphi % 2 == 0;
    // The extended line of half-line k: index j >= 0 at theta = j dtheta on k, j < 0 on k + nphi/2.
    const int lo = through ? -(ntheta - 1) : 0;
    const int points = std::min(6, ntheta - lo);
    double w[6];
    const int first = lagrange(theta / dtheta - lo, ntheta - lo, points, w, source) + lo;
    std::vector<Stokes> line(static_cast<std::size_t>(nphi));
    for (int k = 0; k < nphi; ++k) {
      Stokes v{};
      for (int a = 0; a < points; ++a) {
        const int j = first + a;
        const int kk = j >= 0 ? k : (k + nphi / 2) % nphi;
        const Stokes& x = s[static_cast<std::size_t>(kk) * ntheta + std::abs(j)];
        for (int c = 0; c < 4; ++c) v[c] += w[a] * x[c];
      }
      line[static_cast<std::size_t>(k)] = v;
    }
    // Periodic interpolation through nphi evenly spaced samples (the Dirichlet kernel).
    Stokes out{};
    const double h = 2 * pi / nphi;
    for (int k = 0; k < nphi; ++k) {
      const double x = phi - (phi0 + k * h);
      const double half = 0.5 * x;
      const double sn = std::sin(half);
      double kernel;
      if (std::abs(sn) < 1e-12) {
        kernel = std::cos(half * nphi) / std::cos(half);  // the limit: +-1 at x = 2 pi k
        kernel = std::abs(std::remainder(x, 2 * pi)) < 1e-9 ? 1.0 : kernel;
      } else if (nphi % 2 == 0) {
        kernel = std::sin(nphi * half) / (nphi * std::tan(half));
      } else {
        kernel = std::sin(nphi * half) / (nphi * sn);
      }
      for (int c = 0; c < 4; ++c) out[c] += kernel * line[static_cast<std::size_t>(k)][c];
    }
    return out;
  }
};

// A theta-phi description (cuts or an IGRID 7 grid) as half-lines; fails naming the file.
PolarStokes polar_of(const GraspBeam& b, const std::vector<double>& phis, const std::vector<double>& thetas) {
  const auto fail = [&](const std::string& what) { throw Error(b.source + ": " + what); };
  const int nt = static_cast<int>(thetas.size());
  const double dtheta = std::abs(thetas.size() > 1 ? thetas[1] - thetas[0] : 0.0);
  if (!(dtheta > 0)) fail("theta does not advance along the cuts");
  // Each (phi, theta) sample as (half-line phi, index |theta| / dtheta).
  struct Sample {
    double phi;
    int j;
    Stokes s;
  };
  std::vector<Sample> samples;
  int jmax = 0;
  for (std::size_t i = 0; i < phis.size(); ++i)
    for (int t = 0; t < nt; ++t) {
      const double theta = thetas[static_cast<std::size_t>(t)];
      const double jf = std::abs(theta) / dtheta;
      // A grid through the axis reaches at most nt - 1 steps from it: anything further (or a NaN) is
      // refused before the cast to int.
      if (!(jf <= nt))
        fail("theta = " + std::to_string(theta * 180 / pi) + " deg lies " + detail::number_text(jf) +
             " steps of " + std::to_string(dtheta * 180 / pi) + " deg from the beam axis, beyond the " +
             std::to_string(nt) + " samples of a cut; expected theta samples on a grid through the beam axis");
      if (!std::isfinite(phis[i]))
        fail("phi = " + detail::number_text(phis[i] * 180 / pi) + " deg is not finite");
      const int j = static_cast<int>(std::lround(jf));
      if (std::abs(jf - j) > 1e-6)
        fail("theta = " + std::to_string(theta * 180 / pi) + " deg is not a multiple of the step " +
             std::to_string(dtheta * 180 / pi) + " deg; expected theta samples on a grid through the beam axis");
      double phi = phis[i] + (theta < 0 ? pi : 0.0);
      phi = std::remainder(phi, 2 * pi);
      if (phi < 0) phi += 2 * pi;
      const std::size_t k = static_cast<std::size_t>(t) * phis.size() + i;
      samples.push_back({phi, j, stokes_of(b.co[k], b.cx[k])});
      jmax = std::max(jmax, j);
    }
  // The distinct half-lines, evenly spaced over the circle.
  std::vector<double> lines;
  for (const Sample& s : samples) {
    if (s.j == 0) continue;
    bool known = false;
    for (double p : lines)
      if (std::abs(std::remainder(p - s.phi, 2 * pi)) < 1e-6) known = true;
    if (!known) lines.push_back(s.phi);
  }
  std::sort(lines.begin(), lines.end());
  const int n = static_cast<int>(lines.size());
  if (n < 1) fail("no samples off the beam axis");
  for (int k = 0; k < n; ++k)
    if (std::abs(std::remainder(lines[static_cast<std::size_t>(k)] - (lines[0] + k * 2 * pi / n), 2 * pi)) > 1e-6)
      fail("the cuts' phi (with theta < 0 as phi + 180 deg) are not evenly spaced around the beam axis: " + std::to_string(n) +
           " half-lines, expected a step of " + std::to_string(360.0 / n) + " deg");
  PolarStokes p;
  p.source = b.source;
  p.nphi = n;
  p.ntheta = jmax + 1;
  p.phi0 = lines[0];
  p.dtheta = dtheta;
  p.s.assign(static_cast<std::size_t>(n) * p.ntheta, Stokes{std::nan(""), 0, 0, 0});
  Stokes axis{std::nan(""), 0, 0, 0};
  for (const Sample& s : samples) {
    if (s.j == 0) {
      axis = s.s;
      continue;
    }
    // In [n/2, 3n/2] for a finite phi (checked above): a bound before the cast to int.
    const double kf = std::remainder(s.phi - p.phi0, 2 * pi) / (2 * pi / n) + n;
    if (!(kf >= 0.0 && kf <= 2.0 * n))
      fail("phi = " + detail::number_text(s.phi * 180 / pi) + " deg falls on half-line " + detail::number_text(kf) +
           " of " + std::to_string(n));
    const int k = static_cast<int>(std::lround(kf)) % n;
    p.s[static_cast<std::size_t>(k) * p.ntheta + s.j] = s.s;
  }
  if (std::isnan(axis[0])) fail("no sample on the beam axis (theta = 0); expected cuts through the axis");
  for (int k = 0; k < n; ++k) {
    p.s[static_cast<std::size_t>(k) * p.ntheta] = axis;
    for (int j = 1; j < p.ntheta; ++j)
      if (std::isnan(p.s[static_cast<std::size_t>(k) * p.ntheta + j][0]))
        fail("the half-line at phi = " + std::to_string(lines[static_cast<std::size_t>(k)] * 180 / pi) + " deg has no sample at theta = " +
             std::to_string(j * dtheta * 180 / pi) + " deg; expected every cut to cover the same theta range");
  }
  return p;
}

}  // namespace

std::vector<GraspBeam> GraspBeam::read(const std::filesystem::path& file) {
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  if (ext == ".grd") return read_grid(file);
  if (ext == ".cut") return read_cuts(file);
  throw Error(file.string() + ": expected a TICRA GRASP file named .grd (a grid) or .cut (cuts)");
}

Beamsor Beamsor::from_grasp(const GraspBeam& b, const FileBeamOptions& options) {
  check_file_beam_options(options, b.source);
  if (b.nx < 2 || b.ny < 2 || b.co.size() != static_cast<std::size_t>(b.nx) * b.ny || b.cx.size() != b.co.size())
    throw Error(b.source + ": the field holds " + std::to_string(b.co.size()) + " points; expected NX x NY = " +
                std::to_string(b.nx) + " x " + std::to_string(b.ny));
  const double angle = options.angle;
  const double rho_max = options.rho_max;
  Field field;
  double file_step = 0.0;
  double reach = 0.0;  // how far from the axis the file's samples reach (radians)
  std::string kind;
  if (b.grid != GraspBeam::Grid::theta_phi && b.grid != GraspBeam::Grid::cuts) {
    auto g = std::make_shared<RegularStokes>();
    g->source = b.source;
    g->nx = b.nx;
    g->ny = b.ny;
    g->xs = b.xs;
    g->ys = b.ys;
    g->dx = (b.xe - b.xs) / (b.nx - 1);
    g->dy = (b.ye - b.ys) / (b.ny - 1);
    g->s.resize(b.co.size());
    for (std::size_t k = 0; k < b.co.size(); ++k) g->s[k] = stokes_of(b.co[k], b.cx[k]);
    const GraspBeam::Grid type = b.grid;
    const bool uv = type == GraspBeam::Grid::uv;
    file_step = std::min(std::abs(g->dx), std::abs(g->dy));
    const double half = std::min({std::abs(b.xs), std::abs(b.xe), std::abs(b.ys), std::abs(b.ye)});
    if (b.xs * b.xe > 0 || b.ys * b.ye > 0)
      throw Error(b.source + ": the grid does not contain the beam axis (u = v = 0); expected a grid about the beam's axis");
    reach = uv ? std::asin(std::min(1.0, half)) : half;
    kind = uv ? "uv grid"
           : type == GraspBeam::Grid::elevation_and_azimuth ? "elevation-and-azimuth grid"
           : type == GraspBeam::Grid::elevation_over_azimuth ? "elevation-over-azimuth grid"
                                                              : "azimuth-over-elevation grid";
    field = [g, type, angle](double rho, double sigma) {
      const double s = sigma - angle;
      // The direction (u, v, w) = (sin(theta) cos(phi), sin(theta) sin(phi), cos(theta)) in each grid's
      // coordinates, all with az = -u and el = v to first order about the axis (docs/beams.md).
      const double u = std::sin(rho) * std::cos(s), v = std::sin(rho) * std::sin(s), w = std::cos(rho);
      double x, y;
      switch (type) {
        case GraspBeam::Grid::uv: x = u; y = v; break;
        case GraspBeam::Grid::elevation_and_azimuth: x = -rho * std::cos(s); y = rho * std::sin(s); break;
        case GraspBeam::Grid::elevation_over_azimuth: x = -std::atan2(u, w); y = std::asin(std::clamp(v, -1.0, 1.0)); break;
        default: x = -std::asin(std::clamp(u, -1.0, 1.0)); y = std::atan2(v, w); break;  // azimuth over elevation
      }
      if (!g->inside(x, y)) return Mueller{};
      const Stokes st = g->at(x, y);
      return stokes_mueller(st[0], st[1], st[2], st[3]);
    };
  } else {
    std::vector<double> phis, thetas;
    if (b.grid == GraspBeam::Grid::cuts) {
      phis = b.x_values;
    } else {
      for (int i = 0; i < b.nx; ++i) phis.push_back(b.xs + i * (b.xe - b.xs) / (b.nx - 1));
    }
    for (int j = 0; j < b.ny; ++j) thetas.push_back(b.ys + j * (b.ye - b.ys) / (b.ny - 1));
    // A theta-phi grid whose last column repeats its first (phi = 360 deg) is one column shorter.
    GraspBeam copy;
    const GraspBeam* src = &b;
    if (b.grid == GraspBeam::Grid::theta_phi && phis.size() > 1 &&
        std::abs(std::remainder(phis.back() - phis.front(), 2 * pi)) < 1e-9) {
      copy = b;
      copy.co.clear();
      copy.cx.clear();
      for (int j = 0; j < b.ny; ++j)
        for (int i = 0; i + 1 < b.nx; ++i) {
          copy.co.push_back(b.co[static_cast<std::size_t>(j) * b.nx + i]);
          copy.cx.push_back(b.cx[static_cast<std::size_t>(j) * b.nx + i]);
        }
      phis.pop_back();
      src = &copy;
    }
    auto p = std::make_shared<PolarStokes>(polar_of(*src, phis, thetas));
    file_step = p->dtheta;
    reach = p->theta_max();
    kind = b.grid == GraspBeam::Grid::cuts ? std::to_string(phis.size()) + " cuts" : "theta-phi grid";
    field = [p, angle](double rho, double sigma) {
      if (rho > p->theta_max() * (1 + 1e-12)) return Mueller{};
      const Stokes v = p->at(rho, sigma - angle);
      return stokes_mueller(v[0], v[1], v[2], v[3]);
    };
  }
  if (rho_max > reach * (1 + 1e-9))
    throw Error(b.source + ": the file's " + kind + " reaches " + detail::degrees_text(reach) +
                " from the beam axis; rho_max = " + detail::degrees_text(rho_max) + " is beyond it (set rho_max_deg <= " +
                std::to_string(reach / deg) + ")");
  // By default 1 / 1.6 of the file's own step (docs/beams.md, "GRASP files").
  double step = options.grid_step > 0 ? options.grid_step : file_step / 1.6;
  step = std::max(step, 2 * std::sin(rho_max) / (max_grid_nodes - 2));
  std::ostringstream d;
  d << "GRASP " << kind << " " << b.source;
  if (b.frequency > 0) d << " (frequency " << b.frequency << ")";
  if (angle != 0.0) d << ", turned by " << angle / deg << " deg";
  d << ", rho_max " << rho_max / deg << " deg, grid step " << step / deg * 60 << " arcmin";
  return from_field(field, rho_max, step, d.str(), 0.0, false, options.split);
}

}  // namespace pisco
