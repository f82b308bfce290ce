// EngineOptions: each backend's own settings, and the one-name settings of simulation files, the
// command line and Python routed to the backends they apply to (docs/library.md, "Engine options").
#include <string>

#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace pisco {

Arithmetic arithmetic_from(const std::string& name) {
  if (name == "auto") return Arithmetic::automatic;
  if (name == "float64") return Arithmetic::float64;
  if (name == "float-float") return Arithmetic::float_float;
  throw Error("arithmetic: expected \"auto\", \"float64\" or \"float-float\", got \"" + name + "\"");
}

std::string arithmetic_name(Arithmetic a) {
  switch (a) {
    case Arithmetic::float64: return "float64";
    case Arithmetic::float_float: return "float-float";
    case Arithmetic::automatic: break;
  }
  return "auto";
}

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
  throw Error("the " + backend + " backend has no " + setting + " setting (it applies to " + list + ")");
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
