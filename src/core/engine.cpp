#include "pisco/engine.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <future>
#include <numbers>
#include <type_traits>

#include "core/backend.hpp"
#include "core/masked_sky.hpp"
#include "core/polar_copy.hpp"
#include "core/poles.hpp"
#include "core/prepared.hpp"
#include "core/sky_pass.hpp"
#include "core/sources.hpp"
#include "core/outer_sky.hpp"
#include "core/text.hpp"
#include "pisco/hwp.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace detail {

const std::vector<BackendEntry>& backend_registry() {
  static const std::vector<BackendEntry> registry{cpu_backend_entry(), simd_backend_entry(), vulkan_backend_entry(),
                                                  cuda_backend_entry()};
  return registry;
}

std::uint64_t Backend::adjoint(std::size_t detector, const PointingInput&, std::span<const double>, bool) {
  throw SubmissionError(detector, "the " + name() + " backend has no adjoint", ErrorKind::unavailable);
}

void Backend::take_adjoint(const std::array<std::span<double>, 4>&) {}
std::uint64_t Backend::normal(std::size_t detector, const PointingInput&, std::span<const double>) {
  throw SubmissionError(detector, "the " + name() + " backend has no normal pass", ErrorKind::unavailable);
}

std::uint64_t next_shared_key() noexcept {
  static std::atomic<std::uint64_t> last{0};
  return last.fetch_add(1, std::memory_order_relaxed) + 1;
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

Engine::Engine(const SkyView& sky, const std::vector<Beamsor>& beams, const FocalPlane& focal_plane,
               const EngineOptions& options)
    : focal_plane_(focal_plane) {
  detail::check_engine_options(options);
  check_focal_plane(focal_plane, beams.size());  // before the sky's set-up, which takes time
  // Beams that change with time or turn with the plate: a detector of the engine's own for each of their
  // beams, without a plate (a plate's beams hold it).
  std::vector<Detector> all = focal_plane.detectors();
  nodes_.resize(all.size());
  node_scale_.resize(all.size());
  const auto add_node = [&](std::size_t d, std::size_t beam) {
    Detector node = focal_plane[d];
    node.beam = beam;
    node.beam_sequence.clear();
    node.plate_beams.reset();
    nodes_[d].push_back(all.size());
    all.push_back(std::move(node));
  };
  for (std::size_t d = 0; d < focal_plane.size(); ++d) {
    for (const BeamNode& n : focal_plane[d].beam_sequence) add_node(d, n.beam);
    if (const auto& p = focal_plane[d].plate_beams) {
      if (options.normalization != Normalization::integral)
        throw Error("detector '" + focal_plane[d].name + "': plate_beams need the integral normalization (the "
                    "plate's beams share their mean Omega~; a per-sample normalization would take the plate's "
                    "modulation of the total power out)");
      double norm = p->omega;
      if (norm == 0.0)
        for (const std::size_t b : p->beams) norm += beams[b].omega_tilde() / double(p->beams.size());
      for (const std::size_t b : p->beams) {
        add_node(d, b);
        node_scale_[d].push_back(beams[b].omega_tilde() / norm);
      }
    }
  }
  detectors_ = FocalPlane(std::move(all));
  entry_ = &detail::choose_backend(options.backend);
  options_ = options;
  load_sky(sky, &beams);
}

void Engine::set_sky(const SkyView& sky) {
  if (sky.nside() != inputs_->sky.nside)
    throw Error("set_sky: the sky has NSIDE " + std::to_string(sky.nside()) + "; the engine was made for NSIDE " +
                std::to_string(inputs_->sky.nside));
  wait();
  if (main_->holds_adjoint() || (outer_ && outer_->holds_adjoint()))
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
  if (beams) inputs_ = prepared(weighted, *beams, detectors_, options);
  else weighted.check_finite("sky");
  // Samples near the poles: on the sky turned by 90 deg, where they lie on its equator (a masked sky
  // has none: its copy would interpolate across the UNSEEN pixels).
  const bool polar = options.quadrature == Quadrature::corrected;
  main_.reset();  // a device holds one sky at a time
  main_ = std::make_unique<detail::SkyPass>(entry, inputs_, weighted, sky, options, polar && unseen_pixels_ == 0,
                                            weighs_cap_boundaries(options));

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
    split_.resize(detectors_.size());
    for (std::size_t d = 0; d < detectors_.size(); ++d)
      split_[d] = (*beams).at(detectors_[d].beam).sidelobes() != nullptr;
    outer_band_ = std::min(band, 2 * outer_nside_);
  }
  if (outer_nside_ == 0) return;
  if (options.unseen != UnseenPolicy::error && unseen_pixels_ > 0)
    throw Error("engine: the sky has UNSEEN pixels, which a band-limited copy for the beams' sidelobes cannot hold; "
                "fill the mask or do not split the beams");
  const Sky coarse = detail::band_limited_sky(sky, outer_nside_, outer_band_);
  Sky summed = coarse;
  if (weighs_cap_boundaries(options_)) detail::weigh_cap_boundaries(summed);
  if (beams) outer_inputs_ = prepared(summed, outer, detectors_, options);
  outer_.reset();
  outer_ = std::make_unique<detail::SkyPass>(entry, outer_inputs_, summed, coarse, options, polar,
                                             weighs_cap_boundaries(options));
}

