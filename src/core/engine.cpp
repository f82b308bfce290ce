#include "pisco/engine.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <future>

#include "core/backend.hpp"
#include "core/masked_sky.hpp"
#include "core/polar_copy.hpp"
#include "core/poles.hpp"
#include "core/prepared.hpp"
#include "core/sources.hpp"
#include "beams/sidelobes.hpp"
#include "core/text.hpp"
#include "pisco/hwp.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace detail {

const std::vector<BackendEntry>& backend_registry() {
  static const std::vector<BackendEntry> registry = [] {
    std::vector<BackendEntry> r;
    r.push_back(cpu_backend_entry());
#ifdef PISCO_HAVE_SIMD
    r.push_back(simd_backend_entry());
#endif
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

std::uint64_t Backend::adjoint(std::size_t detector, const PointingInput&, std::span<const double>, bool) {
  throw SubmissionError(detector, "the " + name() + " backend has no adjoint", ErrorKind::unavailable);
}

void Backend::take_adjoint(const std::array<std::span<double>, 4>&) {}
std::uint64_t Backend::normal(std::size_t detector, const PointingInput&, std::span<const double>) {
  throw SubmissionError(detector, "the " + name() + " backend has no normal pass", ErrorKind::unavailable);
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
    if (!best) throw Error("backend 'auto': no backend is available on this machine", ErrorKind::unavailable);
    return *best;
  }
  std::string known;
  for (const auto& e : reg) {
    if (e.name == name) {
      const BackendInfo info = e.probe();
      if (!info.available)
        throw Error("backend '" + name + "' is not available: " + info.detail, ErrorKind::unavailable);
      return e;
    }
    known += (known.empty() ? "" : ", ") + e.name;
  }
  throw Error("backend '" + name + "' is unknown; expected one of: auto, " + known);
}
}  // namespace
}  // namespace detail

namespace {
// The cap-boundary weights (core/poles.hpp) with the integral normalization only: a per-sample
// normalization divides each sample by its own discrete beam sum, in which the boundary rings' term
// cancels for a uniform sky, as that normalization promises (gain exactly 1).
bool weighs_cap_boundaries(const EngineOptions& options) {
  return options.quadrature == Quadrature::corrected && options.normalization == Normalization::integral;
}

std::shared_ptr<const detail::EngineInputs> prepared(const SkyView& sky, const std::vector<Beamsor>& beams,
                                                     const FocalPlane& focal_plane, const EngineOptions& options) {
  detail::EngineInputs in = detail::prepare_inputs(sky, beams, focal_plane, options.normalization);
  in.quadrature = weighs_cap_boundaries(options) ? Quadrature::corrected : Quadrature::plain;
  return std::make_shared<const detail::EngineInputs>(std::move(in));
}
}  // namespace

// The polar copy's transform (detail::polar_sky), running from set-up until the backend takes it.
struct Engine::PolarSetup {
  std::future<detail::SkyBand> sky;
  std::exception_ptr error;  // the transform's or the backend's, once reported
};

// One adjoint call's samples near the poles, turned, and their values (a row detector's, with a plate).
struct Engine::PolarAdjoint {
  std::size_t detector = 0;
  std::shared_ptr<const detail::PolarSamples> samples;
  std::vector<double> values;
};

Engine::Engine(const SkyView& sky, const std::vector<Beamsor>& beams, const FocalPlane& focal_plane,
               const EngineOptions& options)
    : focal_plane_(focal_plane) {
  detail::check_engine_options(options);
  check_focal_plane(focal_plane, beams.size());  // before the sky's set-up, which takes time
  entry_ = &detail::choose_backend(options.backend);
  options_ = options;
  load_sky(sky, &beams);
}

void Engine::set_sky(const SkyView& sky) {
  if (sky.nside() != inputs_->sky.nside)
    throw Error("set_sky: the sky has NSIDE " + std::to_string(sky.nside()) + "; the engine was made for NSIDE " +
                std::to_string(inputs_->sky.nside));
  wait();
  if (adjoint_main_ || adjoint_outer_ || !polar_adjoints_.empty())
    throw Error("set_sky: the engine holds adjoint maps not yet taken; call take_adjoint first");
  load_sky(sky, nullptr);
}

