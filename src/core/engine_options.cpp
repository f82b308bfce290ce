// EngineOptions: the engine's own settings and the backends' by name, checked in one place against
// the backends that declare them (docs/library.md, "Engine options").
#include <algorithm>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "core/backend.hpp"
#include "core/names.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace pisco {

namespace {
constexpr detail::Named<Normalization> normalizations[] = {{"integral", Normalization::integral},
                                                           {"per_sample", Normalization::per_sample}};
constexpr detail::Named<Quadrature> quadratures[] = {{"corrected", Quadrature::corrected}, {"plain", Quadrature::plain}};
constexpr detail::Named<UnseenPolicy> unseen_policies[] = {
    {"error", UnseenPolicy::error}, {"zero", UnseenPolicy::zero}, {"flag", UnseenPolicy::flag}};
}  // namespace

Normalization normalization_from(const std::string& name) {
  return detail::from_name(normalizations, name, "normalization");
}
std::string normalization_name(Normalization n) { return detail::name_of(normalizations, n); }
Quadrature quadrature_from(const std::string& name) { return detail::from_name(quadratures, name, "quadrature"); }
std::string quadrature_name(Quadrature q) { return detail::name_of(quadratures, q); }
UnseenPolicy unseen_policy_from(const std::string& name) { return detail::from_name(unseen_policies, name, "unseen"); }
std::string unseen_policy_name(UnseenPolicy u) { return detail::name_of(unseen_policies, u); }

namespace detail {

BackendSetting threads_setting() {
  return {"threads", "worker threads, 0 for all hardware threads", true, [](const EngineValue& v) {
            const long long n = std::get<long long>(v);
            if (n > static_cast<long long>(Engine::max_threads()))
              throw Error("expected 0 (all hardware threads) or a number of threads up to " +
                              std::to_string(Engine::max_threads()) + " (64 per hardware thread of this machine), got " +
                              std::to_string(n),
                          ErrorKind::input, "threads");
          }};
}
BackendSetting device_setting() { return {"device", "\"auto\", a device's index or part of its name"}; }
BackendSetting chunk_samples_setting() {
  return {"chunk_samples", "samples per device chunk, 0 to fit the device", true};
}

void check_value_type(const std::string& name, bool number, const std::string& takes, const EngineValue& value) {
  const std::string* t = std::get_if<std::string>(&value);
  const long long* n = std::get_if<long long>(&value);
  if (number && !n) throw Error("expected a number, got \"" + *t + "\"", ErrorKind::input, name);
  if (!number && !t) throw Error("expected " + takes + ", got the number " + std::to_string(*n), ErrorKind::input, name);
  if (n && *n < 0) throw Error("expected a number of zero or more, got " + std::to_string(*n), ErrorKind::input, name);
}

void mark_not_built(BackendEntry& e, const std::string& needs) {
  e.probe = [name = e.name, needs] {
    return BackendInfo{name, false, "not built into this library (its build needs " + needs + ")", {}, {}};
  };
  e.create = nullptr;
}

namespace {

bool is_default(const EngineValue& v) {
  if (const std::string* t = std::get_if<std::string>(&v)) return t->empty() || *t == "auto";
  return std::get<long long>(v) == 0;
}

// The backends' settings, each once: its declarations in registry order, the backends that take it,
// and what it takes (one text where they agree, else each with its backends).
struct Declared {
  std::string name;
  std::vector<std::pair<const BackendEntry*, BackendSetting>> by;
  std::string backends, takes;
  bool number = false;
};

const std::vector<Declared>& declared() {
  static const std::vector<Declared> all = [] {
    std::vector<Declared> out;
    for (const BackendEntry& e : backend_registry())
      for (const BackendSetting& s : e.settings) {
        auto it = std::find_if(out.begin(), out.end(), [&](const Declared& d) { return d.name == s.name; });
        if (it == out.end()) it = out.insert(out.end(), Declared{s.name, {}, {}, {}, s.number});
        it->by.emplace_back(&e, s);
      }
    for (Declared& d : out) {
      std::vector<std::string> names;
      std::vector<std::pair<std::string, std::vector<std::string>>> takes;  // each text, with its backends
      for (const auto& by : d.by) {
        const std::string name = by.first->name, text = by.second.takes;
        names.push_back(name);
        auto t = std::find_if(takes.begin(), takes.end(), [&](const auto& p) { return p.first == text; });
        if (t == takes.end()) t = takes.insert(takes.end(), {text, {}});
        t->second.push_back(name);
      }
      d.backends = series_text(names, "and");
      if (takes.size() == 1) d.takes = takes[0].first;
      else
        for (const auto& [text, by] : takes) d.takes += (d.takes.empty() ? "" : "; ") + text + " (" + series_text(by, "and") + ")";
    }
    return out;
  }();
  return all;
}

const Declared* find_declared(const std::string& name) {
  for (const Declared& d : declared())
    if (d.name == name) return &d;
  return nullptr;
}

// The engine's own settings, and how each is set.
struct Own {
  const char* name;
  std::string takes;
  void (*set)(EngineOptions& o, const std::string& text);
};

// "cpu", "simd", ... or "auto" (the fastest present): the registry's names.
std::string backend_takes() {
  std::vector<std::string> quoted;
  for (const BackendEntry& e : backend_registry()) quoted.push_back("\"" + e.name + "\"");
  quoted.push_back("\"auto\"");
  return series_text(quoted, "or") + " (the fastest present)";
}

const std::vector<Own>& own_settings() {
  static const std::vector<Own> table{
      {"backend", backend_takes(), [](EngineOptions& o, const std::string& t) { o.backend = t; }},
      {"normalization", listed(normalizations),
       [](EngineOptions& o, const std::string& t) { o.normalization = normalization_from(t); }},
      {"unseen", listed(unseen_policies), [](EngineOptions& o, const std::string& t) { o.unseen = unseen_policy_from(t); }},
      {"quadrature", listed(quadratures), [](EngineOptions& o, const std::string& t) { o.quadrature = quadrature_from(t); }},
  };
  return table;
}

// Checks the backend setting `d` with `value` against the backend `backend`: its type; under a named
// backend that takes it, that backend's check; else (under "auto", a name the engine rejects itself,
// or a backend without the setting) every taker's check, and for a backend without it, that the
// value is the default.
void check_setting(const std::string& backend, const Declared& d, const EngineValue& value) {
  check_value_type(d.name, d.number, d.takes, value);
  const auto taker = std::find_if(d.by.begin(), d.by.end(), [&](const auto& b) { return b.first->name == backend; });
  if (taker != d.by.end()) {
    if (taker->second.check) taker->second.check(value);
    return;
  }
  // Under "auto", or a backend without the setting: a value well formed for every backend that takes it.
  for (const auto& [e, s] : d.by)
    if (s.check) s.check(value);
  bool known = false;
  for (const BackendEntry& e : backend_registry()) known = known || e.name == backend;
  if (known && !is_default(value))
    throw Error("the " + backend + " backend has no " + d.name + " setting (it applies to " + d.backends + ")",
                ErrorKind::input, d.name);
}

[[noreturn]] void unknown_setting(const std::string& name) {
  std::string all;
  for (const EngineSetting& s : engine_settings()) all += std::string(all.empty() ? "" : ", ") + s.name;
  throw Error("not a setting of the engine (expected one of " + all + ")", ErrorKind::input, name);
}

}  // namespace

void check_engine_options(const EngineOptions& options) {
  for (const auto& [name, value] : options.settings) {
    const Declared* d = find_declared(name);
    if (!d) unknown_setting(name);
    check_setting(options.backend, *d, value);
  }
}

}  // namespace detail