Engine::~Engine() {
  // Nothing still in flight may write into the pending submissions' buffers once they are gone (a
  // plate's rows, the polar samples', a split beam's outer part): every backend finishes first.
  if (main_ && main_->last_ticket() > 0) try {
      main_->wait(main_->last_ticket());
    } catch (...) {  // the caller's wait() reports errors; a destructor cannot
    }
  drop_pending();
}

Engine::Engine(Engine&&) noexcept = default;
Engine& Engine::operator=(Engine&&) noexcept = default;

struct Engine::Pending {
  std::uint64_t ticket = 0;  // the last main-pass submission it needs (its polar samples' included)
  // Its last submission to the outer pass (0: none), waited for when it completes, so that submit()
  // queues every part and returns without waiting.
  std::uint64_t outer_ticket = 0;
  std::size_t detector = 0;
  std::span<double> tod;
  bool accumulate = false;
  std::vector<double> plate_angle;          // theta per sample
  std::array<std::vector<double>, 4> rows;  // s_T, s_Q, s_U, s_V
  // A split beam's outer part: its TOD (or its rows), added when the submission completes.
  std::vector<double> outer;
  std::array<std::vector<double>, 4> outer_rows;
  // Each pass's samples near the poles and their values from its polar copy, written over the sky's
  // when the submission completes.
  detail::SkyPass::Work main, outer_work;
  // A beam that changes with time or turns with the plate: its groups of samples, and each group's
  // nodes' TOD.
  std::vector<NodeGroup> groups;
  std::vector<std::vector<std::vector<double>>> values;
};

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

detail::PointingInput input_of(const PointingView& v) { return {v, {}, false, {}}; }
detail::PointingInput input_of(const QuatPointingView& v) { return {{}, v, true, {}}; }

// A group's samples of a chunk: the chunk's own span where they are contiguous, else copied (the
// engine reads pointing and plate angles before a submission returns).
PointingView group_view(const PointingView& v, const std::vector<std::size_t>& index, bool contiguous, Pointing& own) {
  if (contiguous) return v.subspan(index.front(), index.size());
  own = Pointing{};
  own.reserve(index.size());
  for (const std::size_t i : index) own.push_back(v.theta[i], v.phi[i], v.psi[i]);
  return own.view();
}
QuatPointingView group_view(const QuatPointingView& v, const std::vector<std::size_t>& index, bool contiguous,
                            std::vector<Quat>& own) {
  if (contiguous) return v.subspan(index.front(), index.size());
  own.clear();
  for (const std::size_t i : index) own.push_back(v.quats[i]);
  return QuatPointingView{own};
}
std::span<const double> group_values(std::span<const double> v, const std::vector<std::size_t>& index, bool contiguous,
                                     std::vector<double>& own) {
  if (v.empty()) return v;
  if (contiguous) return v.subspan(index.front(), index.size());
  own.clear();
  for (const std::size_t i : index) own.push_back(v[i]);
  return own;
}
// A TOD to accumulate into: finite, or the error names the detector and the sample.
void check_accumulated(const std::string& name, std::span<const double> tod) {
  for (std::size_t i = 0; i < tod.size(); ++i)
    if (!std::isfinite(tod[i]))
      throw Error("convolve: detector '" + name + "': the TOD to accumulate into is " + detail::number_text(tod[i]) +
                  " at sample " + std::to_string(i) + "; the TOD added to must be finite");
}

template <class View>
using GroupStorage = std::conditional_t<std::is_same_v<View, PointingView>, Pointing, std::vector<Quat>>;
}  // namespace

