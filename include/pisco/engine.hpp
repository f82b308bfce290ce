// The engine: given a sky, beamsors and detectors once, turns chunks of pointing into TOD.
// The backend ("cpu", "simd", "vulkan", "cuda") is chosen at run time by name.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"
#include "pisco/sky.hpp"
#include "pisco/sources.hpp"

namespace pisco {

enum class Normalization {
  integral,    // divide by Omega~ = integral of B_TT over the cap (the paper's; default)
  per_sample,  // divide each sample by its own discrete sum of Omega_pix B_TT / Omega~
};

// The sum over pixels (docs/physics.md, "The quadrature"):
enum class Quadrature {
  // corrected where the equal-weight sum is not exact (the default): samples whose disc reaches near
  // a HEALPix pole summed on a copy of the sky turned by 90 deg, where they lie on its equator, and
  // the rings where the polar caps meet the belt weighted by 1 - 1/(12 NSIDE)
  corrected,
  plain,  // the equal-weight pixel sum everywhere (the paper's)
};

// The names of the engine-wide settings, both ways: "integral", "per_sample"; "corrected", "plain";
// "error", "zero", "flag". The *_from functions throw pisco::Error (ErrorKind::input, key "normalization",
// "quadrature" or "unseen") naming the names for any other.
Normalization normalization_from(const std::string& name);
std::string normalization_name(Normalization n);
Quadrature quadrature_from(const std::string& name);
std::string quadrature_name(Quadrature q);
UnseenPolicy unseen_policy_from(const std::string& name);
std::string unseen_policy_name(UnseenPolicy u);

// A setting's value: text, or a number (threads, chunk_samples).
using EngineValue = std::variant<std::string, long long>;

struct EngineOptions {
  std::string backend = "cpu";  // "cpu", "simd", "vulkan", "cuda" or "auto" (the fastest backend present)
  // The backends' own settings by name (engine_settings(): device, threads, chunk_samples, arithmetic),
  // each declared by the backends that take it; set them through set() or set_engine_option, which
  // check them. The backend the engine runs reads those it declares; the others are left at their
  // defaults ("auto" for text, 0 for numbers): devices chosen and threads and chunks fitted to the
  // machine. With backend "auto" a setting goes to every backend that takes it; a named backend
  // that does not take it, given a value other than the default, is an input error naming the
  // setting and the backends it applies to.
  std::map<std::string, EngineValue> settings{};
  Normalization normalization = Normalization::integral;
  // UNSEEN pixels of the sky (a masked map, Sky::read_fits with UnseenPolicy::flag): an error by
  // default; taken as 0 with zero; taken as 0 with flag, and flag_samples() tells which samples' discs
  // hold one.
  UnseenPolicy unseen = UnseenPolicy::error;
  // The polar copy is resampled from the pixels around each pole on a thread of its own from set-up
  // (under a second at any NSIDE; Engine::prepare), and the backend holds the band of rings it lies on
  // beside the sky (1% to 2% more memory at NSIDE 1024 and 2048 for a 6-pixel-per-FWHM beam). Split
  // beams' outer parts have their own, on their coarse sky. A masked sky (UNSEEN pixels) has no copy:
  // its polar samples stay plain.
  Quadrature quadrature = Quadrature::corrected;

