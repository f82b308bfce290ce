// The engine: given a sky, beamsors and detectors once, turns chunks of pointing into TOD.
// The backend ("cpu", later "vulkan", "cuda") is chosen at run time by name.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"
#include "pisco/sky.hpp"

namespace pisco {

enum class Normalization {
  integral,    // divide by Omega~ = integral of B_TT over the cap (the paper's; default)
  per_sample,  // divide each sample by its own discrete sum of Omega_pix B_TT / Omega~
};

struct EngineOptions {
  std::string backend = "cpu";  // "cpu", "vulkan", "cuda" or "auto" (the best backend compiled in and present)
  std::string device = "auto";  // vulkan/cuda: device index, or part of its name; "auto" prefers a discrete GPU
  std::size_t chunk_samples = 0;  // vulkan/cuda: samples per device chunk; 0 = fitted to the device's limits
  Normalization normalization = Normalization::integral;
  unsigned threads = 0;         // cpu backend: worker threads, 0 = all hardware threads
};

struct BackendInfo {
  std::string name;
  bool available = false;
  std::string detail;  // device found, or why the backend is unavailable
};

namespace detail { class Backend; }

class Engine {
 public:
  // Prepares the sky, the beamsors and the detectors for the chosen backend. Throws pisco::Error on
  // an unknown or unavailable backend, a detector referring to a missing beam, or a non-finite sky.
  Engine(const Sky& sky, const std::vector<Beamsor>& beams, const FocalPlane& focal_plane,
         const EngineOptions& options = {});
  ~Engine();
  Engine(Engine&&) noexcept;
  Engine& operator=(Engine&&) noexcept;

  // TOD of detector `detector` for the given pointing chunk; tod.size() must equal pointing.size().
  // Every sample of tod is written. Throws pisco::Error on a bad sample (naming its index).
  void convolve(std::size_t detector, const PointingView& pointing, std::span<double> tod);

  std::string backend_name() const;
  std::string device_name() const;
  const FocalPlane& focal_plane() const noexcept { return focal_plane_; }
  // Mean number of sky pixels per sample over all convolve() calls so far.
  double mean_disc_pixels() const noexcept;

  // Backends compiled into the library, with availability on this machine.
  static std::vector<BackendInfo> backends();

 private:
  FocalPlane focal_plane_;
  std::unique_ptr<detail::Backend> backend_;
  std::uint64_t samples_ = 0, pixels_ = 0;
};

}  // namespace pisco