// Everything the engine makes from the sky; `beams` on the first call (from the constructor) only,
// which also prepares the detectors (their weights do not depend on the sky's values).
void Engine::load_sky(const SkyView& sky, const std::vector<Beamsor>* beams) {
  const detail::BackendEntry& entry = *entry_;
  const EngineOptions& options = options_;
  // A masked sky: the backends get a copy with its UNSEEN pixels 0, for the set-up only (masked_sky.hpp).
  std::optional<Sky> zeroed;
  // The backends get a copy with the rings where the polar caps meet the belt weighted (poles.hpp),
  // for the set-up only.
  Sky weighted(detail::sky_for_backends(sky, options.unseen, zeroed, masked_, unseen_pixels_));
  zeroed.reset();
  if (weighs_cap_boundaries(options_)) detail::weigh_cap_boundaries(weighted);
  if (beams) inputs_ = prepared(weighted, *beams, focal_plane_, options);
  else weighted.check_finite("sky");
  backend_.reset();  // a device holds one sky at a time
  backend_ = entry.create(inputs_, weighted, options);

  // Samples near the poles: on the sky turned by 90 deg, where they lie on its equator.
  polar_ready_ = false;
  polar_setup_.reset();  // waits for a transform still running from the previous sky
  polar_cut_.clear();
  polar_reach_ = 0.0;
  offset_angle_.clear();
  if (options.quadrature == Quadrature::corrected && unseen_pixels_ == 0) {
    bool any = false;
    for (const detail::PreparedDetector& d : inputs_->detectors) {
      polar_cut_.push_back(detail::polar_cut(d.rho_max, sky.nside()));
      const double z = d.offset.active ? detail::rotation_matrix(d.offset.quat).ez.z : 1.0;
      offset_angle_.push_back(std::acos(std::clamp(z, -1.0, 1.0)) + 1e-9);
      any = any || polar_cut_.back() > 0.0;
      // The copy's pixels that such a sample's disc can reach, two pixels more for the disc's edge.
      if (polar_cut_.back() > 0.0)
        polar_reach_ = std::max(polar_reach_, polar_cut_.back() + d.rho_max + 2.0 * std::sqrt(sky.pixel_area()));
    }
    // Its transform starts now on a thread of its own, beside the rest of the set-up and whatever the
    // caller does next; the backend takes it at prepare() or at the first submission with such a sample
    // (a ground scan far from the poles never waits for it), beside the sky, with the same detectors.
    if (any && !detail::polar_copy_fits(sky.nside(), polar_reach_)) {
      any = false;
      std::fill(polar_cut_.begin(), polar_cut_.end(), 0.0);
    }
    if (any) {
      polar_setup_ = std::make_unique<PolarSetup>();
      polar_setup_->sky = std::async(std::launch::async, [source = detail::polar_source(sky, polar_reach_),
                                                           weigh = weighs_cap_boundaries(options)] {
        return detail::polar_sky(source, weigh);
      });
    }
  }

  // Split beams: their outer parts on a band-limited copy of the sky at a coarser NSIDE.
  std::vector<Beamsor> outer;
  if (beams) {
    outer_nside_ = detail::sidelobe_nside(*beams, sky.nside());
    if (outer_nside_ == 0) return;
    if (options.normalization != Normalization::integral)
      throw Error("engine: beams split into a main part and sidelobes need the integral normalization; a per-sample "
                  "normalization would divide each part by its own sum");
    int band = 0;
    const Beamsor* placeholder = nullptr;
    for (const Beamsor& b : *beams)
      if (b.sidelobes()) {
        band = std::max(band, b.sidelobe_band_limit());
        if (!placeholder) placeholder = b.sidelobes();
      }
    for (const Beamsor& b : *beams) outer.push_back(b.sidelobes() ? *b.sidelobes() : *placeholder);
    split_.resize(focal_plane_.size());
    for (std::size_t d = 0; d < focal_plane_.size(); ++d)
      split_[d] = (*beams).at(focal_plane_[d].beam).sidelobes() != nullptr;
    outer_band_ = std::min(band, 2 * outer_nside_);
  }
  if (outer_nside_ == 0) return;
  if (options.unseen != UnseenPolicy::error && unseen_pixels_ > 0)
    throw Error("engine: the sky has UNSEEN pixels, which a band-limited copy for the beams' sidelobes cannot hold; "
                "fill the mask or do not split the beams");
  Sky coarse = detail::band_limited_sky(sky, outer_nside_, outer_band_);
  if (weighs_cap_boundaries(options_)) detail::weigh_cap_boundaries(coarse);
  if (beams) outer_inputs_ = prepared(coarse, outer, focal_plane_, options);
  outer_backend_.reset();
  outer_backend_ = entry.create(outer_inputs_, coarse, options);
}