  // set_engine_option(*this, name, value).
  EngineOptions& set(const std::string& name, const EngineValue& value);
  // A backend setting as a backend reads it: the value given, else the default ("auto" for text, also
  // for an empty text; 0 for a number). Throws pisco::Error (input, keyed) for a value of the other type.
  std::string text(const std::string& name) const;
  std::size_t number(const std::string& name) const;
};

// The engine's settings by name (docs/library.md, "Engine options"): the one table that simulation
// files' [engine] tables, pisco-vk's options and Python's Engine keywords set them through. The
// engine's own (backend, normalization, unseen, quadrature), then those the backends declare, each
// once, with the backends it applies to, whether each backend is built into this library or not.
struct EngineSetting {
  const char* name;      // "backend", "device", "threads", "chunk_samples", "arithmetic", "normalization",
                         // "unseen", "quadrature"
  const char* takes;     // what it takes, in words
  const char* backends;  // the backends it applies to ("all", or names)
  bool number;           // a number (threads, chunk_samples), else text
};
std::span<const EngineSetting> engine_settings();

// Sets the setting `name` of `options`: the engine's own into their members, the backends' into
// EngineOptions::settings. Throws pisco::Error (ErrorKind::input) with key() the setting's name for a
// name not in engine_settings(), a value of the wrong type or not among those it takes, or a value
// other than the default for a named backend without the setting (setting the backend checks the
// settings already given against it).
void set_engine_option(EngineOptions& options, const std::string& name, const EngineValue& value);

// Whether the backend `backend` ("cpu", "simd", "vulkan", "cuda") takes the setting `name`, as its
// entry declares; false for an unknown backend or setting.
bool backend_has_setting(const std::string& backend, const std::string& name);

// `options` for the backend `backend` instead (the backend "auto" chose, a second engine on another
// backend): without the settings `backend` does not take, and without the device where the options
// named another backend (a device belongs to the backend it was given for; under "auto" it was
// given for all). The engine-wide settings are kept.
EngineOptions options_for_backend(const EngineOptions& options, const std::string& backend);

// What a backend can do, so that a caller (a framework, the simulation pipeline) decides by
// capability rather than by the backend's name.
struct BackendCapabilities {
  bool float64 = false;         // every operation in float64 (the reference); else float32 pixel sums
                                // with float64 where it decides (docs/physics.md, "Device backends")
  bool plates = true;           // half-wave plates, at the aperture and between optics and detector
  bool adjoint = false;         // the transpose of convolve: Engine::adjoint
  bool worker_threads = false;  // runs its own host threads: its "threads" setting applies
  bool normal = false;          // a one-pass normal (Engine::normal: each pixel's weights computed once for
                                // A^T A s) for detectors of its float32 path without a split beam or a
                                // plate before the detector; elsewhere the engine runs the forward pass
                                // and then the adjoint
  std::uint64_t device_memory = 0;  // bytes of memory of the device "auto" picks; 0: the host's memory
};

struct BackendInfo {
  std::string name;
  bool available = false;
  std::string detail;  // device found, or why the backend is unavailable
  // The indices (the "device" setting) of the devices "auto" chooses among: the usable ones of the
  // kind it prefers (discrete GPUs before others), in index order; empty for cpu. Several processes on
  // one node (pisco-vk under MPI) share them out: process k takes devices[k % devices.size()].
  std::vector<std::size_t> devices;
  BackendCapabilities capabilities;  // meaningful where available
};

// Four writable maps at the engine's NSIDE (RING order) that Engine::take_adjoint adds into. V may
// be empty: its part is then dropped.
struct StokesMaps {
  std::span<double> I, Q, U, V;
};

namespace detail {
class Backend;
struct BackendEntry;
struct EngineInputs;
class SkyPass;
}  // namespace detail

// A chunk of boresight pointing that several detectors' submissions read (Engine::share): the
// caller's angles or quaternions, checked once, and the key by which a device backend knows it has
// staged them already. It refers to the caller's arrays, which must outlive it.
class SharedPointing {
 public:
  SharedPointing() = default;
  std::size_t size() const noexcept { return quaternions_ ? quats_.size() : angles_.size(); }
  bool quaternions() const noexcept { return quaternions_; }
  const PointingView& angles() const noexcept { return angles_; }
  const QuatPointingView& quats() const noexcept { return quats_; }
  // Samples [offset, offset + count), still shared; pisco::Error (input) beyond the chunk.
  SharedPointing subspan(std::size_t offset, std::size_t count) const {
    if (offset > size() || count > size() - offset)
      throw Error("SharedPointing::subspan: samples " + std::to_string(offset) + " to " +
                  std::to_string(offset + count) + " (exclusive) of a chunk of " + std::to_string(size()));
    SharedPointing p = *this;
    if (quaternions_) p.quats_ = quats_.subspan(offset, count);
    else p.angles_ = angles_.subspan(offset, count);
    p.first_ += offset;
    return p;
  }

