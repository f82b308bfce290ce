// EngineOptions: each backend's own settings, and the one-name settings of simulation files, the
// command line and Python routed to the backends they apply to (docs/library.md, "Engine options").
#include <span>
#include <string>
#include <variant>

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

}  // namespace pisco

namespace pisco {
namespace {

constexpr EngineSetting settings[] = {
    {"backend", "\"cpu\", \"simd\", \"vulkan\", \"cuda\" or \"auto\" (the fastest present)", "all", false},
    {"device", "\"auto\", a device's index or part of its name; for simd, an instruction set", "simd, vulkan and cuda",
     false},
    {"threads", "worker threads, 0 for all hardware threads", "cpu and simd", true},
    {"chunk_samples", "samples per device chunk, 0 to fit the device", "vulkan and cuda", true},
    {"arithmetic", "\"auto\", \"float64\" or \"float-float\"", "vulkan", false},
    {"normalization", "\"integral\" or \"per_sample\"", "all", false},
    {"unseen", "\"error\", \"zero\" or \"flag\"", "all", false},
    {"quadrature", "\"corrected\" or \"plain\"", "all", false},
};

}  // namespace

std::span<const EngineSetting> engine_settings() { return settings; }

void set_engine_option(EngineOptions& options, const std::string& name, const EngineValue& value) {
  const EngineSetting* setting = nullptr;
  for (const EngineSetting& s : settings)
    if (name == s.name) setting = &s;
  if (!setting) {
    std::string all;
    for (const EngineSetting& s : settings) all += std::string(all.empty() ? "" : ", ") + s.name;
    throw Error("not a setting of the engine (expected one of " + all + ")", ErrorKind::input, name);
  }
  const std::string* text = std::get_if<std::string>(&value);
  const long long* number = std::get_if<long long>(&value);
  if (setting->number && !number) throw Error("expected a number, got \"" + *text + "\"", ErrorKind::input, name);
  if (!setting->number && !text)
    throw Error("expected " + std::string(setting->takes) + ", got the number " + std::to_string(*number),
                ErrorKind::input, name);
  if (number && *number < 0)
    throw Error("expected a number of zero or more, got " + std::to_string(*number), ErrorKind::input, name);
  if (name == "threads" && *number > static_cast<long long>(Engine::max_threads()))
    throw Error("expected 0 (all hardware threads) or a number of threads up to " + std::to_string(Engine::max_threads()) +
                    " (64 per hardware thread of this machine), got " + std::to_string(*number),
                ErrorKind::input, name);
  if (name == "backend") options.backend = *text;
  else if (name == "device") options.set_device(*text);
  else if (name == "threads") options.set_threads(static_cast<unsigned>(*number));
  else if (name == "chunk_samples") options.set_chunk_samples(static_cast<std::size_t>(*number));
  else if (name == "arithmetic") options.set_arithmetic(arithmetic_from(*text));
  else if (name == "normalization") options.normalization = normalization_from(*text);
  else if (name == "unseen") options.unseen = unseen_policy_from(*text);
  else options.quadrature = quadrature_from(*text);
}

}  // namespace pisco
