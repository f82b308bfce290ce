// TOAST 3 focal plane files (docs/formats.md, "TOAST focal planes"): the table that
// toast.instrument.Focalplane.save_hdf5 writes through astropy, a compound dataset `focalplane` with
// one row per detector, and beside it `focalplane.__table_column_meta__`, astropy's YAML header (one
// string per line) that carries the columns' units and the table's meta (sample_rate).
//
// Only what the mapping onto pisco::Detector needs is read: name, quat, pol_leakage (or
// pol_efficiency), psi_pol, and fwhm for the caller. Columns are read one at a time by name through a
// one-member compound memory type, so the file's other columns, their order and their types do not
// matter.
#include <hdf5.h>

#include <cmath>
#include <cstring>
#include <map>
#include <numbers>
#include <optional>
#include <regex>
#include <string>
#include <vector>

#include "io/hdf5.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"

namespace pisco {

namespace {

namespace fs = std::filesystem;
using namespace detail::hdf5;

constexpr const char* table_expected =
    "a TOAST focal plane: a compound dataset 'focalplane' with one row per detector and at least the columns "
    "name and quat, as toast.instrument.Focalplane.save_hdf5 writes it";
constexpr const char* meta_name = "focalplane.__table_column_meta__";

// ---------------------------------------------------------------- astropy's YAML header

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n"), e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

std::string unquote(std::string s) {
  s = trim(s);
  if (s.size() >= 2 && (s.front() == '\'' || s.front() == '"') && s.back() == s.front()) s = s.substr(1, s.size() - 2);
  return s;
}

struct TableMeta {
  bool present = false;                     // the file has the meta dataset
  std::map<std::string, std::string> unit;  // column -> unit, for columns that have one
  double sample_rate = 0.0;                 // Hz; 0 when absent or in a unit not understood
};

// The units of the columns, from the `datatype:` list of entries such as
//   - {name: psi_pol, unit: rad, datatype: float64}
// (flow style; an entry may go on over indented lines, or be written in block style), and the
// meta's sample_rate: a Quantity whose unit may be an alias (*id003) of an anchor set elsewhere.
TableMeta parse_meta(const std::vector<std::string>& lines) {
  TableMeta meta;
  meta.present = true;
  // Anchors of units, "&id003 !astropy.units.Unit {unit: Hz}", wherever they are.
  std::map<std::string, std::string> anchors;
  const std::regex anchor_re(R"(&(\S+)\s+!astropy\.units\.Unit\s*\{\s*unit:\s*([^}]*)\})");
  for (const std::string& line : lines)
    for (auto it = std::sregex_iterator(line.begin(), line.end(), anchor_re); it != std::sregex_iterator(); ++it)
      anchors[(*it)[1]] = unquote((*it)[2]);

  // Top-level sections and, within `datatype:`, its entries ("- " at column 0 and the indented lines
  // after it).
  std::vector<std::string> entries;
  std::string section;
  for (const std::string& raw : lines) {
    const std::string line = raw.substr(0, raw.find_last_not_of(" \r\n") + 1);
    if (line.empty()) continue;
    if (line[0] != ' ' && line[0] != '-') {
      section = trim(line.substr(0, line.find(':')));
      continue;
    }
    if (section != "datatype") continue;
    if (line[0] == '-') entries.push_back(line.substr(1));
    else if (!entries.empty()) entries.back() += " " + trim(line);
  }
  const std::regex name_re(R"((?:^|[{,\s])name:\s*('[^']*'|"[^"]*"|[^,}\s]+))");
  const std::regex unit_re(R"((?:^|[{,\s])unit:\s*('[^']*'|"[^"]*"|[^,}]+))");
  for (const std::string& entry : entries) {
    std::smatch name, unit;
    if (std::regex_search(entry, name, name_re) && std::regex_search(entry, unit, unit_re))
      meta.unit[unquote(name[1])] = unquote(unit[1]);
  }

