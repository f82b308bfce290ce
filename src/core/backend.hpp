// The backend interface behind pisco::Engine. A backend receives the prepared inputs once and then
// turns pointing chunks into TOD. Backends register themselves in backend_registry().
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "kernel/frame.hpp"
#include "core/polar_copy.hpp"
#include "core/prepared.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace pisco::detail {

// An error in a submission of `detector`: the engine names the detector in its message.
struct SubmissionError : Error {
  SubmissionError(std::size_t det, const std::string& what, ErrorKind kind = ErrorKind::device)
      : Error(what, kind), detector(det) {}
  std::size_t detector;
};

// One chunk of boresight pointing as a backend receives it: angles or quaternions, validated.
struct PointingInput {
  PointingView angles;
  QuatPointingView quats;
  bool quaternions = false;
  // Aperture half-wave plates: the plate's angle from the detector's axis per sample (hwp_angle -
  // gamma); empty for detectors without one.
  std::span<const double> plate_angle;
  // The sky the samples are summed on: 0 the sky itself, 1 its polar copy (Backend::set_polar_sky), onto
  // whose equator the engine has turned them.
  int sky = 0;
  // Non-zero: these are samples [shared_first, shared_first + size()) of a pointing chunk that other
  // submissions with the same `shared` also read (Engine::submit for several detectors, a plate's four
  // rows, a beam's two nodes): a device backend whose staging buffer still holds exactly those samples
  // may use it again instead of staging and uploading them anew. The plate angles are not part of it.
  std::uint64_t shared = 0;
  std::size_t shared_first = 0;
  std::size_t size() const noexcept { return quaternions ? quats.size() : angles.size(); }
  PointingInput subspan(std::size_t offset, std::size_t count) const {
    PointingInput p = *this;
    p.shared_first += offset;
    if (quaternions) p.quats = quats.subspan(offset, count);
    else p.angles = angles.subspan(offset, count);
    if (!plate_angle.empty()) p.plate_angle = plate_angle.subspan(offset, count);
    return p;
  }
};

// A key for a newly shared pointing chunk (PointingInput::shared): unique within the process, whichever
// engine asks, never 0.
std::uint64_t next_shared_key() noexcept;

// Sample i's antenna frame for detector `det` (its offset applied, frame.hpp), from either pointing
// form, and its line of sight's theta and phi: the host backends' per-sample start.
inline SampleFrame<double> detector_frame(const PointingInput& in, std::size_t i, const PreparedDetector& det,
                                          double& theta, double& phi) {
  if (in.quaternions) {
    const Quat& q = in.quats.quats[i];
    return quat_sample({q.x, q.y, q.z, q.w}, det.offset, det.cos_zeta, det.sin_zeta, theta, phi);
  }
  return angle_sample(in.angles.theta[i], in.angles.phi[i], in.angles.psi[i], det.offset, det.cos_zeta, det.sin_zeta,
                      theta, phi);
}

// A band's table read through the sky's pixel numbers: `data` less `first` elements, so that pixel p
// of the band is element p. Formed through an integer, since it points before the table's start; the
// kernels read it only at the band's pixels (Backend::set_polar_sky).
template <class T>
const T* band_indexed(const T* data, std::size_t first) {
  return reinterpret_cast<const T*>(reinterpret_cast<std::uintptr_t>(data) - first * sizeof(T));
}

// take_adjoint's work for backends that keep the adjoint as four float64 maps (I, Q, U, V): adds them
// into the caller's (those not empty) and frees them.
inline void hand_over_adjoint(std::array<std::vector<double>, 4>& own, const std::array<std::span<double>, 4>& maps) {
  for (int c = 0; c < 4; ++c) {
    if (!maps[std::size_t(c)].empty())
      for (std::size_t p = 0; p < own[std::size_t(c)].size(); ++p) maps[std::size_t(c)][p] += own[std::size_t(c)][p];
    own[std::size_t(c)] = {};
  }
}

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  virtual std::string device() const = 0;
  // The sky's polar copy (core/polar_copy.hpp), kept beside the sky in the backend's own layout with
  // the same detectors: submissions whose pointing has sky = 1 read it. The engine gives it once the
  // copy is made and turns onto it only samples whose discs stay within the band. The adjoint needs
  // no copy: its scatter reads the pixels' positions alone, which are the sky's.
  virtual void set_polar_sky(const SkyBand& band) = 0;
  // Queues the TOD of `pointing` (tod.size() samples, validated) for `detector`, on the sky that
  // pointing.sky names: written into tod,
  // or added to it with `accumulate`. The pointing is read before submit() returns; tod must stay
  // valid until wait() has returned for `ticket` (tickets increase with every submission).
  virtual void submit(std::size_t detector, const PointingInput& pointing, std::span<double> tod, bool accumulate,
                      std::uint64_t ticket) = 0;
  // Completes every submission up to `ticket`, in order. Returns the number of sky pixels they
  // evaluated. On an error, every pending submission is abandoned and the error names the
  // detector and samples of the submission that failed.
  virtual std::uint64_t wait(std::uint64_t ticket) = 0;

  // The adjoint (docs/physics.md, "The adjoint"): adds A^T tod, the transpose of submit()'s map for
  // `detector` (the pointing as submit() takes it, tod.size() samples), into the backend's own four
  // accumulated maps (I, Q, U, V at the sky's NSIDE, RING). Completes before it returns; the caller
  // has waited for every submission first. Returns the number of sky pixels evaluated. A backend
  // without it (BackendCapabilities::adjoint false) throws ErrorKind::unavailable.
  // With `squares`, adds (d a_k)^2 instead of d a_k for each pixel k and Stokes parameter: with d = 1,
  // the diagonal of A^T A (a preconditioner's).
  virtual std::uint64_t adjoint(std::size_t detector, const PointingInput& pointing, std::span<const double> tod,
                                bool squares = false);
  // The normal pass: adds A^T A s for the backend's own sky s into the accumulated maps, for the
  // samples i of `pointing` with select[i] != 0 (the others left out): each sample's forward value
  // scattered back as adjoint() scatters it, the same bits as submit() followed by adjoint() of its
  // TOD, with each pixel's weights computed once. Only where has_normal() (elsewhere the engine
  // runs the two); returns the number of sky pixels evaluated.
  virtual bool has_normal() const { return false; }
  virtual std::uint64_t normal(std::size_t detector, const PointingInput& pointing, std::span<const double> select);
  // Adds the accumulated maps into maps[0..3] (npix each) and clears them.
  virtual void take_adjoint(const std::array<std::span<double>, 4>& maps);
  // Pointing samples staged for the device so far (Engine::staged_samples); 0 for a backend that reads
  // the caller's pointing where it lies.
  virtual std::uint64_t staged_samples() const { return 0; }
};