template <class View>
void Engine::check_submission(const char* what, std::size_t detector, const View& boresight, std::size_t tod_size,
                              std::span<const double> hwp_angle, std::vector<double>& plate_angle,
                              std::span<const double> time, bool node, bool pointing_checked) const {
  const std::string op = what;
  if (detector >= (node ? detectors_.size() : focal_plane_.size()))
    throw Error(op + ": detector index " + std::to_string(detector) + " but the focal plane has " +
                std::to_string(focal_plane_.size()) + " detectors");
  const std::string& name = detectors_[detector].name;
  if (!node && !focal_plane_[detector].beam_sequence.empty()) {
    if (time.size() != tod_size)
      throw Error(op + ": detector '" + name + "' has a beam that changes with time (beam_sequence): expected " +
                  std::to_string(tod_size) + " sample times (time), got " + std::to_string(time.size()));
    for (std::size_t i = 0; i < time.size(); ++i)
      if (!std::isfinite(time[i]))
        throw Error(op + ": detector '" + name + "': the time of sample " + std::to_string(i) + " is " +
                    detail::number_text(time[i]) + "; expected a finite number");
  }
  if (tod_size != boresight.size())
    throw Error(op + ": the TOD buffer of detector '" + name + "' has " + std::to_string(tod_size) +
                " samples but the pointing has " + std::to_string(boresight.size()));
  if (!pointing_checked) check_pointing(boresight, ("pointing of detector '" + name + "'").c_str());
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  // A beam that turns with the plate: the plate is in its beams, whose angle it needs all the same.
  const std::optional<PlateBeams>& plate_beams = node ? std::nullopt : focal_plane_[detector].plate_beams;
  const bool plate = det.plate != detail::PreparedDetector::Plate::none || plate_beams.has_value();
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
      plate_angle[i] = hwp_angle[i] - (plate_beams ? plate_beams->gamma : det.plate_gamma);
    }
  }
}

template <class View>
void Engine::add_sources_view(std::size_t detector, const View& boresight, std::span<const double> time,
                              const std::vector<SourceTrack>& sources, std::span<double> tod,
                              std::span<const double> hwp_angle, bool node) const {
  std::vector<double> plate_angle;
  check_submission("add_sources", detector, boresight, tod.size(), hwp_angle, plate_angle, {}, node);
  const std::string& name = detectors_[detector].name;
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
  if (!node && has_nodes(detector)) {
    // Each node's response at its samples, weighted, summed apart and added once all are made (an
    // error leaves the TOD as it was).
    std::vector<double> total(tod.size(), 0.0), part, times, plate;
    GroupStorage<View> own;
    for (const NodeGroup& group : node_groups("add_sources", detector, time, hwp_angle)) {
      const bool contiguous = group.contiguous();
      const View view = group_view(boresight, group.index, contiguous, own);
      const std::span<const double> t = group_values(time, group.index, contiguous, times);
      const std::span<const double> h = node_plate(detector, hwp_angle, group, contiguous, plate);
      for (std::size_t j = 0; j < group.nodes.size(); ++j) {
        part.assign(group.index.size(), 0.0);
        add_sources_view(group.nodes[j], view, t, sources, part, h, true);
        for (std::size_t m = 0; m < part.size(); ++m) total[group.index[m]] += group.coefficient[j][m] * part[m];
      }
    }
    for (std::size_t i = 0; i < tod.size(); ++i) tod[i] += total[i];
    return;
  }
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

bool Engine::polar_copy() const noexcept { return main_->polar_copy(); }

void Engine::prepare() {
  main_->prepare();
  if (outer_) outer_->prepare();
}

// The plate angles a group's nodes take: a beam that changes with time hands its own on (its nodes have
// its plate); the beams that turn with the plate hold it, and take none.
std::span<const double> Engine::node_plate(std::size_t detector, std::span<const double> hwp_angle,
                                           const NodeGroup& group, bool contiguous, std::vector<double>& own) const {
  if (focal_plane_[detector].plate_beams) return {};
  return group_values(hwp_angle, group.index, contiguous, own);
}

// The detector's samples in groups, each with its nodes and their coefficients (docs/changing.md):
// - a beam that changes with time: the samples between each two nodes k and k + 1 (the groups in the
//   order of their first sample), with 1 - w and w, w = (t - t_k) / (t_k+1 - t_k);
// - a beam that turns with the plate: every sample with every beam, with the trigonometric
//   interpolant's weights at x = 2 pi (theta - gamma) / period, times each beam's Omega~ over the
//   plate beams' shared normalization (node_scale_; the nodes are normalized each by its own).
std::vector<Engine::NodeGroup> Engine::node_groups(const char* what, std::size_t detector,
                                                   std::span<const double> time,
                                                   std::span<const double> hwp_angle) const {
  const Detector& d = focal_plane_[detector];
  const std::vector<std::size_t>& nodes = nodes_[detector];
  std::vector<NodeGroup> groups;
  if (const auto& p = d.plate_beams) {
    const std::size_t n = hwp_angle.size(), beams = nodes.size();
    if (n == 0) return groups;
    NodeGroup& g = groups.emplace_back();
    g.nodes = nodes;
    g.index.resize(n);
    for (std::size_t i = 0; i < n; ++i) g.index[i] = i;
    g.coefficient.assign(beams, std::vector<double>(n));
    // N points, harmonics m < N / 2, and for an even N the Nyquist term as cos(N x / 2) alone.
    const std::size_t top = (beams - 1) / 2;
    const bool nyquist = beams % 2 == 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = 2 * std::numbers::pi * (hwp_angle[i] - p->gamma) / p->period;
      for (std::size_t k = 0; k < beams; ++k) {
        const double u = x - 2 * std::numbers::pi * double(k) / double(beams);
        double c = 1.0;
        for (std::size_t m = 1; m <= top; ++m) c += 2.0 * std::cos(double(m) * u);
        if (nyquist) c += std::cos(double(beams / 2) * u);
        g.coefficient[k][i] = c / double(beams) * node_scale_[detector][k];
      }
    }
    return groups;
  }
  const std::vector<BeamNode>& seq = d.beam_sequence;
  std::vector<std::size_t> group_of(seq.size() - 1, std::size_t(-1));
  for (std::size_t i = 0; i < time.size(); ++i) {
    const double t = time[i];
    if (!(t >= seq.front().time && t <= seq.back().time))
      throw Error(std::string(what) + ": detector '" + d.name + "': sample " + std::to_string(i) + " is at time " +
                  detail::number_text(t, 12) + " s, outside its beam_sequence's nodes (" +
                  detail::number_text(seq.front().time, 12) + " to " + detail::number_text(seq.back().time, 12) +
                  " s)");
    // The node k with t_k <= t < t_k+1 (the last interval holds its end).
    const auto after = std::upper_bound(seq.begin(), seq.end(), t,
                                        [](double v, const BeamNode& n) { return v < n.time; });
    const std::size_t k = std::min(std::size_t(after - seq.begin()), seq.size() - 1) - 1;
    const double w = (t - seq[k].time) / (seq[k + 1].time - seq[k].time);
    if (group_of[k] == std::size_t(-1)) {
      group_of[k] = groups.size();
      NodeGroup& g = groups.emplace_back();
      g.nodes = {nodes[k], nodes[k + 1]};
      g.coefficient.resize(2);
    }
    NodeGroup& g = groups[group_of[k]];
    g.index.push_back(i);
    g.coefficient[0].push_back(1.0 - w);
    g.coefficient[1].push_back(w);
  }
  return groups;
}