 private:
  friend class Engine;
  PointingView angles_;
  QuatPointingView quats_;
  bool quaternions_ = false;
  std::uint64_t key_ = 0;   // unique to the share() that made it
  std::size_t first_ = 0;   // its first sample within what share() was given
};

// Thread safety: one Engine is used by one thread at a time. Its members that change it (convolve,
// submit, wait, adjoint, adjoint_diagonal, normal, take_adjoint, set_sky, and moving it) must not run
// concurrently with any other member; guard a shared engine
// with a mutex, or give each thread its own. Distinct engines may run concurrently in one process, on
// the same device or not (each holds its own device state; the Vulkan instance they share is made once,
// under a lock). The engine copies what it needs of the sky, beams and focal plane at construction:
// the caller may change or destroy them afterwards. The cpu and simd backends run their own worker
// threads inside each call; the GPU backends their own streams or queues.
//
// Errors are pisco::Error (pisco/error.hpp) with a kind: ErrorKind::unavailable for a backend or device
// absent from this machine (a caller may fall back on another), ErrorKind::device for a device that
// fails while working, ErrorKind::input for bad arguments.
class Engine {
 public:
  // Prepares the sky, the beamsors and the detectors for the chosen backend. Throws pisco::Error on
  // an unknown (input) or unavailable (unavailable) backend, a detector referring to a missing beam,
  // or a non-finite sky.
  Engine(const SkyView& sky, const std::vector<Beamsor>& beams, const FocalPlane& focal_plane,
         const EngineOptions& options = {});
  ~Engine();
  Engine(Engine&&) noexcept;
  Engine& operator=(Engine&&) noexcept;

  // TOD of detector `detector` for a chunk of boresight pointing, as angles or as quaternions; the
  // engine applies the detector's offset (Detector::offset) on the device. tod.size() must equal the
  // pointing's size. Every sample of tod is written, or, with `accumulate`, added to what tod holds
  // (as a framework operator adds a signal into its detector data). A detector with a half-wave plate
  // (Detector::hwp) needs `hwp_angle`, the plate's angle per sample in the focal-plane frame
  // (radians, TOAST's `hwp_angle`); others must be given none. A detector whose beam changes with time
  // (Detector::beam_sequence) needs `time`, each sample's time in seconds on the clock of its nodes;
  // others ignore it. Throws pisco::Error on a bad sample (naming the detector and the sample's index),
  // and on a TOD sample that is not finite once complete (float64 overflowed: the error names the
  // detector, the sample and the value).
  void convolve(std::size_t detector, const PointingView& boresight, std::span<double> tod, bool accumulate = false,
                std::span<const double> hwp_angle = {}, std::span<const double> time = {});
  void convolve(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                bool accumulate = false, std::span<const double> hwp_angle = {}, std::span<const double> time = {});

