#include "pisco/engine.hpp"

#include <algorithm>

#include "core/backend.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace detail {

const std::vector<BackendEntry>& backend_registry() {
  static const std::vector<BackendEntry> registry = [] {
    std::vector<BackendEntry> r;
    r.push_back(cpu_backend_entry());
#ifdef PISCO_HAVE_VULKAN
    r.push_back(vulkan_backend_entry());
#endif
#ifdef PISCO_HAVE_CUDA
    r.push_back(cuda_backend_entry());
#endif
    return r;
  }();
  return registry;
}

namespace {
const BackendEntry& choose_backend(const std::string& name) {
  const auto& reg = backend_registry();
  if (name == "auto") {
    const BackendEntry* best = nullptr;
    int best_priority = 0;
    for (const auto& e : reg) {
      if (!e.probe().available) continue;
      const int priority = e.auto_priority ? e.auto_priority() : e.priority;
      if (!best || priority > best_priority) {
        best = &e;
        best_priority = priority;
      }
    }
    if (!best) throw Error("backend 'auto': no backend is available on this machine");
    return *best;
  }
  std::string known;
  for (const auto& e : reg) {
    if (e.name == name) {
      const BackendInfo info = e.probe();
      if (!info.available) throw Error("backend '" + name + "' is not available: " + info.detail);
      return e;
    }
    known += (known.empty() ? "" : ", ") + e.name;
  }
  throw Error("backend '" + name + "' is unknown; expected one of: auto, " + known);
}
}  // namespace
}  // namespace detail

Engine::Engine(const Sky& sky, const std::vector<Beamsor>& beams, const FocalPlane& focal_plane,
               const EngineOptions& options)
    : focal_plane_(focal_plane) {
  const detail::BackendEntry& entry = detail::choose_backend(options.backend);
  auto inputs = std::make_shared<const detail::EngineInputs>(
      detail::prepare_inputs(sky, beams, focal_plane, options.normalization));
  backend_ = entry.create(std::move(inputs), sky, options);
}

Engine::~Engine() = default;
Engine::Engine(Engine&&) noexcept = default;
Engine& Engine::operator=(Engine&&) noexcept = default;

namespace {
detail::PointingInput input_of(const PointingView& v) { return {v, {}, false}; }
detail::PointingInput input_of(const QuatPointingView& v) { return {{}, v, true}; }
}  // namespace

template <class View>
std::uint64_t Engine::submit_view(std::size_t detector, const View& boresight, std::span<double> tod,
                                  bool accumulate) {
  if (detector >= focal_plane_.size())
    throw Error("convolve: detector index " + std::to_string(detector) + " but the focal plane has " +
                std::to_string(focal_plane_.size()) + " detectors");
  const std::string& name = focal_plane_[detector].name;
  if (tod.size() != boresight.size())
    throw Error("convolve: the TOD buffer of detector '" + name + "' has " + std::to_string(tod.size()) +
                " samples but the pointing has " + std::to_string(boresight.size()));
  check_pointing(boresight, ("pointing of detector '" + name + "'").c_str());
  const std::uint64_t ticket = next_ticket_++;
  try {
    backend_->submit(detector, input_of(boresight), tod, accumulate, ticket);
  } catch (const detail::SubmissionError& e) {
    throw Error("convolving detector '" + focal_plane_[e.detector].name + "': " + e.what());
  } catch (const Error& e) {
    throw Error("convolving detector '" + name + "': " + e.what());
  }
  samples_ += boresight.size();
  return ticket;
}

std::uint64_t Engine::submit(std::size_t detector, const PointingView& boresight, std::span<double> tod,
                             bool accumulate) {
  return submit_view(detector, boresight, tod, accumulate);
}

std::uint64_t Engine::submit(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                             bool accumulate) {
  return submit_view(detector, boresight, tod, accumulate);
}

void Engine::wait(std::uint64_t ticket) {
  try {
    pixels_ += backend_->wait(ticket);
  } catch (const detail::SubmissionError& e) {
    throw Error("convolving detector '" + focal_plane_[e.detector].name + "': " + e.what());
  }
}

void Engine::wait() { wait(next_ticket_ - 1); }

void Engine::convolve(std::size_t detector, const PointingView& boresight, std::span<double> tod, bool accumulate) {
  wait(submit(detector, boresight, tod, accumulate));
}

void Engine::convolve(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                      bool accumulate) {
  wait(submit(detector, boresight, tod, accumulate));
}

std::string Engine::backend_name() const { return backend_->name(); }
std::string Engine::device_name() const { return backend_->device(); }
double Engine::mean_disc_pixels() const noexcept {
  return samples_ ? double(pixels_) / double(samples_) : 0.0;
}

std::vector<BackendInfo> Engine::backends() {
  std::vector<BackendInfo> out;
  for (const auto& e : detail::backend_registry()) out.push_back(e.probe());
  return out;
}

}  // namespace pisco