void Engine::abandon(std::size_t mark) noexcept {
  try {
    if (main_->last_ticket() > 0) main_->wait(main_->last_ticket());
  } catch (...) {  // the failure being reported is this one
  }
  try {
    if (outer_ && outer_->last_ticket() > 0) outer_->wait(outer_->last_ticket());
  } catch (...) {
  }
  pending_.erase(pending_.begin() + std::ptrdiff_t(mark), pending_.end());
}

// A beam that changes with time or turns with the plate: each group of samples submitted for its
// nodes' detectors into buffers of the submission's own, combined with the samples' coefficients when it
// completes.
template <class View>
std::uint64_t Engine::submit_nodes(std::size_t detector, const View& boresight, std::span<double> tod,
                                   bool accumulate, std::span<const double> hwp_angle, std::span<const double> time,
                                   bool pointing_checked) {
  auto pending = std::make_unique<Pending>();
  std::vector<double> plate_angle;
  check_submission("convolve", detector, boresight, tod.size(), hwp_angle, plate_angle, time, false,
                   pointing_checked);
  const std::string& name = detectors_[detector].name;
  if (accumulate) check_accumulated(name, tod);
  pending->groups = node_groups("convolve", detector, time, hwp_angle);
  pending->values.resize(pending->groups.size());
  const std::size_t mark = pending_.size();
  try {
    GroupStorage<View> own;
    std::vector<double> plate;
    for (std::size_t g = 0; g < pending->groups.size(); ++g) {
      const NodeGroup& group = pending->groups[g];
      const bool contiguous = group.contiguous();
      const View view = group_view(boresight, group.index, contiguous, own);
      const std::span<const double> h = node_plate(detector, hwp_angle, group, contiguous, plate);
      pending->values[g].resize(group.nodes.size());
      // The group's nodes read the same samples, checked above.
      const Shared shared{detail::next_shared_key(), 0, true};
      for (std::size_t j = 0; j < group.nodes.size(); ++j) {
        pending->values[g][j].assign(group.index.size(), 0.0);
        submit_view(group.nodes[j], view, pending->values[g][j], false, h, {}, true, shared);
      }
    }
  } catch (...) {
    abandon(mark);
    throw;
  }
  samples_ -= tod.size() * (pending->groups.empty() ? 0 : pending->groups.front().nodes.size() - 1);
  pending->ticket = main_->last_ticket();
  pending->detector = detector;
  pending->tod = tod;
  pending->accumulate = accumulate;
  pending_.push_back(std::move(pending));
  return pending_.back()->ticket;
}