  // The same, asynchronously: the pointing is read (copied to the device's staging memory) before
  // submit() returns, and the call returns a ticket as soon as the work is queued; tod must stay
  // valid, and is written, by the time wait(ticket) returns. Submissions complete in order, so
  // waiting for one waits for every earlier one. While the device convolves one submission, the
  // caller prepares the next and reads back the previous: upload, compute and download overlap
  // whatever the size of the caller's chunks. The device holds at most two chunks in flight: a
  // submit() that finds both busy first completes the oldest.
  // (The plate angles, like the pointing, are read before submit() returns.)
  std::uint64_t submit(std::size_t detector, const PointingView& boresight, std::span<double> tod,
                       bool accumulate = false, std::span<const double> hwp_angle = {},
                       std::span<const double> time = {});
  std::uint64_t submit(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                       bool accumulate = false, std::span<const double> hwp_angle = {},
                       std::span<const double> time = {});
  // Several detectors on one chunk of boresight pointing (a focal plane's detectors over a time chunk):
  // share() checks the pointing once and returns it marked as shared; submit() given that (whole, or
  // a part of it: SharedPointing::subspan) queues one detector as the submit() above does, the same
  // bits, without checking the pointing again, and a device backend's slot that already holds those
  // samples is not staged again: where each detector's submission fits one device chunk, the chunk
  // is staged and uploaded twice (once in each of the two slots the detectors take turns in) instead
  // of once per detector; each detector's offset is applied on the device. A detector with samples near a
  // pole alone among the sky's sends its other samples as pointing of its own. The pointing's values
  // must stay as they were at share() until the last submit() given it has returned.
  SharedPointing share(const PointingView& boresight);
  SharedPointing share(const QuatPointingView& boresight);
  std::uint64_t submit(std::size_t detector, const SharedPointing& boresight, std::span<double> tod,
                       bool accumulate = false, std::span<const double> hwp_angle = {},
                       std::span<const double> time = {});
  // The same for a list of detectors in one call: tods[k] is detectors[k]'s TOD, of the pointing's size;
  // hwp_angle goes to the detectors with a half-wave plate (needed when one has one), time to those whose
  // beam changes with time. The indices and buffer sizes are checked before anything is queued; on any
  // other error (naming its detector) the detectors before it have completed (their TODs written)
  // when it is thrown. Returns the last detector's ticket (0 for no detectors). (A caller that reads back each detector's TOD while the
  // next ones convolve, as `pisco-vk run` does, calls share() and then submit() a detector at a time.)
  std::uint64_t submit(std::span<const std::size_t> detectors, const PointingView& boresight,
                       std::span<const std::span<double>> tods, bool accumulate = false,
                       std::span<const double> hwp_angle = {}, std::span<const double> time = {});
  std::uint64_t submit(std::span<const std::size_t> detectors, const QuatPointingView& boresight,
                       std::span<const std::span<double>> tods, bool accumulate = false,
                       std::span<const double> hwp_angle = {}, std::span<const double> time = {});
  // Waits for submission `ticket` and every earlier one; without a ticket, for all. Rethrows the
  // error of a failed submission, or of a TOD sample that is not finite (every submission waited for
  // is complete all the same: a later wait() does not report it again).
  void wait(std::uint64_t ticket);
  void wait();