  // sample_rate: "- sample_rate: !astropy.units.Quantity" followed by more indented lines with
  // "unit: ... {unit: Hz}" (or "unit: *id003") and "value: 10.0"; or a plain number.
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& line = lines[i];
    const auto key = line.find("sample_rate:");
    if (key == std::string::npos || trim(line.substr(0, key)).find_first_not_of("- ") != std::string::npos) continue;
    const std::string rest = trim(line.substr(key + std::strlen("sample_rate:")));
    std::string text = rest;
    const std::size_t indent = line.find_first_not_of(" -");
    for (std::size_t j = i + 1; j < lines.size(); ++j) {
      const std::size_t ind = lines[j].find_first_not_of(' ');
      if (ind == std::string::npos || ind <= indent) break;
      text += "\n" + lines[j];
    }
    double value = 0.0;
    std::string unit = "Hz";
    std::smatch m;
    if (std::regex_search(text, m, std::regex(R"(value:\s*([-+0-9.eE]+))"))) value = std::strtod(m[1].str().c_str(), nullptr);
    else if (!rest.empty()) value = std::strtod(rest.c_str(), nullptr);
    if (std::regex_search(text, m, std::regex(R"(unit:\s*(?:&\S+\s+)?!astropy\.units\.Unit\s*\{\s*unit:\s*([^}]*)\})")))
      unit = unquote(m[1]);
    else if (std::regex_search(text, m, std::regex(R"(unit:\s*\*(\S+))")))
      unit = anchors.count(m[1]) ? anchors[m[1]] : std::string();
    const double scale = unit == "Hz" ? 1.0 : unit == "kHz" ? 1e3 : unit == "MHz" ? 1e6 : 0.0;
    if (std::isfinite(value) && value > 0) meta.sample_rate = value * scale;
    break;
  }
  return meta;
}

// Radians per unit of an angle column; a column without a unit is taken to be in radians.
double angle_unit(const TableMeta& meta, const std::string& column, const std::string& where) {
  const auto it = meta.unit.find(column);
  if (it == meta.unit.end()) return 1.0;
  const std::string& u = it->second;
  if (u == "rad" || u == "radian") return 1.0;
  if (u == "mrad") return 1e-3;
  if (u == "deg" || u == "degree") return std::numbers::pi / 180;
  if (u == "arcmin") return std::numbers::pi / (180 * 60);
  if (u == "arcsec") return std::numbers::pi / (180 * 3600);
  throw Error(where + ": column '" + column + "' of dataset '/focalplane' has unit '" + u +
              "' (expected an angle in rad, mrad, deg, arcmin or arcsec)");
}

// ---------------------------------------------------------------- the table

class Table {
 public:
  Table(hid_t file, const std::string& where) : where_(where) {
    dataset_ = open_dataset(file, "focalplane", "/focalplane", where, table_expected);
    if (dataset_.type_class != H5T_COMPOUND)
      throw Error(where + ": dataset '/focalplane' is not a table of named columns (expected " + table_expected + ")");
    if (dataset_.shape.size() != 1)
      throw Error(where + ": dataset '/focalplane' has " + std::to_string(dataset_.shape.size()) +
                  " dimensions (expected " + table_expected + ")");
    rows_ = static_cast<std::size_t>(dataset_.shape[0]);
    if (rows_ == 0) throw Error(where + ": dataset '/focalplane' has no rows (expected one row per detector)");
    type_ = checked(H5Dget_type(dataset_.handle.get()), H5Tclose, where, "cannot get the type of '/focalplane'");
    const int n = H5Tget_nmembers(type_.get());
    if (n < 0) fail(where, "cannot list the columns of '/focalplane'");
    for (int i = 0; i < n; ++i) {
      char* name = H5Tget_member_name(type_.get(), static_cast<unsigned>(i));
      if (name == nullptr) fail(where, "cannot get the name of a column of '/focalplane'");
      columns_[name] = static_cast<unsigned>(i);
      H5free_memory(name);
    }
  }

