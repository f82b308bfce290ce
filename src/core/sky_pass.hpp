// One sky summed by one backend, with its own treatment of the poles (docs/physics.md, "The
// quadrature"): the samples near a HEALPix pole summed on the sky's polar copy, which the backend
// holds beside the sky (Backend::set_polar_sky), the others on the sky itself. The engine has one for
// the sky and one for split beams' outer parts on their band-limited coarse sky (docs/beams.md,
// "Sidelobes"); each gives forward, adjoint and normal passes the same treatment, and take_adjoint()
// its part of A^T d at its own NSIDE, through the transposes of the copy and of the cap-boundary
// weights.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <future>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "core/backend.hpp"
#include "core/polar_copy.hpp"
#include "core/poles.hpp"
#include "pisco/engine.hpp"
#include "pisco/sky.hpp"

namespace pisco::detail {

class SkyPass {
 public:
  // The backend made from `entry` over `summed` (the pixels as it sums them: the cap-boundary rings
  // already weighted when `weigh`) for `inputs`' detectors. With `polar`, the polar copy of `sky` (the
  // same sky unweighted) is made on a thread of its own, for detectors whose discs allow one
  // (polar_cut); the backend takes it at prepare() or when a submission first needs it.
  SkyPass(const BackendEntry& entry, std::shared_ptr<const EngineInputs> inputs, const SkyView& summed,
          const SkyView& sky, const EngineOptions& options, bool polar, bool weigh);
  ~SkyPass();
  SkyPass(const SkyPass&) = delete;
  SkyPass& operator=(const SkyPass&) = delete;

  Backend& backend() noexcept { return *backend_; }
  const Backend& backend() const noexcept { return *backend_; }
  int nside() const noexcept { return nside_; }
  // Whether samples near the poles go to a polar copy (made or still being made).
  bool polar_copy() const noexcept { return polar_ready_ || setup_ != nullptr; }
  // Completes the polar copy's set-up and hands it to the backend; rethrows the transform's error.
  void prepare();

  // One submission on this pass: its samples near the poles (found once for all the detectors it
  // queues, a plate's four rows among them) and each queued detector's values there.
  struct Work {
    std::shared_ptr<const PolarSamples> polar;  // null: none near a pole
    // The samples the adjoint scatters on the sky (sky_runs): a short run of polar samples stays in
    // its neighbours', scattering 0.
    std::vector<std::array<std::size_t, 2>> runs;
    // The forward pass's samples on the sky, where they are not `runs` (a short run of polar samples
    // between two of the sky's): gathered into one submission of their own, so that no sample is summed
    // on both skies. Null: the forward pass sums `runs`.
    struct Gathered {
      std::vector<std::size_t> index;  // ascending
      Pointing angles;
      std::vector<Quat> quats;
      std::vector<double> plate_angle;
      std::uint64_t shared = 0;  // its own key: a plate's four rows read it alike
      PointingInput input() const;
    };
    std::shared_ptr<const Gathered> sky;
    struct Part {
      std::span<double> out;
      bool accumulate = false;
      std::vector<double> values, base;  // at the polar samples: the copy's, and what out held before
      std::vector<double> sky_values;    // at the gathered samples: the sky's
    };
    std::vector<Part> parts;
    std::uint64_t ticket = 0;  // its last submission to the backend; 0: none
  };
  // Finds the samples of `input` near a pole for `detector` (its line of sight, its offset applied)
  // and the runs the sky sums; for a `forward` pass (submit()), the sky's samples gathered where
  // those runs hold polar ones. A forward pass with such samples calls prepare() before submit(); the
  // adjoint's scatter needs no copy.
  void begin(std::size_t detector, const PointingInput& input, Work& w, bool forward);
  // Queues `target`'s values over the submission's samples: the sky's runs written into out (or
  // added, with accumulate), the polar samples' (and gathered samples') into the work's own buffers,
  // which finish() writes into out. Each sample is summed once. `out` must stay valid until finish().
  void submit(Work& w, std::size_t target, const PointingInput& input, std::span<double> out, bool accumulate);
  // Completes the backend's submissions up to `ticket`; returns the sky pixels they evaluated.
  std::uint64_t wait(std::uint64_t ticket) { return backend_->wait(ticket); }
  std::uint64_t last_ticket() const noexcept { return next_ticket_ - 1; }
  // Once the work's ticket is waited for: the polar samples' values, and the gathered samples', written
  // into out.
  static void finish(Work& w);

  // Scatters `target`'s values (d, or d times a plate's coefficient) into the backend's maps: the
  // sky's runs now, the polar samples' at take_adjoint(). With `squares` (the diagonal), every sample
  // on the sky, and no polar samples (begin() was not called). Returns the pixels evaluated.
  std::uint64_t adjoint(const Work& w, std::size_t target, const PointingInput& input, std::span<const double> values,
                        bool squares);
  // The backend's one-pass normal (Backend::has_normal) for `detector`: A^T A s on the sky's samples,
  // the polar samples' forward values on the copy now and their scatter at take_adjoint().
  bool has_normal() const { return backend_->has_normal(); }
  std::uint64_t normal(const Work& w, std::size_t detector, const PointingInput& input);
  // Whether maps not yet taken are held.
  bool holds_adjoint() const noexcept { return adjoint_ || !polar_adjoints_.empty(); }
  // What adjoint() and normal() scattered since the last call, at this pass's NSIDE, through the
  // transposes of the cap-boundary weights and of the polar copy; nothing when nothing was scattered.
  // Adds the pixels the polar samples' scatter evaluates to `pixels`.
  std::optional<Sky> take_adjoint(std::uint64_t& pixels);

 private:
  void attach();
  Sky collect();

  std::shared_ptr<const EngineInputs> inputs_;
  std::unique_ptr<Backend> backend_;
  int nside_ = 0;
  bool weigh_ = false;
  std::uint64_t next_ticket_ = 1;
  // The polar copy: each detector's cut and distance from the boresight, the copy's reach, and its
  // transform running from set-up until the backend takes it.
  std::vector<double> cut_, offset_angle_;
  double reach_ = 0.0;
  struct Setup {
    std::future<SkyBand> band;
    std::exception_ptr error;  // the transform's or the backend's, once reported
  };
  std::unique_ptr<Setup> setup_;
  bool polar_ready_ = false;
  // The polar samples' scatter, replayed at take_adjoint() after the sky's maps are taken.
  struct PolarAdjoint {
    std::size_t target = 0;
    std::shared_ptr<const PolarSamples> samples;
    std::vector<double> values;
  };
  std::vector<PolarAdjoint> polar_adjoints_;
  bool adjoint_ = false;
};

}  // namespace pisco::detail
