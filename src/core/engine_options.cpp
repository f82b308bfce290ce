// EngineOptions: each backend's own settings, and the one-name settings of simulation files, the
// command line and Python routed to the backends they apply to (docs/library.md, "Engine options").
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace pisco {

namespace {

// The names of a setting's values.
template <class E>
struct Named {
  const char* name;
  E value;
};
constexpr Named<Arithmetic> arithmetics[] = {
    {"auto", Arithmetic::automatic}, {"float64", Arithmetic::float64}, {"float-float", Arithmetic::float_float}};
constexpr Named<Normalization> normalizations[] = {{"integral", Normalization::integral},
                                                   {"per_sample", Normalization::per_sample}};
constexpr Named<Quadrature> quadratures[] = {{"corrected", Quadrature::corrected}, {"plain", Quadrature::plain}};
constexpr Named<UnseenPolicy> unseen_policies[] = {
    {"error", UnseenPolicy::error}, {"zero", UnseenPolicy::zero}, {"flag", UnseenPolicy::flag}};

// "a", "b" or "c", quoted.
template <class E, std::size_t N>
std::string listed(const Named<E> (&names)[N]) {
  std::string out;
  for (std::size_t i = 0; i < N; ++i)
    out += (i == 0 ? "" : i + 1 == N ? " or " : ", ") + std::string("\"") + names[i].name + "\"";
  return out;
}

template <class E, std::size_t N>
E from_name(const Named<E> (&names)[N], const std::string& name, const char* key) {
  for (const Named<E>& n : names)
    if (name == n.name) return n.value;
  throw Error("expected " + listed(names) + ", got \"" + name + "\"", ErrorKind::input, key);
}

template <class E, std::size_t N>
std::string name_of(const Named<E> (&names)[N], E value) {
  for (const Named<E>& n : names)
    if (n.value == value) return n.name;
  return names[0].name;
}

}  // namespace

Arithmetic arithmetic_from(const std::string& name) { return from_name(arithmetics, name, "arithmetic"); }
std::string arithmetic_name(Arithmetic a) { return name_of(arithmetics, a); }
Normalization normalization_from(const std::string& name) { return from_name(normalizations, name, "normalization"); }
std::string normalization_name(Normalization n) { return name_of(normalizations, n); }
Quadrature quadrature_from(const std::string& name) { return from_name(quadratures, name, "quadrature"); }
std::string quadrature_name(Quadrature q) { return name_of(quadratures, q); }
UnseenPolicy unseen_policy_from(const std::string& name) { return from_name(unseen_policies, name, "unseen"); }
std::string unseen_policy_name(UnseenPolicy u) { return name_of(unseen_policies, u); }

namespace {
// Whether a setting that the backends `takers` have applies under `backend` ("auto", or a name none
// of them is: the engine names an unknown backend itself); a value other than the default for a
// backend that has no such setting is an error.
bool applies(const std::string& backend, std::initializer_list<const char*> takers, const char* setting,
             bool is_default) {
  bool known = backend == "auto";
  for (const char* b : {"cpu", "simd", "vulkan", "cuda"}) known = known || backend == b;
  if (!known || backend == "auto") return true;
  for (const char* t : takers)
    if (backend == t) return true;
  if (is_default) return false;
  std::string list;  // "simd, vulkan and cuda"
  std::size_t i = 0;
  for (const char* t : takers) {
    list += t;
    if (++i + 1 < takers.size()) list += ", ";
    else if (i + 1 == takers.size()) list += " and ";
  }
  throw Error("the " + backend + " backend has no " + setting + " setting (it applies to " + list + ")",
              ErrorKind::input, setting);
}
}  // namespace

void EngineOptions::set_device(const std::string& device) {
  if (!applies(backend, {"simd", "vulkan", "cuda"}, "device", device.empty() || device == "auto")) return;
  // Under "auto" (or a name the engine will reject) every backend with a device gets it; else the named one.
  const std::string value = device.empty() ? "auto" : device;
  for (std::string* d : {&simd.instruction_set, &vulkan.device, &cuda.device})
    if (std::string* own = device_of(backend); !own || own == d) *d = value;
}

void EngineOptions::set_threads(unsigned threads) {
  if (!applies(backend, {"cpu", "simd"}, "threads", threads == 0)) return;
  cpu.threads = simd.threads = threads;
}

void EngineOptions::set_chunk_samples(std::size_t samples) {
  if (!applies(backend, {"vulkan", "cuda"}, "chunk_samples", samples == 0)) return;
  vulkan.chunk_samples = cuda.chunk_samples = samples;
}

void EngineOptions::set_arithmetic(Arithmetic arithmetic) {
  if (!applies(backend, {"vulkan"}, "arithmetic", arithmetic == Arithmetic::automatic)) return;
  vulkan.arithmetic = arithmetic;
}

unsigned* EngineOptions::threads_of(const std::string& name) {
  if (name == "cpu") return &cpu.threads;
  if (name == "simd") return &simd.threads;
  return nullptr;
}

std::string* EngineOptions::device_of(const std::string& name) {
  if (name == "simd") return &simd.instruction_set;
  if (name == "vulkan") return &vulkan.device;
  if (name == "cuda") return &cuda.device;
  return nullptr;
}

namespace {

// Each setting once: its name, the backends it applies to, whether it takes a number, what it takes
// (for the enums, their names' own list), and how it is set. engine_settings() is this table.
struct Setting {
  const char* name;
  const char* backends;
  bool number;
  std::string takes;
  void (*set)(EngineOptions& o, const std::string& text, long long number);
};

const std::vector<Setting>& setting_table() {
  static const std::vector<Setting> table{
      {"backend", "all", false, "\"cpu\", \"simd\", \"vulkan\", \"cuda\" or \"auto\" (the fastest present)",
       [](EngineOptions& o, const std::string& t, long long) { o.backend = t; }},
      {"device", "simd, vulkan and cuda", false, "\"auto\", a device's index or part of its name; for simd, an instruction set",
       [](EngineOptions& o, const std::string& t, long long) { o.set_device(t); }},
      {"threads", "cpu and simd", true, "worker threads, 0 for all hardware threads",
       [](EngineOptions& o, const std::string&, long long n) { o.set_threads(static_cast<unsigned>(n)); }},
      {"chunk_samples", "vulkan and cuda", true, "samples per device chunk, 0 to fit the device",
       [](EngineOptions& o, const std::string&, long long n) { o.set_chunk_samples(static_cast<std::size_t>(n)); }},
      {"arithmetic", "vulkan", false, listed(arithmetics),
       [](EngineOptions& o, const std::string& t, long long) { o.set_arithmetic(arithmetic_from(t)); }},
      {"normalization", "all", false, listed(normalizations),
       [](EngineOptions& o, const std::string& t, long long) { o.normalization = normalization_from(t); }},
      {"unseen", "all", false, listed(unseen_policies),
       [](EngineOptions& o, const std::string& t, long long) { o.unseen = unseen_policy_from(t); }},
      {"quadrature", "all", false, listed(quadratures),
       [](EngineOptions& o, const std::string& t, long long) { o.quadrature = quadrature_from(t); }},
  };
  return table;
}

}  // namespace

std::span<const EngineSetting> engine_settings() {
  static const std::vector<EngineSetting> view = [] {
    std::vector<EngineSetting> v;
    for (const Setting& s : setting_table()) v.push_back({s.name, s.takes.c_str(), s.backends, s.number});
    return v;
  }();
  return view;
}

void set_engine_option(EngineOptions& options, const std::string& name, const EngineValue& value) {
  const Setting* setting = nullptr;
  for (const Setting& s : setting_table())
    if (name == s.name) setting = &s;
  if (!setting) {
    std::string all;
    for (const Setting& s : setting_table()) all += std::string(all.empty() ? "" : ", ") + s.name;
    throw Error("not a setting of the engine (expected one of " + all + ")", ErrorKind::input, name);
  }
  const std::string* text = std::get_if<std::string>(&value);
  const long long* number = std::get_if<long long>(&value);
  if (setting->number && !number) throw Error("expected a number, got \"" + *text + "\"", ErrorKind::input, name);
  if (!setting->number && !text)
    throw Error("expected " + setting->takes + ", got the number " + std::to_string(*number), ErrorKind::input, name);
  if (number && *number < 0)
    throw Error("expected a number of zero or more, got " + std::to_string(*number), ErrorKind::input, name);
  if (name == "threads" && *number > static_cast<long long>(Engine::max_threads()))
    throw Error("expected 0 (all hardware threads) or a number of threads up to " + std::to_string(Engine::max_threads()) +
                    " (64 per hardware thread of this machine), got " + std::to_string(*number),
                ErrorKind::input, name);
  setting->set(options, text ? *text : std::string(), number ? *number : 0);
}

}  // namespace pisco