template <class View>
std::uint64_t Engine::submit_view(std::size_t detector, const View& boresight, std::span<double> tod,
                                  bool accumulate, std::span<const double> hwp_angle, std::span<const double> time,
                                  bool node, Shared shared) {
  if (!node && has_nodes(detector))
    return submit_nodes(detector, boresight, tod, accumulate, hwp_angle, time, shared.checked);
  const auto host_start = std::chrono::steady_clock::now();
  auto pending = std::make_unique<Pending>();
  check_submission("convolve", detector, boresight, tod.size(), hwp_angle, pending->plate_angle, time, node,
                   shared.checked);
  const std::string& name = detectors_[detector].name;
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  if (accumulate) check_accumulated(name, tod);
  detail::PointingInput input = input_of(boresight);
  // A plate's four row detectors read the same pointing, as do the detectors of a submission for
  // several (submit_detectors).
  input.shared = shared.key != 0 ? shared.key : detail::next_shared_key();
  input.shared_first = shared.first;
  if (det.plate == detail::PreparedDetector::Plate::aperture) input.plate_angle = pending->plate_angle;
  const bool split = !split_.empty() && split_[detector];
  try {
    // Each pass finds its samples near the poles (detail::SkyPass::begin); one that has some hands its
    // polar copy to its backend first, if it has not yet (outside the host work timed).
    main_->begin(detector, input, pending->main, true);
    if (split) outer_->begin(detector, input, pending->outer_work, true);
    host_seconds_ += seconds_since(host_start);
    if (pending->main.polar) main_->prepare();
    if (split && pending->outer_work.polar) outer_->prepare();
    if (det.plate == detail::PreparedDetector::Plate::detector) {
      // d = D(0) M(theta) s, s_r from row detector r: completed by finish_pending().
      for (int r = 0; r < 4; ++r) {
        pending->rows[r].assign(tod.size(), 0.0);
        main_->submit(pending->main, det.rows[r], input, pending->rows[r], false);
      }
      if (split)
        for (int r = 0; r < 4; ++r) {
          pending->outer_rows[r].assign(tod.size(), 0.0);
          outer_->submit(pending->outer_work, det.rows[r], input, pending->outer_rows[r], false);
        }
    } else {
      main_->submit(pending->main, detector, input, tod, accumulate);
      if (split) {
        pending->outer.assign(tod.size(), 0.0);
        outer_->submit(pending->outer_work, detector, input, pending->outer, false);
      }
    }
    // Every submission is completed, or at least checked, by finish_pending().
    pending->ticket = pending->main.ticket;
    pending->outer_ticket = pending->outer_work.ticket;
    pending->detector = detector;
    pending->tod = tod;
    pending->accumulate = accumulate;
    if (pending->main.polar) polar_samples_ += pending->main.polar->index.size();
    pending_.push_back(std::move(pending));
  } catch (const detail::SubmissionError& e) {
    throw Error("convolving detector '" + detectors_[inputs_->detectors.at(e.detector).owner].name + "': " + e.what(),
                e.kind());
  } catch (const Error& e) {
    throw Error("convolving detector '" + name + "': " + e.what(), e.kind());
  }
  samples_ += boresight.size();
  return pending_.back()->ticket;
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
      if (p.outer_ticket) pixels_ += outer_->wait(p.outer_ticket);
    } catch (const detail::SubmissionError& e) {
      drop_pending();
      throw Error("convolving detector '" + detectors_[inputs_->detectors.at(e.detector).owner].name + "': " +
                      e.what(),
                  e.kind());
    }
    const auto host_start = std::chrono::steady_clock::now();
    complete(p);
    // One pass over the chunk: the arithmetic overflowed somewhere in the sum (every input was finite).
    for (std::size_t i = 0; i < p.tod.size() && problem.empty(); ++i)
      if (!std::isfinite(p.tod[i])) {
        const std::string& name = detectors_[p.detector].name;
        // The cpu backend sums in float64; the others sum the pixels in float32 (docs/simd.md).
        const bool wide = main_->backend().name() == "cpu";
        problem = "convolving detector '" + name + "': sample " + std::to_string(i) + " of the TOD is " +
                  detail::number_text(p.tod[i]) + ": the convolution overflowed " + (wide ? "float64" : "float32") +
                  "; the sky, the detector's gain or the beam's or half-wave plate's Mueller entries are too large "
                  "for " + (wide ? "float64 (their products exceed 1.8e308)" :
                                   "the " + main_->backend().name() + " backend's float32 sums (beyond 3.4e38)") +
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
  if (outer_ && outer_->last_ticket() > 0) try {
      outer_->wait(outer_->last_ticket());
    } catch (...) {
    }
  pending_.clear();
}