std::span<const EngineSetting> engine_settings() {
  static const std::vector<EngineSetting> view = [] {
    std::vector<EngineSetting> v;
    const auto& own = detail::own_settings();
    v.push_back({own[0].name, own[0].takes.c_str(), "all", false});
    for (const detail::Declared& d : detail::declared())
      v.push_back({d.name.c_str(), d.takes.c_str(), d.backends.c_str(), d.number});
    for (std::size_t i = 1; i < own.size(); ++i) v.push_back({own[i].name, own[i].takes.c_str(), "all", false});
    return v;
  }();
  return view;
}

void set_engine_option(EngineOptions& options, const std::string& name, const EngineValue& value) {
  for (const detail::Own& own : detail::own_settings()) {
    if (name != own.name) continue;
    const std::string* text = std::get_if<std::string>(&value);
    if (!text)
      throw Error("expected " + own.takes + ", got the number " + std::to_string(std::get<long long>(value)),
                  ErrorKind::input, name);
    EngineOptions changed = options;
    own.set(changed, *text);
    detail::check_engine_options(changed);  // the settings already given, against a new backend
    options = std::move(changed);
    return;
  }
  const detail::Declared* d = detail::find_declared(name);
  if (!d) detail::unknown_setting(name);
  detail::check_setting(options.backend, *d, value);
  const std::string* text = std::get_if<std::string>(&value);
  options.settings[name] = text && text->empty() ? EngineValue(std::string("auto")) : value;
}

EngineOptions& EngineOptions::set(const std::string& name, const EngineValue& value) {
  set_engine_option(*this, name, value);
  return *this;
}

std::string EngineOptions::text(const std::string& name) const {
  const auto it = settings.find(name);
  if (it == settings.end()) return "auto";
  detail::check_value_type(name, false, "text", it->second);
  const std::string& t = std::get<std::string>(it->second);
  return t.empty() ? "auto" : t;
}

std::size_t EngineOptions::number(const std::string& name) const {
  const auto it = settings.find(name);
  if (it == settings.end()) return 0;
  detail::check_value_type(name, true, "", it->second);
  return static_cast<std::size_t>(std::get<long long>(it->second));
}

EngineOptions options_for_backend(const EngineOptions& options, const std::string& backend) {
  EngineOptions o = options;
  const bool another = options.backend != "auto" && options.backend != backend;
  o.backend = backend;
  std::erase_if(o.settings, [&](const auto& setting) {
    return !backend_has_setting(backend, setting.first) || (another && setting.first == "device");
  });
  return o;
}

bool backend_has_setting(const std::string& backend, const std::string& name) {
  for (const detail::BackendEntry& e : detail::backend_registry())
    if (e.name == backend) return e.takes(name);
  return false;
}

}  // namespace pisco