  // The adjoint (docs/physics.md, "The adjoint"): convolve is a linear map A from the sky (I, Q, U,
  // V at the engine's NSIDE) to a detector's TOD; adjoint() adds A^T tod, the transpose of the same
  // map (offsets, plates, normalization, the polar copy and cap-boundary weights, split beams
  // included), into the engine's own accumulated maps, and take_adjoint() adds those into `maps` and
  // clears them. <s, A^T d> = <A s, d> to rounding. The sky the engine was made with plays no part.
  // The order of the detectors and chunks given to adjoint() does not change the result beyond
  // rounding, and the same calls give the same bits. Waits for every submission first. Throws
  // pisco::Error of kind unavailable where the backend has no adjoint (capabilities().adjoint), and
  // of kind input for bad arguments (as convolve; a TOD sample that is not finite is one).
  void adjoint(std::size_t detector, const PointingView& boresight, std::span<const double> tod,
               std::span<const double> hwp_angle = {}, std::span<const double> time = {});
  void adjoint(std::size_t detector, const QuatPointingView& boresight, std::span<const double> tod,
               std::span<const double> hwp_angle = {}, std::span<const double> time = {});
  // The diagonal of A^T A for these samples (per pixel and Stokes parameter, the sum over samples of
  // the squared weights with which adjoint() scatters), added into the same maps: what a
  // preconditioner needs (DeconvolvingMapmaker). Exact on the main beam's plain pixel sum; samples
  // near the poles are counted on the sky rather than its polar copy, split beams' outer parts are
  // left out, and a plate between the optics and the detector counts its four row detectors' squares
  // without their cross terms, as a beam that changes with time its two nodes' at each sample. Take the
  // maps before mixing it with adjoint().
  void adjoint_diagonal(std::size_t detector, const PointingView& boresight, std::span<const double> hwp_angle = {},
                        std::span<const double> time = {});
  void adjoint_diagonal(std::size_t detector, const QuatPointingView& boresight,
                        std::span<const double> hwp_angle = {}, std::span<const double> time = {});
  // A^T A s for the engine's sky s (set_sky's, or the constructor's): adds the adjoint of the
  // detector's own convolution of s into the same maps: what convolve() into a TOD followed by
  // adjoint() of that TOD adds (an iteration of DeconvolvingMapmaker), the same bits. Where the
  // backend can (simd without its float64 path: no monopole taken out of the sky, no per-sample
  // normalization), each sample's disc is evaluated once instead of twice (docs/physics.md,
  // "Map-making with the beams"); elsewhere, and for split beams, plates between the optics and the
  // detector and beams that change with time, it convolves and scatters in two passes. Errors as adjoint().
  void normal(std::size_t detector, const PointingView& boresight, std::span<const double> hwp_angle = {},
              std::span<const double> time = {});
  void normal(std::size_t detector, const QuatPointingView& boresight, std::span<const double> hwp_angle = {},
              std::span<const double> time = {});
  // maps.I, Q, U (and V unless empty) must have npix() samples each.
  void take_adjoint(const StokesMaps& maps);
  // Replaces the sky, keeping the beams, the detectors and the options: what an iterative solver
  // (DeconvolvingMapmaker) does between iterations. The same NSIDE; waits for every submission; the
  // adjoint maps must have been taken. Costs what the constructor's sky set-up costs (the backend's
  // copy of the pixels; the polar copy and a split beam's coarse sky when they are used). The polar
  // copy's transform runs in the background, as at construction (prepare()).
  void set_sky(const SkyView& sky);
  // Completes the set-up the engine runs in the background: the sky's polar copy (EngineOptions::
  // quadrature), whose spherical-harmonic turn of the sky starts on a thread of its own at construction
  // and at set_sky(), and its upload to the backend. Optional: the first submission with a sample near
  // a pole otherwise completes it (and a run far from the poles never waits for it). Call it to pay
  // the set-up before time-critical work, or to time the set-up apart from the convolution (`pisco-vk
  // bench`). Rethrows an error of the transform (pisco::Error). Does nothing when there is no polar copy.
  void prepare();
  std::size_t npix() const noexcept;
  int nside() const noexcept;

  std::string backend_name() const;
  std::string device_name() const;
  const FocalPlane& focal_plane() const noexcept { return focal_plane_; }
  // Mean number of sky pixels per sample over all convolve() calls so far (a split beam's main and
  // outer parts together).
  double mean_disc_pixels() const noexcept;
  // Seconds the calling thread has spent in convolve() and submit()'s own per-sample host work so far:
  // checking the pointing, plate angles and TOD, finding the samples near the poles, and completing
  // and checking each TOD; not the backends' staging, kernels or transfers, nor the polar copy's set-up.
  double host_seconds() const noexcept { return host_seconds_; }
  // Beams split into a main part and sidelobes (Beamsor::sidelobes; docs/beams.md, "Sidelobes"): the
  // NSIDE of the band-limited sky their outer parts are summed on; 0 when no beam is split.
  int sidelobe_nside() const noexcept { return outer_nside_; }
  // Whether samples near the poles are summed on the sky's polar copy (EngineOptions::quadrature), and how
  // many submitted so far were.
  bool polar_copy() const noexcept;
  std::uint64_t polar_samples() const noexcept { return polar_samples_; }
  // Pointing samples the device backends (vulkan, cuda) have staged for the device so far: each
  // submission's once a detector, or once a slot for submit() with several detectors. 0 on the host
  // backends, which read the caller's pointing where it lies.
  std::uint64_t staged_samples() const noexcept;