void Engine::complete(Pending& p) {
  if (!p.groups.empty()) {  // a beam combined from nodes: their submissions completed before it
    for (std::size_t g = 0; g < p.groups.size(); ++g) {
      const NodeGroup& group = p.groups[g];
      for (std::size_t m = 0; m < group.index.size(); ++m) {
        double v = 0.0;
        for (std::size_t j = 0; j < group.nodes.size(); ++j) v += group.coefficient[j][m] * p.values[g][j][m];
        const std::size_t i = group.index[m];
        p.tod[i] = p.accumulate ? p.tod[i] + v : v;
      }
    }
    return;
  }
  detail::SkyPass::finish(p.main);
  detail::SkyPass::finish(p.outer_work);
  if (p.rows[0].empty()) {  // no plate before the detector: a split beam's outer part added
    if (!p.outer.empty())
      for (std::size_t i = 0; i < p.tod.size(); ++i) p.tod[i] += p.outer[i];
    return;
  }
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
                             bool accumulate, std::span<const double> hwp_angle, std::span<const double> time) {
  return submit_view(detector, boresight, tod, accumulate, hwp_angle, time);
}

std::uint64_t Engine::submit(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                             bool accumulate, std::span<const double> hwp_angle, std::span<const double> time) {
  return submit_view(detector, boresight, tod, accumulate, hwp_angle, time);
}

template <class View>
SharedPointing Engine::share_view(const View& boresight) {
  const auto host_start = std::chrono::steady_clock::now();
  check_pointing(boresight, "the shared boresight pointing");
  host_seconds_ += seconds_since(host_start);
  SharedPointing p;
  if constexpr (std::is_same_v<View, QuatPointingView>) {
    p.quats_ = boresight;
    p.quaternions_ = true;
  } else {
    p.angles_ = boresight;
  }
  p.key_ = detail::next_shared_key();
  return p;
}

SharedPointing Engine::share(const PointingView& boresight) { return share_view(boresight); }
SharedPointing Engine::share(const QuatPointingView& boresight) { return share_view(boresight); }

std::uint64_t Engine::submit(std::size_t detector, const SharedPointing& boresight, std::span<double> tod,
                             bool accumulate, std::span<const double> hwp_angle, std::span<const double> time) {
  if (boresight.key_ == 0) throw Error("submit: the pointing was not made by Engine::share()");
  const Shared shared{boresight.key_, boresight.first_, true};
  return boresight.quaternions_
             ? submit_view(detector, boresight.quats_, tod, accumulate, hwp_angle, time, false, shared)
             : submit_view(detector, boresight.angles_, tod, accumulate, hwp_angle, time, false, shared);
}

// Several detectors on one chunk: the indices and buffers checked for all before any is queued, then
// the pointing shared, and each detector queued as submit() queues it; on an error, what was queued
// completed before it is thrown.
template <class View>
std::uint64_t Engine::submit_detectors(std::span<const std::size_t> detectors, const View& boresight,
                                       std::span<const std::span<double>> tods, bool accumulate,
                                       std::span<const double> hwp_angle, std::span<const double> time) {
  if (tods.size() != detectors.size())
    throw Error("submit: " + std::to_string(detectors.size()) + " detectors but " + std::to_string(tods.size()) +
                " TOD buffers (expected one a detector)");
  for (std::size_t k = 0; k < detectors.size(); ++k) {
    if (detectors[k] >= focal_plane_.size())
      throw Error("submit: detector index " + std::to_string(detectors[k]) + " (entry " + std::to_string(k) +
                  ") but the focal plane has " + std::to_string(focal_plane_.size()) + " detectors");
    if (tods[k].size() != boresight.size())
      throw Error("submit: the TOD buffer of detector '" + focal_plane_[detectors[k]].name + "' has " +
                  std::to_string(tods[k].size()) + " samples but the pointing has " +
                  std::to_string(boresight.size()));
  }
  if (detectors.empty()) return 0;
  const SharedPointing shared = share(boresight);
  std::uint64_t ticket = 0;
  try {
    for (std::size_t k = 0; k < detectors.size(); ++k) {
      const Detector& d = focal_plane_[detectors[k]];
      const bool plate = d.hwp.has_value() || d.plate_beams.has_value();
      ticket = submit(detectors[k], shared, tods[k], accumulate, plate ? hwp_angle : std::span<const double>(), time);
    }
  } catch (...) {
    // The detectors this call queued complete first, so that none writes its buffer after the error
    // (an error of theirs, or of an earlier submission, is thrown instead).
    if (ticket != 0) wait(ticket);
    throw;
  }
  return ticket;
}

