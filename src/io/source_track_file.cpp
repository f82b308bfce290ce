// Source track files (pisco/sources.hpp; docs/formats.md, "Source tracks"): a CSV table of a point
// source's direction and flux at a sequence of times.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "io/csv_text.hpp"
#include "io/input_file.hpp"
#include "pisco/error.hpp"
#include "pisco/output_file.hpp"
#include "pisco/sources.hpp"
#include "pisco/units.hpp"

namespace pisco {
namespace {

constexpr std::array<const char*, 7> columns = {"time_s", "theta_deg", "phi_deg", "I", "Q", "U", "V"};

}  // namespace

SourceTrack SourceTrack::read_csv(const std::filesystem::path& file, std::string name) {
  const std::string expected = "a source track: CSV with columns time_s, theta_deg, phi_deg, I[, Q, U, V]";
  detail::require_regular_file(file, expected);
  std::ifstream in(file, std::ios::binary);
  if (!in) throw Error(file.string() + ": cannot open the source track file", ErrorKind::io);
  SourceTrack t;
  t.name = std::move(name);
  std::vector<std::vector<double>*> fields = {&t.time, &t.theta, &t.phi, &t.I, &t.Q, &t.U, &t.V};  // as columns
  std::vector<std::size_t> order;  // per column of the file, its index in `columns`
  std::string line;
  std::size_t lineno = 0;
  while (std::getline(in, line)) {
    if (!detail::csv_content_line(line, ++lineno)) continue;
    const std::string where = file.string() + ":" + std::to_string(lineno) + ": ";
    std::vector<std::string> f = detail::csv_fields(line);
    if (!line.empty() && line.back() == ',') f.emplace_back();  // a trailing comma: one more (empty) field
    if (order.empty()) {
      std::vector<std::string> seen;
      for (const std::string& h : f) {
        const auto it = std::find_if(columns.begin(), columns.end(), [&](const char* c) { return h == c; });
        if (it == columns.end())
          throw Error(where + "unknown column '" + h + "'; expected time_s, theta_deg, phi_deg, I, Q, U, V");
        if (std::find(seen.begin(), seen.end(), h) != seen.end()) throw Error(where + "column '" + h + "' appears twice");
        seen.push_back(h);
        order.push_back(static_cast<std::size_t>(it - columns.begin()));
      }
      for (const char* required : {"time_s", "theta_deg", "phi_deg", "I"})
        if (std::find(seen.begin(), seen.end(), required) == seen.end())
          throw Error(where + "the header needs a '" + std::string(required) +
                      "' column (the columns: time_s, theta_deg, phi_deg, I, and optionally Q, U, V)");
      continue;
    }
    if (f.size() != order.size())
      throw Error(where + "expected " + std::to_string(order.size()) + " fields, got " + std::to_string(f.size()));
    for (std::size_t i = 0; i < f.size(); ++i) {
      const std::optional<double> number = detail::csv_number(f[i]);
      if (!number) throw Error(where + "column '" + columns[order[i]] + "': expected a finite number, got '" + f[i] + "'");
      const double v = *number;
      if (columns[order[i]] == std::string("theta_deg") && !(v >= 0.0 && v <= 180.0))
        throw Error(where + "column 'theta_deg': " + f[i] + " is outside [0, 180] (the colatitude)");
      if (order[i] == 0 && !t.time.empty() && !(v > t.time.back()))
        throw Error(where + "column 'time_s': " + f[i] + " does not follow the previous row's time; times must increase strictly");
      fields[order[i]]->push_back(v);
    }
  }
  if (order.empty()) throw Error(file.string() + ": no header; expected " + expected);
  if (t.time.empty()) throw Error(file.string() + ": no rows after the header; expected one row per time");
  for (double& x : t.theta) x *= deg;
  for (double& x : t.phi) x *= deg;
  t.check(file.string());
  return t;
}

void SourceTrack::write_csv(const std::filesystem::path& file) const {
  check(file.string());
  std::string out = "# PISCO-VK source track '" + name + "' (docs/formats.md, \"Source tracks\")\n";
  out += "time_s,theta_deg,phi_deg,I,Q,U,V\n";
  const auto at = [](const std::vector<double>& v, std::size_t k) { return v.empty() ? 0.0 : v[k]; };
  char row[256];
  for (std::size_t k = 0; k < time.size(); ++k) {
    std::snprintf(row, sizeof row, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", time[k], theta[k] / deg,
                  phi[k] / deg, I[k], at(Q, k), at(U, k), at(V, k));
    out += row;
  }
  write_file_atomically(file, out);
}

}  // namespace pisco