Engine::~Engine() {
  // Nothing still in flight may write into the pending submissions' buffers once they are gone (a
  // plate's rows, the polar samples', a split beam's outer part): every backend finishes first.
  if (backend_ && next_ticket_ > 1) try {
      backend_->wait(next_ticket_ - 1);
    } catch (...) {  // the caller's wait() reports errors; a destructor cannot
    }
  drop_pending();
}

Engine::Engine(Engine&&) noexcept = default;
Engine& Engine::operator=(Engine&&) noexcept = default;

struct Engine::Pending {
  std::uint64_t ticket = 0;  // the last main-backend submission it needs (its polar samples' included)
  // Its last submission to the outer backend (0: none), waited for when it completes, so that
  // submit() queues every part and returns without waiting.
  std::uint64_t outer_ticket = 0;
  std::size_t detector = 0;
  std::span<double> tod;
  bool accumulate = false;
  std::vector<double> plate_angle;          // theta per sample
  std::array<std::vector<double>, 4> rows;  // s_T, s_Q, s_U, s_V
  // A split beam's outer part: its TOD (or its rows), added when the submission completes.
  std::vector<double> outer;
  std::array<std::vector<double>, 4> outer_rows;
  // Samples near the poles: their TOD (or rows) from the polar copy, and with `accumulate` what tod
  // held before, written over the main backend's when the submission completes.
  detail::PolarSamples polar;
  std::vector<double> polar_tod, polar_base;
  std::array<std::vector<double>, 4> polar_rows;
};

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

detail::PointingInput input_of(const PointingView& v) { return {v, {}, false, {}}; }
detail::PointingInput input_of(const QuatPointingView& v) { return {{}, v, true, {}}; }
}  // namespace

template <class View>
void Engine::check_submission(const char* what, std::size_t detector, const View& boresight, std::size_t tod_size,
                              std::span<const double> hwp_angle, std::vector<double>& plate_angle) const {
  const std::string op = what;
  if (detector >= focal_plane_.size())
    throw Error(op + ": detector index " + std::to_string(detector) + " but the focal plane has " +
                std::to_string(focal_plane_.size()) + " detectors");
  const std::string& name = focal_plane_[detector].name;
  if (tod_size != boresight.size())
    throw Error(op + ": the TOD buffer of detector '" + name + "' has " + std::to_string(tod_size) +
                " samples but the pointing has " + std::to_string(boresight.size()));
  check_pointing(boresight, ("pointing of detector '" + name + "'").c_str());
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  const bool plate = det.plate != detail::PreparedDetector::Plate::none;
  if (plate && hwp_angle.size() != tod_size)
    throw Error(op + ": detector '" + name + "' has a half-wave plate: expected " + std::to_string(tod_size) +
                " plate angles (hwp_angle), got " + std::to_string(hwp_angle.size()));
  if (!plate && !hwp_angle.empty())
    throw Error(op + ": detector '" + name + "' has no half-wave plate, but plate angles (hwp_angle) were given");
  if (plate) {
    plate_angle.resize(tod_size);
    for (std::size_t i = 0; i < tod_size; ++i) {
      if (!std::isfinite(hwp_angle[i]))
        throw Error(op + ": detector '" + name + "': plate angle (hwp_angle) of sample " + std::to_string(i) +
                    " is not finite");
      plate_angle[i] = hwp_angle[i] - det.plate_gamma;
    }
  }
}

template <class View>
void Engine::add_sources_view(std::size_t detector, const View& boresight, std::span<const double> time,
                              const std::vector<SourceTrack>& sources, std::span<double> tod,
                              std::span<const double> hwp_angle) const {
  std::vector<double> plate_angle;
  check_submission("add_sources", detector, boresight, tod.size(), hwp_angle, plate_angle);
  const std::string& name = focal_plane_[detector].name;
  if (time.size() != tod.size())
    throw Error("add_sources: detector '" + name + "': " + std::to_string(time.size()) + " sample times for " +
                std::to_string(tod.size()) + " samples");
  for (std::size_t i = 0; i < time.size(); ++i)
    if (!std::isfinite(time[i]))
      throw Error("add_sources: detector '" + name + "': the time of sample " + std::to_string(i) + " is " +
                  detail::number_text(time[i]) + "; expected a finite number");
  if (options_.normalization != Normalization::integral)
    throw Error("add_sources: point sources need the integral normalization; a per-sample normalization divides "
                "each sample by its own disc's sum, which a source outside the sky does not change");
  for (const SourceTrack& s : sources) s.check("add_sources");
  const auto part = [&](const detail::EngineInputs& in) {
    detail::SourcePart p;
    p.detector = &in.detectors.at(detector);
    for (int r = 0; r < 4; ++r)
      if (p.detector->plate == detail::PreparedDetector::Plate::detector) p.rows[r] = &in.detectors.at(p.detector->rows[r]);
    p.pixel_area = in.sky.pixel_area;
    return p;
  };
  std::vector<detail::SourcePart> parts{part(*inputs_)};
  if (!split_.empty() && split_[detector]) parts.push_back(part(*outer_inputs_));
  detail::PointingInput input = input_of(boresight);
  try {
    detail::add_source_tod(input, plate_angle, time, sources, parts, tod);
  } catch (const Error& e) {
    throw Error("add_sources: detector '" + name + "': " + e.what(), e.kind());
  }
}