  std::size_t rows() const { return rows_; }
  bool has(const std::string& column) const { return columns_.count(column) != 0; }
  void require(const std::string& column) const {
    if (!has(column))
      throw Error(where_ + ": dataset '/focalplane' has no column '" + column + "' (expected " + table_expected + ")");
  }

  // A text column (fixed-length or variable-length strings).
  std::vector<std::string> strings(const std::string& column) const {
    const Handle member = member_type(column);
    if (H5Tget_class(member.get()) != H5T_STRING) throw wrong(column, "is not a string column", "a name per detector");
    const htri_t variable = H5Tis_variable_str(member.get());
    if (variable < 0) fail(where_, "cannot inspect the string type of " + what(column));
    std::vector<std::string> out(rows_);
    if (variable > 0) {
      Handle mem = checked(H5Tcopy(H5T_C_S1), H5Tclose, where_, "cannot create a string type");
      check(H5Tset_size(mem.get(), H5T_VARIABLE), where_, "cannot size a string type");
      check(H5Tset_cset(mem.get(), H5Tget_cset(member.get())), where_, "cannot set a character set");
      std::vector<char*> text(rows_, nullptr);
      read(column, mem.get(), text.data());
      for (std::size_t i = 0; i < rows_; ++i) {
        out[i] = text[i] != nullptr ? text[i] : "";
        H5free_memory(text[i]);
      }
      return out;
    }
    const std::size_t size = H5Tget_size(member.get());
    if (size == 0) fail(where_, "cannot get the size of " + what(column));
    std::vector<char> buffer(rows_ * size);
    read(column, member.get(), buffer.data());
    const bool spaces = H5Tget_strpad(member.get()) == H5T_STR_SPACEPAD;
    for (std::size_t i = 0; i < rows_; ++i) {
      std::string s(buffer.data() + i * size, size);
      s.resize(std::min(s.find('\0'), size));
      if (spaces) s.erase(s.find_last_not_of(' ') + 1);
      out[i] = s;
    }
    return out;
  }

  // A numeric column as float64.
  std::vector<double> numbers(const std::string& column) const {
    const Handle member = member_type(column);
    const H5T_class_t cls = H5Tget_class(member.get());
    if (cls != H5T_FLOAT && cls != H5T_INTEGER) throw wrong(column, "is not numeric", "one number per detector");
    std::vector<double> out(rows_);
    read(column, H5T_NATIVE_DOUBLE, out.data());
    return out;
  }

  // A column of quaternions: four numbers per row (a float64[4] sub-array in TOAST's files).
  std::vector<Quat> quats(const std::string& column) const {
    const char* expected = "4 floating-point numbers per detector: a quaternion x, y, z, w";
    const Handle member = member_type(column);
    if (H5Tget_class(member.get()) != H5T_ARRAY) throw wrong(column, "is not an array column", expected);
    const int rank = H5Tget_array_ndims(member.get());
    if (rank < 0) fail(where_, "cannot get the shape of " + what(column));
    std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
    if (rank > 0 && H5Tget_array_dims2(member.get(), dims.data()) < 0) fail(where_, "cannot get the shape of " + what(column));
    std::string shape;
    for (hsize_t d : dims) shape += (shape.empty() ? "" : ", ") + std::to_string(d);
    if (rank != 1 || dims[0] != 4) throw wrong(column, "has shape (" + shape + ") per row", expected);
    Handle base = checked(H5Tget_super(member.get()), H5Tclose, where_, "cannot get the element type of " + what(column));
    const H5T_class_t cls = H5Tget_class(base.get());
    if (cls != H5T_FLOAT && cls != H5T_INTEGER) throw wrong(column, "is not numeric", expected);
    const hsize_t four = 4;
    Handle mem = checked(H5Tarray_create2(H5T_NATIVE_DOUBLE, 1, &four), H5Tclose, where_, "cannot create an array type");
    std::vector<Quat> out(rows_);
    read(column, mem.get(), out.data());
    return out;
  }