  // Every backend the library knows, built into it or not, with whether it runs on this machine (a
  // backend not built says so in BackendInfo::detail) and what it can do.
  static std::vector<BackendInfo> backends();
  // Their names ("cpu", "simd", "vulkan", "cuda"), without looking for devices.
  static std::vector<std::string> backend_names();

  // Masked skies (EngineOptions::unseen = UnseenPolicy::flag): flags[i] = 1 where the disc of sample
  // i (the detector's, its offset applied; the convolution's own disc selection, HEALPix query_disc
  // with inclusive = false) holds a pixel that is UNSEEN in the sky, 0 elsewhere; returns the number
  // flagged. flags.size() must equal the pointing's size. Computed on the host at the call; with no
  // UNSEEN pixel (or another policy) every flag is 0. Such samples are convolved with those pixels
  // taken as 0: leave them out of maps (BinnedMapmaker::add's flags). A beam that changes with time
  // flags the samples whose disc holds one under any of its nodes' beams.
  std::size_t flag_samples(std::size_t detector, const PointingView& boresight, std::span<std::uint8_t> flags) const;
  std::size_t flag_samples(std::size_t detector, const QuatPointingView& boresight,
                           std::span<std::uint8_t> flags) const;
  // Point sources, fixed or moving (pisco/sources.hpp, docs/sources.md): adds to tod each source's
  // response at these samples, the detector's beam (a split beam's outer part included) evaluated at
  // the source's direction, with the half-wave plate, exactly: no pixelization of the source, the same
  // near the poles as anywhere. `time` is each sample's time on the sources' clock. Computed on the
  // host in float64, the same bits whatever the backend; a beam that changes with time at these
  // times (Detector::beam_sequence). Needs the integral normalization. Throws
  // pisco::Error naming the detector, the source or the sample (a time outside a source's track).
  void add_sources(std::size_t detector, const PointingView& boresight, std::span<const double> time,
                   const std::vector<SourceTrack>& sources, std::span<double> tod,
                   std::span<const double> hwp_angle = {}) const;
  void add_sources(std::size_t detector, const QuatPointingView& boresight, std::span<const double> time,
                   const std::vector<SourceTrack>& sources, std::span<double> tod,
                   std::span<const double> hwp_angle = {}) const;
  // The number of UNSEEN sky pixels taken as 0 (policies zero and flag).
  std::size_t unseen_pixels() const noexcept { return unseen_pixels_; }
  // The largest "threads" setting: 64 per hardware thread of this machine.
  static unsigned max_threads() noexcept;