void Engine::add_sources(std::size_t detector, const PointingView& boresight, std::span<const double> time,
                         const std::vector<SourceTrack>& sources, std::span<double> tod,
                         std::span<const double> hwp_angle) const {
  add_sources_view(detector, boresight, time, sources, tod, hwp_angle);
}

void Engine::add_sources(std::size_t detector, const QuatPointingView& boresight, std::span<const double> time,
                         const std::vector<SourceTrack>& sources, std::span<double> tod,
                         std::span<const double> hwp_angle) const {
  add_sources_view(detector, boresight, time, sources, tod, hwp_angle);
}

void Engine::attach_polar_copy() {
  if (polar_ready_ || !polar_setup_) return;
  if (polar_setup_->error) std::rethrow_exception(polar_setup_->error);  // every later call fails alike
  try {
    backend_->set_polar_sky(polar_setup_->sky.get());
  } catch (...) {
    polar_setup_->error = std::current_exception();
    throw;
  }
  polar_setup_.reset();
  polar_ready_ = true;
}

void Engine::prepare() { attach_polar_copy(); }

template <class View>
std::uint64_t Engine::submit_view(std::size_t detector, const View& boresight, std::span<double> tod,
                                  bool accumulate, std::span<const double> hwp_angle) {
  const auto host_start = std::chrono::steady_clock::now();
  auto pending = std::make_unique<Pending>();
  check_submission("convolve", detector, boresight, tod.size(), hwp_angle, pending->plate_angle);
  const std::string& name = focal_plane_[detector].name;
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  if (accumulate)
    for (std::size_t i = 0; i < tod.size(); ++i)
      if (!std::isfinite(tod[i]))
        throw Error("convolve: detector '" + name + "': the TOD to accumulate into is " + detail::number_text(tod[i]) +
                    " at sample " + std::to_string(i) + "; the TOD added to must be finite");
  detail::PointingInput input = input_of(boresight);
  if (det.plate == detail::PreparedDetector::Plate::aperture) input.plate_angle = pending->plate_angle;
  std::uint64_t ticket = 0;
  const bool split = !split_.empty() && split_[detector];
  const bool polar = polar_copy() && detail::find_polar_samples(input, det.offset, offset_angle_.at(detector),
                                                                polar_cut_.at(detector), pending->polar);
  // The sky's own pass over every sample but the runs that go to the polar copy (detail::sky_runs).
  std::vector<std::array<std::size_t, 2>> runs{{0, tod.size()}};
  if (polar) runs = detail::sky_runs(pending->polar.index, tod.size());
  host_seconds_ += seconds_since(host_start);
  if (polar) attach_polar_copy();
  const auto submit_runs = [&](std::size_t target, std::span<double> out, bool add) {
    for (const auto& [b, e] : runs) {
      ticket = next_ticket_++;
      backend_->submit(target, input.subspan(b, e - b), out.subspan(b, e - b), add, ticket);
    }
  };
  try {
    if (det.plate == detail::PreparedDetector::Plate::detector) {
      // d = D(0) M(theta) s, s_r from row detector r: completed by finish_pending().
      for (int r = 0; r < 4; ++r) {
        pending->rows[r].assign(tod.size(), 0.0);
        submit_runs(det.rows[r], pending->rows[r], false);
      }
      if (split) {
        std::uint64_t t = 0;
        for (int r = 0; r < 4; ++r) {
          pending->outer_rows[r].assign(tod.size(), 0.0);
          t = outer_ticket_++;
          outer_backend_->submit(det.rows[r], input, pending->outer_rows[r], false, t);
        }
        pending->outer_ticket = t;
      }
      if (polar) {
        const detail::PointingInput turned = pending->polar.input();
        for (int r = 0; r < 4; ++r) {
          pending->polar_rows[r].assign(turned.size(), 0.0);
          ticket = next_ticket_++;
          backend_->submit(det.rows[r], turned, pending->polar_rows[r], false, ticket);
        }
      }
    } else {
      if (polar && accumulate) {
        pending->polar_base.resize(pending->polar.index.size());
        for (std::size_t k = 0; k < pending->polar.index.size(); ++k)
          pending->polar_base[k] = tod[pending->polar.index[k]];
      }
      submit_runs(detector, tod, accumulate);
      if (split) {
        pending->outer.assign(tod.size(), 0.0);
        const std::uint64_t t = outer_ticket_++;
        outer_backend_->submit(detector, input, pending->outer, false, t);
        pending->outer_ticket = t;
      }
      if (polar) {
        pending->polar_tod.assign(pending->polar.index.size(), 0.0);
        ticket = next_ticket_++;
        backend_->submit(detector, pending->polar.input(), pending->polar_tod, false, ticket);
      }
    }
    // Every submission is completed, or at least checked, by finish_pending().
    pending->ticket = ticket;
    pending->detector = detector;
    pending->tod = tod;
    pending->accumulate = accumulate;
    pending_.push_back(std::move(pending));
    if (polar) polar_samples_ += pending_.back()->polar.index.size();
  } catch (const detail::SubmissionError& e) {
    throw Error("convolving detector '" + focal_plane_[inputs_->detectors.at(e.detector).owner].name + "': " + e.what(),
                e.kind());
  } catch (const Error& e) {
    throw Error("convolving detector '" + name + "': " + e.what(), e.kind());
  }
  samples_ += boresight.size();
  return ticket;
}