 private:
  std::string what(const std::string& column) const { return "column '" + column + "' of '/focalplane'"; }
  Error wrong(const std::string& column, const std::string& problem, const std::string& expected) const {
    return Error(where_ + ": " + what(column) + " " + problem + " (expected " + expected + ")");
  }
  Handle member_type(const std::string& column) const {
    require(column);
    return checked(H5Tget_member_type(type_.get(), columns_.at(column)), H5Tclose, where_,
                   "cannot get the type of " + what(column));
  }
  // Reads one column: a compound memory type with the one member `column` of type `mem`.
  void read(const std::string& column, hid_t mem, void* buffer) const {
    const std::size_t size = H5Tget_size(mem);
    if (size == 0) fail(where_, "cannot get the size of a memory type");
    Handle compound = checked(H5Tcreate(H5T_COMPOUND, size), H5Tclose, where_, "cannot create a compound type");
    check(H5Tinsert(compound.get(), column.c_str(), 0, mem), where_, "cannot create a compound type");
    check(H5Dread(dataset_.handle.get(), compound.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer), where_,
          "cannot read " + what(column));
  }

  std::string where_;
  Dataset dataset_;
  Handle type_;
  std::size_t rows_ = 0;
  std::map<std::string, unsigned> columns_;
};

// The meta dataset's lines (fixed-length or variable-length strings), or nullopt without it.
std::optional<std::vector<std::string>> read_meta_lines(hid_t file, const std::string& where) {
  const std::string path = std::string("/") + meta_name;
  if (!has_link(file, meta_name, where, "dataset " + in_quotes(path))) return std::nullopt;
  const char* expected = "astropy's YAML header: one string per line";
  const Dataset ds = open_dataset(file, meta_name, path, where, expected);
  if (ds.type_class != H5T_STRING || ds.shape.size() != 1)
    throw Error(where + ": dataset " + in_quotes(path) + " is not a list of strings (expected " + expected + ")");
  Handle type = checked(H5Dget_type(ds.handle.get()), H5Tclose, where, "cannot get the type of " + in_quotes(path));
  const htri_t variable = H5Tis_variable_str(type.get());
  if (variable < 0) fail(where, "cannot inspect the string type of " + in_quotes(path));
  const std::size_t n = ds.elements();
  std::vector<std::string> lines(n);
  if (n == 0) return lines;
  if (variable > 0) {
    Handle mem = checked(H5Tcopy(H5T_C_S1), H5Tclose, where, "cannot create a string type");
    check(H5Tset_size(mem.get(), H5T_VARIABLE), where, "cannot size a string type");
    check(H5Tset_cset(mem.get(), H5Tget_cset(type.get())), where, "cannot set a character set");
    std::vector<char*> text(n, nullptr);
    check(H5Dread(ds.handle.get(), mem.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, text.data()), where,
          "cannot read " + in_quotes(path));
    for (std::size_t i = 0; i < n; ++i) {
      lines[i] = text[i] != nullptr ? text[i] : "";
      H5free_memory(text[i]);
    }
    return lines;
  }
  const std::size_t size = H5Tget_size(type.get());
  std::vector<char> buffer(n * size);
  check(H5Dread(ds.handle.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer.data()), where,
        "cannot read " + in_quotes(path));
  for (std::size_t i = 0; i < n; ++i) {
    std::string s(buffer.data() + i * size, size);
    s.resize(std::min(s.find('\0'), size));
    lines[i] = s;
  }
  return lines;
}

}  // namespace

namespace {
ToastFocalPlane read_table(const fs::path& file, std::size_t beam);
}

// The whole read first in a child process (hdf5.hpp, run_isolated): HDF5 1.10 crashes, loops or asks
// for gigabytes on some corrupt tables; a focal plane is small, so reading it twice costs nothing.
ToastFocalPlane read_toast_focal_plane(const fs::path& file, std::size_t beam) {
  Session session;
  run_isolated(file.string(), [&] { read_table(file, beam); });
  return read_table(file, beam);
}