std::uint64_t Engine::submit(std::span<const std::size_t> detectors, const PointingView& boresight,
                             std::span<const std::span<double>> tods, bool accumulate,
                             std::span<const double> hwp_angle, std::span<const double> time) {
  return submit_detectors(detectors, boresight, tods, accumulate, hwp_angle, time);
}

std::uint64_t Engine::submit(std::span<const std::size_t> detectors, const QuatPointingView& boresight,
                             std::span<const std::span<double>> tods, bool accumulate,
                             std::span<const double> hwp_angle, std::span<const double> time) {
  return submit_detectors(detectors, boresight, tods, accumulate, hwp_angle, time);
}

std::uint64_t Engine::staged_samples() const noexcept {
  return main_->backend().staged_samples() + (outer_ ? outer_->backend().staged_samples() : 0);
}

void Engine::wait(std::uint64_t ticket) {
  try {
    pixels_ += main_->wait(ticket);
  } catch (const detail::SubmissionError& e) {
    drop_pending();
    throw Error("convolving detector '" + detectors_[inputs_->detectors.at(e.detector).owner].name + "': " + e.what(),
                e.kind());
  }
  finish_pending(ticket);
}

void Engine::wait() { wait(main_->last_ticket()); }

void Engine::convolve(std::size_t detector, const PointingView& boresight, std::span<double> tod, bool accumulate,
                      std::span<const double> hwp_angle, std::span<const double> time) {
  wait(submit(detector, boresight, tod, accumulate, hwp_angle, time));
}

void Engine::convolve(std::size_t detector, const QuatPointingView& boresight, std::span<double> tod,
                      bool accumulate, std::span<const double> hwp_angle, std::span<const double> time) {
  wait(submit(detector, boresight, tod, accumulate, hwp_angle, time));
}

// The adjoint of submit_view, term by term (docs/physics.md, "The adjoint"): A = A_main W_cb on the
// samples away from the poles, A_main C on those near them (C the polar copy, whose own cap-boundary
// weights are inside it), plus A_outer W_cb B for a split beam's outer part (B the band-limited coarse
// sky), and a plate between the optics and the detector combines four row detectors with per-sample
// coefficients. The backends scatter each part into their own maps; take_adjoint applies the
// transposes of W_cb, C and B.
template <class View>
void Engine::adjoint_view(std::size_t detector, const View& boresight, std::span<const double> tod,
                          std::span<const double> hwp_angle, std::span<const double> time, bool squares, bool node) {
  std::vector<double> plate_angle;
  const char* what = squares ? "adjoint_diagonal" : "adjoint";
  check_submission(what, detector, boresight, tod.size(), hwp_angle, plate_angle, time, node);
  const std::string& name = detectors_[detector].name;
  for (std::size_t i = 0; i < tod.size(); ++i)
    if (!std::isfinite(tod[i]))
      throw Error("adjoint: detector '" + name + "': TOD sample " + std::to_string(i) + " is " +
                  detail::number_text(tod[i]) + "; the adjoint needs finite values");
  if (!node && has_nodes(detector)) {
    // A^T d = sum over the nodes of A_k^T (c_k d), c_k each sample's coefficients (the diagonal: each
    // node's squares, c_k^2 times its own).
    std::vector<double> part, plate;
    GroupStorage<View> own;
    for (const NodeGroup& group : node_groups(what, detector, time, hwp_angle)) {
      const bool contiguous = group.contiguous();
      const View view = group_view(boresight, group.index, contiguous, own);
      const std::span<const double> h = node_plate(detector, hwp_angle, group, contiguous, plate);
      for (std::size_t j = 0; j < group.nodes.size(); ++j) {
        part.resize(group.index.size());
        for (std::size_t m = 0; m < part.size(); ++m) part[m] = group.coefficient[j][m] * tod[group.index[m]];
        adjoint_view(group.nodes[j], view, part, h, {}, squares, true);
      }
      samples_ -= group.index.size() * (group.nodes.size() - 1);  // each sample once, with its nodes' pixels
    }
    return;
  }
  wait();
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  detail::PointingInput input = input_of(boresight);
  if (det.plate == detail::PreparedDetector::Plate::aperture) input.plate_angle = plate_angle;
  // The diagonal leaves out the outer parts and the polar copy (the main backend's plain sum instead).
  const bool split = !squares && !split_.empty() && split_[detector];
  detail::SkyPass::Work main, outer;
  if (!squares) main_->begin(detector, input, main, false);
  if (split) outer_->begin(detector, input, outer, false);
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
      if (split) pixels_ += outer_->adjoint(outer, targets[r], input, rows[r], false);
      pixels_ += main_->adjoint(main, targets[r], input, rows[r], squares);
    }
  } catch (const detail::SubmissionError& e) {
    throw Error("adjoint of detector '" + name + "': " + e.what(), e.kind());
  } catch (const Error& e) {
    throw Error("adjoint of detector '" + name + "': " + e.what(), e.kind());
  }
  samples_ += tod.size();
}