// The submissions done by `ticket`: their TOD completed (the polar samples, a split beam's outer
// part, the plates between the optics and the detector, d = D(0) M(theta) s), then checked finite.
// Every one of them is completed and dropped before the first non-finite value found is reported, so
// that the engine holds no half-finished work after the error.
void Engine::finish_pending(std::uint64_t ticket) {
  std::size_t done = 0;
  std::string problem;
  for (; done < pending_.size() && pending_[done]->ticket <= ticket; ++done) {
    Pending& p = *pending_[done];
    try {
      if (p.outer_ticket) pixels_ += outer_backend_->wait(p.outer_ticket);
    } catch (const detail::SubmissionError& e) {
      drop_pending();
      throw Error("convolving detector '" + focal_plane_[inputs_->detectors.at(e.detector).owner].name + "': " +
                      e.what(),
                  e.kind());
    }
    const auto host_start = std::chrono::steady_clock::now();
    complete(p);
    // One pass over the chunk: the arithmetic overflowed somewhere in the sum (every input was finite).
    for (std::size_t i = 0; i < p.tod.size() && problem.empty(); ++i)
      if (!std::isfinite(p.tod[i])) {
        const std::string& name = focal_plane_[p.detector].name;
        // The cpu backend sums in float64; the others sum the pixels in float32 (docs/simd.md).
        const bool wide = backend_->name() == "cpu";
        problem = "convolving detector '" + name + "': sample " + std::to_string(i) + " of the TOD is " +
                  detail::number_text(p.tod[i]) + ": the convolution overflowed " + (wide ? "float64" : "float32") +
                  "; the sky, the detector's gain or the beam's or half-wave plate's Mueller entries are too large "
                  "for " + (wide ? "float64 (their products exceed 1.8e308)" :
                                   "the " + backend_->name() + " backend's float32 sums (beyond 3.4e38)") +
                  (p.accumulate ? ", or so is the TOD accumulated into" : "");
      }
    host_seconds_ += seconds_since(host_start);
  }
  pending_.erase(pending_.begin(), pending_.begin() + std::ptrdiff_t(done));
  if (!problem.empty()) throw Error(problem);
}

// After a failed submission: every part's backend finished with the buffers of the pending
// submissions (their own errors are the same failure's), then the submissions dropped.
void Engine::drop_pending() noexcept {
  if (outer_backend_ && outer_ticket_ > 1) try {
      outer_backend_->wait(outer_ticket_ - 1);
    } catch (...) {
    }
  pending_.clear();
}