namespace {
ToastFocalPlane read_table(const fs::path& file, std::size_t beam) {
  const std::string where = file.string();
  Session session;
  const Handle f = open_read_only(file);
  const Table table(f.get(), where);
  table.require("name");
  table.require("quat");
  const auto meta_lines = read_meta_lines(f.get(), where);
  const TableMeta meta = meta_lines ? parse_meta(*meta_lines) : TableMeta{};

  const std::vector<std::string> names = table.strings("name");
  const std::vector<Quat> quats = table.quats("quat");
  const std::size_t n = table.rows();
  auto row_text = [&](std::size_t i) {
    return where + ": dataset '/focalplane' row " + std::to_string(i) + " (detector '" + names[i] + "')";
  };

  std::vector<double> epsilon(n, 0.0);
  if (table.has("pol_leakage")) {
    epsilon = table.numbers("pol_leakage");
    for (std::size_t i = 0; i < n; ++i)
      if (!(epsilon[i] >= 0.0 && epsilon[i] <= 1.0))
        throw Error(row_text(i) + ", column 'pol_leakage': " + format_double(epsilon[i]) +
                    " (expected a cross-polar leakage from 0 to 1)");
  } else if (table.has("pol_efficiency")) {
    const std::vector<double> eta = table.numbers("pol_efficiency");
    for (std::size_t i = 0; i < n; ++i) {
      if (!(eta[i] >= 0.0 && eta[i] <= 1.0))
        throw Error(row_text(i) + ", column 'pol_efficiency': " + format_double(eta[i]) +
                    " (expected a polarization efficiency from 0 to 1)");
      epsilon[i] = (1.0 - eta[i]) / (1.0 + eta[i]);
    }
  }
  std::vector<double> zeta(n, 0.0);
  if (table.has("psi_pol")) {
    const double scale = angle_unit(meta, "psi_pol", where);
    zeta = table.numbers("psi_pol");
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isfinite(zeta[i]))
        throw Error(row_text(i) + ", column 'psi_pol': " + format_double(zeta[i]) + " (expected a finite angle)");
      zeta[i] *= scale;
    }
  }

  ToastFocalPlane out;
  out.sample_rate = meta.sample_rate;
  if (table.has("fwhm")) {
    const double scale = angle_unit(meta, "fwhm", where);
    out.fwhm = table.numbers("fwhm");
    for (double& v : out.fwhm) v *= scale;
  }
  if (table.has("gamma")) {
    const double scale = angle_unit(meta, "gamma", where);
    out.gamma = table.numbers("gamma");
    for (std::size_t i = 0; i < out.gamma.size(); ++i) {
      if (!std::isfinite(out.gamma[i]))
        throw Error(row_text(i) + ", column 'gamma': " + format_double(out.gamma[i]) + " (expected a finite angle)");
      out.gamma[i] *= scale;
    }
  }

  std::map<std::string, std::size_t> seen;
  out.detectors.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (names[i].empty()) throw Error(where + ": dataset '/focalplane' row " + std::to_string(i) + ", column 'name': empty name");
    const auto [it, inserted] = seen.emplace(names[i], i);
    if (!inserted)
      throw Error(where + ": dataset '/focalplane' rows " + std::to_string(it->second) + " and " + std::to_string(i) +
                  ", column 'name': both are detector '" + names[i] + "' (expected unique names)");
    const Quat& q = quats[i];
    if (const std::string problem = rotation_problem(q); !problem.empty())
      throw Error(row_text(i) + ", column 'quat' " + problem);
    Detector d;
    d.name = names[i];
    d.epsilon = epsilon[i];
    d.gain = 2.0 / (1.0 + epsilon[i]);
    d.zeta = zeta[i];
    d.beam = beam;
    // The antenna basis is TOAST's beam frame, quat turned back by psi_pol about the line of sight;
    // the polarization axis, at zeta from its theta', is then quat x^.
    const Quat back{0.0, 0.0, -std::sin(zeta[i] / 2), std::cos(zeta[i] / 2)};
    d.offset = q * back;
    out.detectors.push_back(std::move(d));
  }
  return out;
}
}  // namespace

}  // namespace pisco