void Engine::adjoint(std::size_t detector, const PointingView& boresight, std::span<const double> tod,
                     std::span<const double> hwp_angle, std::span<const double> time) {
  adjoint_view(detector, boresight, tod, hwp_angle, time, false);
}

void Engine::adjoint(std::size_t detector, const QuatPointingView& boresight, std::span<const double> tod,
                     std::span<const double> hwp_angle, std::span<const double> time) {
  adjoint_view(detector, boresight, tod, hwp_angle, time, false);
}

void Engine::adjoint_diagonal(std::size_t detector, const PointingView& boresight, std::span<const double> hwp_angle,
                              std::span<const double> time) {
  const std::vector<double> ones(boresight.size(), 1.0);
  adjoint_view(detector, boresight, ones, hwp_angle, time, true);
}

void Engine::adjoint_diagonal(std::size_t detector, const QuatPointingView& boresight,
                              std::span<const double> hwp_angle, std::span<const double> time) {
  const std::vector<double> ones(boresight.size(), 1.0);
  adjoint_view(detector, boresight, ones, hwp_angle, time, true);
}

template <class View>
void Engine::normal_view(std::size_t detector, const View& boresight, std::span<const double> hwp_angle,
                         std::span<const double> time) {
  std::vector<double> plate_angle;
  check_submission("normal", detector, boresight, boresight.size(), hwp_angle, plate_angle, time);
  if (has_nodes(detector)) {  // two passes, through the nodes
    std::vector<double> tod(boresight.size());
    convolve(detector, boresight, tod, false, hwp_angle, time);
    adjoint_view(detector, boresight, tod, hwp_angle, time, false);
    return;
  }
  wait();
  const detail::PreparedDetector& det = inputs_->detectors.at(detector);
  const bool split = !split_.empty() && split_[detector];
  detail::PointingInput input = input_of(boresight);
  if (det.plate == detail::PreparedDetector::Plate::aperture) input.plate_angle = plate_angle;
  // The two passes where a sample's value comes from more than one backend's sum (a split beam's
  // outer part, a plate's four row detectors) or the backend has no normal pass.
  if (split || det.plate == detail::PreparedDetector::Plate::detector || !main_->has_normal()) {
    std::vector<double> tod(boresight.size());
    convolve(detector, boresight, tod, false, hwp_angle);
    adjoint_view(detector, boresight, tod, hwp_angle, {}, false);
    return;
  }
  try {
    detail::SkyPass::Work work;
    main_->begin(detector, input, work, false);
    if (work.polar) main_->prepare();
    pixels_ += main_->normal(work, detector, input);
    if (work.polar) polar_samples_ += work.polar->index.size();
  } catch (const detail::SubmissionError& e) {
    throw Error("normal pass of detector '" + detectors_[detector].name + "': " + e.what(), e.kind());
  } catch (const Error& e) {
    throw Error("normal pass of detector '" + detectors_[detector].name + "': " + e.what(), e.kind());
  }
  samples_ += boresight.size();
}

void Engine::normal(std::size_t detector, const PointingView& boresight, std::span<const double> hwp_angle,
                    std::span<const double> time) {
  normal_view(detector, boresight, hwp_angle, time);
}

void Engine::normal(std::size_t detector, const QuatPointingView& boresight, std::span<const double> hwp_angle,
                    std::span<const double> time) {
  normal_view(detector, boresight, hwp_angle, time);
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
  // Each pass's maps, through the transposes of its polar copy and cap-boundary weights, then of what
  // the engine did to the sky before it (the outer pass's band-limited coarse sky).
  std::uint64_t pixels = 0;
  if (const std::optional<Sky> part = main_->take_adjoint(pixels)) add(*part);
  if (outer_)
    if (const std::optional<Sky> part = outer_->take_adjoint(pixels))
      add(detail::band_limited_sky_adjoint(*part, nside, outer_band_));
  pixels_ += pixels;
}

std::string Engine::backend_name() const { return main_->backend().name(); }
std::string Engine::device_name() const { return main_->backend().device(); }
double Engine::mean_disc_pixels() const noexcept {
  return samples_ ? double(pixels_) / double(samples_) : 0.0;
}

std::vector<std::string> Engine::backend_names() {
  std::vector<std::string> out;
  for (const auto& e : detail::backend_registry()) out.push_back(e.name);
  return out;
}

std::vector<BackendInfo> Engine::backends() {
  std::vector<BackendInfo> out;
  for (const auto& e : detail::backend_registry()) out.push_back(e.probe());
  return out;
}

}  // namespace pisco