void Engine::complete(Pending& p) {
  const std::vector<std::size_t>& polar = p.polar.index;
  if (p.rows[0].empty()) {  // no plate before the detector: the polar samples, then a split beam's outer part
    for (std::size_t k = 0; k < polar.size(); ++k)
      p.tod[polar[k]] = (p.accumulate ? p.polar_base[k] : 0.0) + p.polar_tod[k];
    if (!p.outer.empty())
      for (std::size_t i = 0; i < p.tod.size(); ++i) p.tod[i] += p.outer[i];
    return;
  }
  for (std::size_t k = 0; k < polar.size(); ++k)
    for (int r = 0; r < 4; ++r) p.rows[r][polar[k]] = p.polar_rows[r][k];
  if (!p.outer_rows[0].empty())
    for (int r = 0; r < 4; ++r)
      for (std::size_t i = 0; i < p.tod.size(); ++i) p.rows[r][i] += p.outer_rows[r][i];
  const detail::PreparedDetector& det = inputs_->detectors.at(p.detector);
  Mueller m0{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) m0[i][j] = det.plate_mueller[i][j];
  for (std::size_t i = 0; i < p.tod.size(); ++i) {
    const Mueller m = rotated_mueller(m0, p.plate_angle[i]);
    double d = 0.0;
    for (int b = 0; b < 4; ++b) d += (det.d0[0] * m[0][b] + det.d0[1] * m[1][b]) * p.rows[b][i];
    p.tod[i] = p.accumulate ? p.tod[i] + d : d;
  }
}

std::uint64_t Engine::submit(std::size_t detector, const PointingView& boresight, std::span<double> tod,
                             bool accumulate, std::span<const double> hwp_angle) {
  return submit_view(detector, boresight, tod, accumulate, hwp_angle);
}

std::uint64_t Engine::submit(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                             bool accumulate, std::span<const double> hwp_angle) {
  return submit_view(detector, boresight, tod, accumulate, hwp_angle);
}

void Engine::wait(std::uint64_t ticket) {
  try {
    pixels_ += backend_->wait(ticket);
  } catch (const detail::SubmissionError& e) {
    drop_pending();
    throw Error("convolving detector '" + focal_plane_[inputs_->detectors.at(e.detector).owner].name + "': " + e.what(),
                e.kind());
  }
  finish_pending(ticket);
}

void Engine::wait() { wait(next_ticket_ - 1); }

void Engine::convolve(std::size_t detector, const PointingView& boresight, std::span<double> tod, bool accumulate,
                      std::span<const double> hwp_angle) {
  wait(submit(detector, boresight, tod, accumulate, hwp_angle));
}

void Engine::convolve(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                      bool accumulate, std::span<const double> hwp_angle) {
  wait(submit(detector, boresight, tod, accumulate, hwp_angle));
}