 private:
  // A submission's pointing as other submissions read it too (detail::PointingInput::shared): the key
  // they share (0: a key of its own), and whether it has been checked already. Always made with braces
  // ({} is all zeros: unshared); no member initializers, so that `= {}` may default a parameter here.
  struct Shared {
    std::uint64_t key;
    std::size_t first;  // the submission's first sample within the shared chunk
    bool checked;
  };
  // `node`: one of the engine's own detectors for a node of a beam that changes with time.
  template <class View>
  std::uint64_t submit_view(std::size_t detector, const View& boresight, std::span<double> tod, bool accumulate,
                            std::span<const double> hwp_angle, std::span<const double> time, bool node = false,
                            Shared shared = {});
  template <class View>
  std::uint64_t submit_nodes(std::size_t detector, const View& boresight, std::span<double> tod, bool accumulate,
                             std::span<const double> hwp_angle, std::span<const double> time,
                             bool pointing_checked);
  template <class View>
  SharedPointing share_view(const View& boresight);
  template <class View>
  std::uint64_t submit_detectors(std::span<const std::size_t> detectors, const View& boresight,
                                 std::span<const std::span<double>> tods, bool accumulate,
                                 std::span<const double> hwp_angle, std::span<const double> time);
  void finish_pending(std::uint64_t ticket);
  template <class View>
  void adjoint_view(std::size_t detector, const View& boresight, std::span<const double> tod,
                    std::span<const double> hwp_angle, std::span<const double> time, bool squares, bool node = false);
  template <class View>
  void normal_view(std::size_t detector, const View& boresight, std::span<const double> hwp_angle,
                   std::span<const double> time);
  // Checks a submission's arguments; fills plate_angle (hwp_angle - gamma) for a detector with a plate.
  // A detector whose beam changes with time needs `time`, one whose beam turns with the plate
  // `hwp_angle` (unless `node`: one of the engine's own detectors for their beams).
  template <class View>
  void check_submission(const char* what, std::size_t detector, const View& boresight, std::size_t tod_size,
                        std::span<const double> hwp_angle, std::vector<double>& plate_angle,
                        std::span<const double> time, bool node = false, bool pointing_checked = false) const;
  template <class View>
  void add_sources_view(std::size_t detector, const View& boresight, std::span<const double> time,
                        const std::vector<SourceTrack>& sources, std::span<double> tod,
                        std::span<const double> hwp_angle, bool node = false) const;
  // A detector whose beam is a per-sample combination of beams (one that changes with time, one that
  // turns with the plate): its samples in groups, each summed by some of the engine's own detectors
  // (nodes_), with a coefficient per node and sample (docs/changing.md).
  struct NodeGroup {
    std::vector<std::size_t> nodes;                // the engine's detectors
    std::vector<std::size_t> index;                // the group's samples, ascending
    std::vector<std::vector<double>> coefficient;  // per node, per sample of the group
    bool contiguous() const noexcept { return index.back() - index.front() + 1 == index.size(); }
  };
  std::vector<NodeGroup> node_groups(const char* what, std::size_t detector, std::span<const double> time,
                                     std::span<const double> hwp_angle) const;
  std::span<const double> node_plate(std::size_t detector, std::span<const double> hwp_angle, const NodeGroup& group,
                                     bool contiguous, std::vector<double>& own) const;
  bool has_nodes(std::size_t detector) const noexcept {
    return detector < nodes_.size() && !nodes_[detector].empty();
  }
  // After a failed submission of such a detector: the parts already queued finished and dropped
  // (pending_ from `mark` on).
  void abandon(std::size_t mark) noexcept;
  void load_sky(const SkyView& sky, const std::vector<Beamsor>* beams);

  // Work the engine itself completes when a submission is done (plates between the optics and the
  // detector: the combination of their row detectors), and the check that its TOD is finite.
  struct Pending;
  void complete(Pending& p);
  void drop_pending() noexcept;

  FocalPlane focal_plane_;
  // The detectors the engine prepares: the focal plane's, then one for each beam of each beam that
  // changes with time or turns with the plate (the detector with that beam, without a plate), whose
  // indices nodes_ holds, and, for the plate's beams, each one's Omega~ over their mean (node_scale_).
  FocalPlane detectors_;
  std::vector<std::vector<std::size_t>> nodes_;  // per detector of the focal plane; empty: a fixed beam
  std::vector<std::vector<double>> node_scale_;
  std::shared_ptr<const detail::EngineInputs> inputs_;
  // The sky summed by the chosen backend, with its polar copy for the samples near the poles
  // (core/sky_pass.hpp). Its tickets are the engine's.
  std::unique_ptr<detail::SkyPass> main_;
  std::uint64_t samples_ = 0, pixels_ = 0;
  double host_seconds_ = 0.0;
  std::vector<std::unique_ptr<Pending>> pending_;
  std::vector<std::uint32_t> masked_;  // UnseenPolicy::flag: the sky's UNSEEN pixels, ascending
  std::size_t unseen_pixels_ = 0;
  // Split beams: their outer parts on the band-limited sky, through a pass of their own (with its own
  // polar copy), queued with each submission and added when it completes.
  std::shared_ptr<const detail::EngineInputs> outer_inputs_;
  std::unique_ptr<detail::SkyPass> outer_;
  std::vector<bool> split_;  // per detector
  int outer_nside_ = 0;
  int outer_band_ = 0;  // the split beams' band limit l_pass
  const detail::BackendEntry* entry_ = nullptr;
  EngineOptions options_;
  std::uint64_t polar_samples_ = 0;
};

}  // namespace pisco