// A setting a backend takes (EngineOptions::settings; docs/library.md, "Engine options"): its name,
// what it takes in words, whether a number, and a check of a value of that type (null: any).
// Every backend setting's default is "auto" (text) or 0 (a number): chosen or fitted by the backend.
// Backends that take a setting of the same name take it in the same sense.
struct BackendSetting {
  const char* name;
  const char* takes;
  bool number = false;
  void (*check)(const EngineValue& value) = nullptr;
};

// The settings several backends share, in the same words: worker threads (the host backends), a
// device and the samples of a device chunk (the device backends).
BackendSetting threads_setting();
BackendSetting device_setting();
BackendSetting chunk_samples_setting();

// A setting's value against its type: text, or a number of zero or more (`takes` says what the
// text one takes). Throws pisco::Error (input) keyed `name`.
void check_value_type(const std::string& name, bool number, const std::string& takes, const EngineValue& value);

// Checks EngineOptions::settings against the backends that declare them (set_engine_option's checks):
// the engine's first step. Throws pisco::Error (input) keyed by the setting.
void check_engine_options(const EngineOptions& options);

// A backend, built into this library or not: its name, its settings, how "auto" ranks it, and, where
// built, how to find and make it.
struct BackendEntry {
  std::string name;
  // "auto" picks the available backend with the highest priority: cuda 20, vulkan on a GPU 10, simd 5,
  // vulkan on a CPU device -1 (lavapipe), the float64 reference -2. Measured (BENCHMARKS.md): on an
  // H200 (2026-11-26) cuda is 1.04 to 1.8 times NVIDIA's Vulkan up to rho_max = 20 deg with a quarter of
  // its set-up, Vulkan 1.1 times cuda at 25 to 30 deg; on two CPU cores simd is 2.6 to 2.7 times lavapipe
  // (2026-11-24, "the simd backend's weights in records").
  int priority = 0;
  // The settings it takes, declared whether it is built or not, so that a simulation file reads the
  // same on every build.
  std::vector<BackendSetting> settings{};
  // Whether it is present and what it can do; for a backend not built, unavailable and why.
  std::function<BackendInfo()> probe = nullptr;
  // Makes the backend; it packs the sky's pixels from `sky` into what it keeps, during the call only.
  std::function<std::unique_ptr<Backend>(std::shared_ptr<const EngineInputs>, const SkyView&, const EngineOptions&)>
      create = nullptr;
  // When set, replaces `priority` for "auto" once the backend is known to be available (the vulkan
  // backend ranks below simd when its only device is a CPU: docs/vulkan.md says why).
  std::function<int()> auto_priority = nullptr;

  bool takes(const std::string& setting) const {
    for (const BackendSetting& s : settings)
      if (setting == s.name) return true;
    return false;
  }
};

// Every backend, built or not, in the order "auto" breaks ties (core/engine.cpp).
const std::vector<BackendEntry>& backend_registry();

// A backend's entry is declared in its own folder (src/NAME/NAME_entry.cpp, compiled into every build;
// the cpu backend's, always built, in cpu_backend.cpp),
// which, where the backend is built (PISCO_HAVE_NAME), has the backend attach its probe and create,
// and elsewhere marks it not built.
BackendEntry cpu_backend_entry();
BackendEntry simd_backend_entry();
BackendEntry vulkan_backend_entry();
BackendEntry cuda_backend_entry();
void attach_simd_backend(BackendEntry& e);    // src/simd/, when built with Highway
void attach_vulkan_backend(BackendEntry& e);  // src/vulkan/, when built with Vulkan
void attach_cuda_backend(BackendEntry& e);    // src/cuda/, when built with CUDA
// A backend this library was built without: unavailable, saying what its build needs.
void mark_not_built(BackendEntry& e, const std::string& needs);

}  // namespace pisco::detail