// The adjoint of submit_view, term by term (docs/physics.md, "The adjoint"): A = A_main W_cb on the
// samples away from the poles, A_main C on those near them (C the polar copy, whose own cap-boundary
// weights are inside it), plus A_outer W_cb B for a split beam's outer part (B the band-limited coarse
// sky), and a plate between the optics and the detector combines four row detectors with per-sample
// coefficients. The backends scatter each part into their own maps; take_adjoint applies the
// transposes of W_cb, C and B.
template <class View>
void Engine::adjoint_view(std::size_t detector, const View& boresight, std::span<const double> tod,
                          std::span<const double> hwp_angle, bool squares) {
  std::vector<double> plate_angle;
  check_submission(squares ? "adjoint_diagonal" : "adjoint", detector, boresight, tod.size(), hwp_angle, plate_angle);
  const std::string& name = focal_plane_[detector].name;
  for (std::size_t i = 0; i < tod.size(); ++i)
    if (!std::isfinite(tod[i]))
      throw Error("adjoint: detector '" + name + "': TOD sample " + std::to_string(i) + " is " +
                  detail::number_text(tod[i]) + "; the adjoint needs finite values");
  wait();
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  detail::PointingInput input = input_of(boresight);
  if (det.plate == detail::PreparedDetector::Plate::aperture) input.plate_angle = plate_angle;
  // The diagonal leaves out the outer parts and the polar copy (the main backend's plain sum instead).
  const bool split = !squares && !split_.empty() && split_[detector];
  auto polar_samples = std::make_shared<detail::PolarSamples>();
  const bool polar = !squares && polar_copy() &&
                     detail::find_polar_samples(input, det.offset, offset_angle_.at(detector), polar_cut_.at(detector),
                                                *polar_samples);
  std::vector<std::array<std::size_t, 2>> runs{{0, tod.size()}};
  if (polar) runs = detail::sky_runs(polar_samples->index, tod.size());
  // The TOD of each row detector (or of the detector itself): d, or d times the plate's coefficient.
  std::array<std::vector<double>, 4> rows;
  std::vector<std::size_t> targets;
  if (det.plate == detail::PreparedDetector::Plate::detector) {
    Mueller m0{};
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) m0[i][j] = det.plate_mueller[i][j];
    for (int b = 0; b < 4; ++b) rows[b].resize(tod.size());
    for (std::size_t i = 0; i < tod.size(); ++i) {
      const Mueller m = rotated_mueller(m0, plate_angle[i]);
      for (int b = 0; b < 4; ++b) rows[b][i] = (det.d0[0] * m[0][b] + det.d0[1] * m[1][b]) * tod[i];
    }
    targets.assign(det.rows, det.rows + 4);
  } else {
    rows[0].assign(tod.begin(), tod.end());
    targets.push_back(detector);
  }
  try {
    for (std::size_t r = 0; r < targets.size(); ++r) {
      const std::vector<double>& d = rows[r];
      if (split) {
        pixels_ += outer_backend_->adjoint(targets[r], input, d);
        adjoint_outer_ = true;
      }
      if (polar) {
        // The sky's part over its runs (a short run of polar samples inside one scatters 0), the
        // polar samples' at take_adjoint.
        std::vector<double> near(polar_samples->index.size()), away = d;
        for (std::size_t k = 0; k < near.size(); ++k) {
          near[k] = d[polar_samples->index[k]];
          away[polar_samples->index[k]] = 0.0;
        }
        for (const auto& [b, e] : runs)
          pixels_ += backend_->adjoint(targets[r], input.subspan(b, e - b), std::span(away).subspan(b, e - b));
        polar_adjoints_.push_back({targets[r], polar_samples, std::move(near)});
      } else {
        pixels_ += backend_->adjoint(targets[r], input, d, squares);
      }
      adjoint_main_ = true;
    }
  } catch (const detail::SubmissionError& e) {
    throw Error("adjoint of detector '" + name + "': " + e.what(), e.kind());
  } catch (const Error& e) {
    throw Error("adjoint of detector '" + name + "': " + e.what(), e.kind());
  }
  samples_ += tod.size();
}

void Engine::adjoint(std::size_t detector, const PointingView& boresight, std::span<const double> tod,
                     std::span<const double> hwp_angle) {
  adjoint_view(detector, boresight, tod, hwp_angle, false);
}

void Engine::adjoint(std::size_t detector, const QuatPointingView& boresight, std::span<const double> tod,
                     std::span<const double> hwp_angle) {
  adjoint_view(detector, boresight, tod, hwp_angle, false);
}

void Engine::adjoint_diagonal(std::size_t detector, const PointingView& boresight, std::span<const double> hwp_angle) {
  const std::vector<double> ones(boresight.size(), 1.0);
  adjoint_view(detector, boresight, ones, hwp_angle, true);
}

void Engine::adjoint_diagonal(std::size_t detector, const QuatPointingView& boresight,
                              std::span<const double> hwp_angle) {
  const std::vector<double> ones(boresight.size(), 1.0);
  adjoint_view(detector, boresight, ones, hwp_angle, true);
}

