#include "core/sky_pass.hpp"

#include <algorithm>
#include <cmath>

#include "kernel/frame.hpp"

namespace pisco::detail {

SkyPass::SkyPass(const BackendEntry& entry, std::shared_ptr<const EngineInputs> inputs, const SkyView& summed,
                 const SkyView& sky, const EngineOptions& options, bool polar, bool weigh)
    : inputs_(std::move(inputs)), nside_(sky.nside()), weigh_(weigh) {
  backend_ = entry.create(inputs_, summed, options);
  if (!polar) return;
  bool any = false;
  for (const PreparedDetector& d : inputs_->detectors) {
    cut_.push_back(polar_cut(d.rho_max, nside_));
    const double z = d.offset.active ? rotation_matrix(d.offset.quat).ez.z : 1.0;
    offset_angle_.push_back(std::acos(std::clamp(z, -1.0, 1.0)) + 1e-9);
    any = any || cut_.back() > 0.0;
    // The copy's pixels that such a sample's disc can reach, two pixels more for the disc's edge.
    if (cut_.back() > 0.0)
      reach_ = std::max(reach_, cut_.back() + d.rho_max + 2.0 * std::sqrt(sky.pixel_area()));
  }
  if (any && !polar_copy_fits(nside_, reach_)) any = false;
  if (!any) {
    cut_.clear();
    offset_angle_.clear();
    return;
  }
  // The transform starts now on a thread of its own, beside the rest of the set-up and whatever the
  // caller does next; a ground scan far from the poles never waits for it.
  setup_ = std::make_unique<Setup>();
  setup_->band = std::async(std::launch::async, [source = polar_source(sky, reach_), weigh] {
    return polar_sky(source, weigh);
  });
}

SkyPass::~SkyPass() = default;

void SkyPass::attach() {
  if (polar_ready_ || !setup_) return;
  if (setup_->error) std::rethrow_exception(setup_->error);  // every later call fails alike
  try {
    backend_->set_polar_sky(setup_->band.get());
  } catch (...) {
    setup_->error = std::current_exception();
    throw;
  }
  setup_.reset();
  polar_ready_ = true;
}

void SkyPass::prepare() { attach(); }

void SkyPass::begin(std::size_t detector, const PointingInput& input, Work& w, bool forward) {
  w.polar.reset();
  w.sky.reset();
  w.runs.assign(1, {0, input.size()});
  w.parts.clear();
  w.parts.reserve(4);
  w.ticket = 0;
  if (!polar_copy()) return;
  auto samples = std::make_shared<PolarSamples>();
  const PreparedDetector& det = inputs_->detectors.at(detector);
  if (!find_polar_samples(input, det.offset, offset_angle_.at(detector), cut_.at(detector), *samples)) return;
  w.runs = sky_runs(samples->index, input.size());
  // Where the adjoint's runs hold polar samples, the forward pass gathers the sky's own samples
  // instead, so that it sums each sample once.
  std::vector<std::array<std::size_t, 2>> exact;
  if (forward) exact = sky_runs(samples->index, input.size(), 1);
  if (forward && exact != w.runs) {
    auto g = std::make_shared<Work::Gathered>();
    g->shared = next_shared_key();
    const std::size_t n = input.size() - samples->index.size();
    g->index.reserve(n);
    if (input.quaternions) g->quats.reserve(n);
    else g->angles.reserve(n);
    if (!input.plate_angle.empty()) g->plate_angle.reserve(n);
    for (const auto& [b, e] : exact)
      for (std::size_t i = b; i < e; ++i) {
        g->index.push_back(i);
        if (input.quaternions) g->quats.push_back(input.quats.quats[i]);
        else g->angles.push_back(input.angles.theta[i], input.angles.phi[i], input.angles.psi[i]);
        if (!input.plate_angle.empty()) g->plate_angle.push_back(input.plate_angle[i]);
      }
    w.sky = std::move(g);
  }
  w.polar = std::move(samples);
}

PointingInput SkyPass::Work::Gathered::input() const {
  PointingInput in;
  in.quaternions = !quats.empty();
  if (in.quaternions) in.quats = QuatPointingView{quats};
  else in.angles = angles.view();
  in.plate_angle = plate_angle;
  in.shared = shared;
  return in;
}

void SkyPass::submit(Work& w, std::size_t target, const PointingInput& input, std::span<double> out,
                     bool accumulate) {
  Work::Part& part = w.parts.emplace_back();
  part.out = out;
  part.accumulate = accumulate;
  if (w.polar && accumulate) {
    part.base.resize(w.polar->index.size());
    for (std::size_t k = 0; k < part.base.size(); ++k) part.base[k] = out[w.polar->index[k]];
  }
  if (w.sky) {
    if (!w.sky->index.empty()) {
      part.sky_values.assign(w.sky->index.size(), 0.0);
      w.ticket = next_ticket_++;
      backend_->submit(target, w.sky->input(), part.sky_values, false, w.ticket);
    }
  } else {
    for (const auto& [b, e] : w.runs) {
      w.ticket = next_ticket_++;
      backend_->submit(target, input.subspan(b, e - b), out.subspan(b, e - b), accumulate, w.ticket);
    }
  }
  if (w.polar) {
    part.values.assign(w.polar->index.size(), 0.0);
    w.ticket = next_ticket_++;
    backend_->submit(target, w.polar->input(), part.values, false, w.ticket);
  }
}

void SkyPass::finish(Work& w) {
  if (!w.polar) return;
  const std::vector<std::size_t>& index = w.polar->index;
  for (Work::Part& part : w.parts) {
    if (w.sky)  // as the backend delivers a sample: written, or added
      for (std::size_t k = 0; k < w.sky->index.size(); ++k) {
        double& o = part.out[w.sky->index[k]];
        o = part.accumulate ? o + part.sky_values[k] : part.sky_values[k];
      }
    for (std::size_t k = 0; k < index.size(); ++k)
      part.out[index[k]] = (part.accumulate ? part.base[k] : 0.0) + part.values[k];
  }
}

std::uint64_t SkyPass::adjoint(const Work& w, std::size_t target, const PointingInput& input,
                               std::span<const double> values, bool squares) {
  adjoint_ = true;
  if (squares || !w.polar) return backend_->adjoint(target, input, values, squares);
  // The sky's part over its runs (a short run of polar samples inside one scatters 0), the polar
  // samples' at take_adjoint().
  const std::vector<std::size_t>& index = w.polar->index;
  std::vector<double> near(index.size()), away(values.begin(), values.end());
  for (std::size_t k = 0; k < near.size(); ++k) {
    near[k] = values[index[k]];
    away[index[k]] = 0.0;
  }
  std::uint64_t pixels = 0;
  for (const auto& [b, e] : w.runs)
    pixels += backend_->adjoint(target, input.subspan(b, e - b), std::span(away).subspan(b, e - b));
  polar_adjoints_.push_back({target, w.polar, std::move(near)});
  return pixels;
}

std::uint64_t SkyPass::normal(const Work& w, std::size_t detector, const PointingInput& input) {
  // The samples near the poles are the polar copy's, the rest the sky's, as the forward pass has them:
  // the copy's forward values now, scattered at take_adjoint() with the adjoint's polar samples.
  std::vector<double> select(input.size(), 1.0);
  if (w.polar)
    for (const std::size_t i : w.polar->index) select[i] = 0.0;
  std::uint64_t pixels = backend_->normal(detector, input, select);
  adjoint_ = true;
  if (w.polar) {
    std::vector<double> values(w.polar->index.size());
    const std::uint64_t t = next_ticket_++;
    backend_->submit(detector, w.polar->input(), values, false, t);
    pixels += backend_->wait(t);
    polar_adjoints_.push_back({detector, w.polar, std::move(values)});
  }
  return pixels;
}

Sky SkyPass::collect() {
  Sky part(nside_);
  backend_->take_adjoint({part.I(), part.Q(), part.U(), part.V()});
  return part;
}

std::optional<Sky> SkyPass::take_adjoint(std::uint64_t& pixels) {
  std::optional<Sky> out;
  if (adjoint_) {
    out = collect();
    if (weigh_) weigh_cap_boundaries(*out);
    adjoint_ = false;
  }
  if (!polar_adjoints_.empty()) {
    // The backend's maps hold the sky's part no more: the polar samples scattered into them afresh,
    // then taken through the copy's transpose.
    std::vector<PolarAdjoint> work = std::move(polar_adjoints_);
    polar_adjoints_.clear();
    for (const PolarAdjoint& a : work) {
      PointingInput turned = a.samples->input();
      turned.sky = 0;  // the scatter reads the pixels' positions, the same in the copy
      pixels += backend_->adjoint(a.target, turned, a.values);
    }
    const Sky part = collect();
    const auto band = polar_band(nside_, reach_);
    const Sky polar = polar_sky_adjoint(band_of(part, band[0], band[1]), weigh_, reach_);
    if (!out) out.emplace(nside_);
    for (int c = 0; c < 4; ++c) {
      const std::span<double> to = out->stokes(StokesIndex(c));
      const std::span<const double> from = polar.stokes(StokesIndex(c));
      for (std::size_t p = 0; p < to.size(); ++p) to[p] += from[p];
    }
  }
  return out;
}

}  // namespace pisco::detail
