// Simulation files and TOML focal planes (docs/config.md): a TOML table read key by key, with the file and
// table in every error, unknown keys rejected (with the nearest known key suggested). Internal: shared
// by the simulation-file reader (src/pipeline/simulation_config.cpp) and the focal-plane reader
// (src/io/focal_plane_file.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>
#include <string>
#include <vector>

#include <toml++/toml.h>

#include "pisco/error.hpp"
#include "io/input_file.hpp"
#include "pisco/healpix_map.hpp"
#include "pisco/beamsor.hpp"

namespace pisco::detail {

namespace fs = std::filesystem;


// Levenshtein distance: insertions, deletions and substitutions, one each.
inline std::size_t edit_distance(const std::string& a, const std::string& b) {
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
inline bool resembles(const std::string& unknown, const std::string& known) {
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
  // A library check's error (pisco::Error) for this table: under its key when the error carries the
  // name of a field this table reads through a key of its own (`keys`: field, key), else as an error
  // of the table, its field named (`context`: what the library calls the table's object).
  [[noreturn]] void fail_checked(const pisco::Error& e, std::initializer_list<std::pair<std::string_view, std::string>> keys,
                                 const std::string& context) const {
    for (const auto& [field, key] : keys)
      if (!e.key().empty() && e.key() == field) fail(key, e.what());
    fail_table(e.named(context));
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
  std::vector<std::string> strings(const std::string& key, std::vector<std::string> fallback) {
    used_.insert(key);
    const toml::node* n = t_.get(key);
    if (!n) return fallback;
    const toml::array* a = n->as_array();
    if (!a || a->empty()) fail(key, "expected a non-empty array of strings");
    std::vector<std::string> out;
    for (const auto& e : *a) {
      auto v = e.value<std::string>();
      if (!v) fail(key + "[" + std::to_string(out.size()) + "]", "expected a string");
      out.push_back(*v);
    }
    return out;
  }
  // A number or a non-empty array of numbers (a number read as an array of one); none when absent.
  std::optional<std::vector<double>> numbers_or_number(const std::string& key) {
    const toml::node* n = t_.get(key);
    if (n && n->is_array()) return numbers(key, {});
    const std::optional<double> v = number(key);
    if (!v) return std::nullopt;
    return std::vector<double>{*v};
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

inline toml::table parse(const fs::path& file, std::string* text) {
  pisco::detail::require_regular_file(file, "a TOML file");
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

}  // namespace pisco::detail