template <class View>
void Engine::normal_view(std::size_t detector, const View& boresight, std::span<const double> hwp_angle) {
  std::vector<double> plate_angle;
  check_submission("normal", detector, boresight, boresight.size(), hwp_angle, plate_angle);
  wait();
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  const bool split = !split_.empty() && split_[detector];
  detail::PointingInput input = input_of(boresight);
  if (det.plate == detail::PreparedDetector::Plate::aperture) input.plate_angle = plate_angle;
  auto polar_samples = std::make_shared<detail::PolarSamples>();
  const bool polar = polar_copy() && detail::find_polar_samples(input, det.offset, offset_angle_.at(detector),
                                                                polar_cut_.at(detector), *polar_samples);
  if (polar) attach_polar_copy();
  // The two passes where a sample's value comes from more than one backend's sum (a split beam's
  // outer part, a plate's four row detectors) or the backend has no normal pass.
  if (split || det.plate == detail::PreparedDetector::Plate::detector || !backend_->has_normal()) {
    std::vector<double> tod(boresight.size());
    convolve(detector, boresight, tod, false, hwp_angle);
    adjoint_view(detector, boresight, tod, hwp_angle, false);
    return;
  }
  // The samples near the poles are the polar copy's, the rest the sky's, as convolve has them: the
  // copy's forward values now, scattered at take_adjoint with the adjoint's polar samples.
  std::vector<double> main(boresight.size(), 1.0);
  for (const std::size_t i : polar_samples->index) main[i] = 0.0;
  std::uint64_t pixels = 0;
  try {
    pixels += backend_->normal(detector, input, main);
    adjoint_main_ = true;
    if (polar) {
      std::vector<double> values(polar_samples->index.size());
      const std::uint64_t t = next_ticket_++;
      backend_->submit(detector, polar_samples->input(), values, false, t);
      pixels += backend_->wait(t);
      polar_adjoints_.push_back({detector, polar_samples, std::move(values)});
      polar_samples_ += polar_samples->index.size();
    }
  } catch (const detail::SubmissionError& e) {
    throw Error("normal pass of detector '" + focal_plane_[detector].name + "': " + e.what(), e.kind());
  } catch (const Error& e) {
    throw Error("normal pass of detector '" + focal_plane_[detector].name + "': " + e.what(), e.kind());
  }
  pixels_ += pixels;
  samples_ += boresight.size();
}

void Engine::normal(std::size_t detector, const PointingView& boresight, std::span<const double> hwp_angle) {
  normal_view(detector, boresight, hwp_angle);
}

void Engine::normal(std::size_t detector, const QuatPointingView& boresight, std::span<const double> hwp_angle) {
  normal_view(detector, boresight, hwp_angle);
}

std::size_t Engine::npix() const noexcept { return inputs_->sky.npix; }
int Engine::nside() const noexcept { return inputs_->sky.nside; }

void Engine::take_adjoint(const StokesMaps& maps) {
  const std::size_t n = npix();
  for (const auto& [m, label] : {std::pair{maps.I, "I"}, {maps.Q, "Q"}, {maps.U, "U"}})
    if (m.size() != n)
      throw Error(std::string("take_adjoint: the ") + label + " map has " + std::to_string(m.size()) +
                  " pixels; the engine's NSIDE " + std::to_string(inputs_->sky.nside) + " has " + std::to_string(n));
  if (!maps.V.empty() && maps.V.size() != n)
    throw Error("take_adjoint: the V map has " + std::to_string(maps.V.size()) + " pixels; expected " +
                std::to_string(n) + " or none");
  const int nside = inputs_->sky.nside;
  const auto add = [&](const SkyView& part) {
    const std::array<std::span<double>, 4> out{maps.I, maps.Q, maps.U, maps.V};
    for (int c = 0; c < 4; ++c)
      if (!out[c].empty())
        for (std::size_t p = 0; p < n; ++p) out[c][p] += part.stokes(StokesIndex(c))[p];
  };
  // Each part on its own maps, then through the transpose of what the forward did to the sky.
  const auto collect = [&](detail::Backend& b, int part_nside) {
    Sky part(part_nside);
    b.take_adjoint({part.I(), part.Q(), part.U(), part.V()});
    return part;
  };
  if (adjoint_main_) {
    Sky part = collect(*backend_, nside);
    if (weighs_cap_boundaries(options_)) detail::weigh_cap_boundaries(part);
    add(part);
    adjoint_main_ = false;
  }
  if (!polar_adjoints_.empty()) {
    // The backend's maps hold the sky's part no more: the polar samples scattered into them afresh,
    // then taken through the copy's transpose.
    std::vector<PolarAdjoint> work = std::move(polar_adjoints_);
    polar_adjoints_.clear();
    for (const PolarAdjoint& a : work) {
      detail::PointingInput turned = a.samples->input();
      turned.sky = 0;  // the scatter reads the pixels' positions, the same in the copy
      pixels_ += backend_->adjoint(a.detector, turned, a.values);
    }
    const Sky part = collect(*backend_, nside);
    const auto [first, count] = detail::polar_band(nside, polar_reach_);
    add(detail::polar_sky_adjoint(detail::band_of(part, first, count), weighs_cap_boundaries(options_), polar_reach_));
  }
  if (adjoint_outer_) {
    Sky part = collect(*outer_backend_, outer_nside_);
    if (weighs_cap_boundaries(options_)) detail::weigh_cap_boundaries(part);
    add(detail::band_limited_sky_adjoint(part, nside, outer_band_));
    adjoint_outer_ = false;
  }
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
