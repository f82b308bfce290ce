// The text of the CSV tables users write (focal planes, source tracks; docs/formats.md): their lines,
// fields and numbers, read alike by every CSV reader. Internal.
#pragma once

#include <cmath>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace pisco::detail {

// Whether `line` (number `lineno` from 1) holds data: not blank and not a '#' comment. A spreadsheet's
// UTF-8 byte-order mark before the first line is removed.
inline bool csv_content_line(std::string& line, std::size_t lineno) {
  if (lineno == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);
  const auto first = line.find_first_not_of(" \t\r");
  return first != std::string::npos && line[first] != '#';
}

// The comma-separated fields of a line, blanks and a CR trimmed (a trailing comma ends the line
// without a field after it).
inline std::vector<std::string> csv_fields(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string x;
  while (std::getline(ss, x, ',')) {
    const auto b = x.find_first_not_of(" \t\r"), e = x.find_last_not_of(" \t\r");
    out.push_back(b == std::string::npos ? "" : x.substr(b, e - b + 1));
  }
  return out;
}

// A field that is a finite number, all of it; nullopt otherwise.
inline std::optional<double> csv_number(const std::string& field) {
  try {
    std::size_t used = 0;
    const double v = std::stod(field, &used);
    if (used == field.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

}  // namespace pisco::detail
