// [mapmaker] type = "deconvolve" (docs/config.md): pisco::DeconvolvingMapmaker, the sky at its own
// NSIDE solved by conjugate gradients that replay the survey after the stream, with the binned maps and
// hits beside (BinnedRun).
#include <algorithm>
#include <numbers>

#include "core/text.hpp"
#include "pipeline/mapmakers/binned.hpp"
#include "pipeline/survey.hpp"

namespace pisco::detail {
namespace {

class DeconvolveRun : public BinnedRun {
 public:
  explicit DeconvolveRun(const MapmakerSetup& s) : BinnedRun(s), source_(s.c.source) {
    const SimulationConfig& c = s.c;
    for (const BackendInfo& b : Engine::backends())
      if (b.name == s.engine.backend_name() && !b.capabilities.adjoint)
        throw Error(c.source.string() + ": [mapmaker] type = \"deconvolve\" needs the adjoint, which the " +
                        s.engine.backend_name() + " backend on " + s.engine.device_name() +
                        " lacks; choose another [engine] backend",
                    ErrorKind::unavailable);
    DeconvolutionOptions o;
    o.max_iterations = c.mapmaker.iterations;
    o.tolerance = c.mapmaker.tolerance;
    o.regularization = c.mapmaker.regularization;
    if (c.mapmaker.regularize_polarization_only) o.regularize = DeconvolutionOptions::Regularize::polarization;
    o.target_fwhm = c.mapmaker.target_fwhm;
    if (s.cl.parallel()) o.reduce = [&cl = s.cl](std::span<double> v) { cl.sum_in_place(v); };
    deconvolver_.emplace(s.engine, o);
  }

  // The binned maps, and the right-hand side A^T d chunk by chunk.
  void add(const MapmakerJob& job) override {
    BinnedRun::add(job);
    try {
      deconvolver_->add(job.chunk, job.tod);
    } catch (const Error& e) {
      throw Error(source_.string() + ": [mapmaker] type = \"deconvolve\": " + e.what(), e.kind());
    }
  }

  // Every process replays its own jobs each iteration, and the maps are summed over the processes
  // (RunContext::sum_in_place), so that all run the same iterations.
  void solve(const MapmakerEnd& end) override;

  MapOutputs write(const MapmakerEnd& end) override {
    MapOutputs out = write_deconvolved_maps(end.c, end.sky, end.maps_nside, *deconvolved_, sky_, end.log);
    write_ground(end, out);
    return out;
  }

 private:
  std::filesystem::path source_;
  std::optional<DeconvolvingMapmaker> deconvolver_;
  std::optional<DeconvolvedMaps> deconvolved_;
};

void DeconvolveRun::solve(const MapmakerEnd& end) {
  const SimulationConfig& c = end.c;
  const auto& say = end.say;
  SimulationResult& result = end.result;
  say(printf_text("mapmaker: deconvolving each detector's beam by conjugate gradients, at most %d iterations "
                  "(tolerance %g, regularization %g), reconvolved to a Gaussian of FWHM %g deg (0: not reconvolved)\n",
                  c.mapmaker.iterations, c.mapmaker.tolerance, c.mapmaker.regularization,
                  c.mapmaker.target_fwhm * 180 / std::numbers::pi));
  const auto survey = [&](const std::function<void(const SurveyChunk&)>& visit) {
    replay_survey(end.plan, c, end.fp, end.scan, visit);
  };
  deconvolved_ = deconvolver_->solve(survey, [&](const DeconvolutionProgress& p) {
    say(printf_text("mapmaker: iteration %d, residual %.3g of ||A^T d|| (%.1f s)\n", p.iteration, p.residual, p.seconds));
  });
  const DeconvolvedMaps& d = *deconvolved_;
  say(printf_text("mapmaker: %s after %d iterations, %.2f s each\n", d.converged ? "converged" : "stopped", d.iterations,
                  d.seconds_per_iteration));
  for (const std::string& line : d.left_out) say(printf_text("mapmaker: left out %s\n", line.c_str()));
  result.deconvolution_iterations = d.iterations;
  result.deconvolution_residual = d.residuals.empty() ? 0.0 : d.residuals.back();
  result.deconvolution_converged = d.converged;
  if (!d.converged) {
    const auto& r = d.residuals;
    const auto best = std::min_element(r.begin(), r.end());
    result.warnings.push_back(printf_text(
        "the deconvolving map-maker did not converge: residual %.3g of ||A^T d|| after %d iterations (the "
        "smallest, %.3g, at iteration %d), above [mapmaker] tolerance = %g; raise iterations, or the "
        "tolerance to what the backend reaches (float32 kernels stop near 1e-4), or add regularization",
        result.deconvolution_residual, d.iterations, best == r.end() ? 0.0 : *best, int(best - r.begin()) + 1,
        c.mapmaker.tolerance));
  }
  if (d.polarization_unconstrained)
    result.warnings.push_back(
        "the scan's polarization angles constrain Q and U in no pixel the beams reach (one angle per "
        "pixel?): the deconvolved maps hold I alone, Q and U are unseen");
}

void read(Table& t, MapmakerConfig& m) {
  m.iterations = static_cast<int>(t.integer_in("iterations", 40, 1, 100000, "a number of iterations from 1 to 100000"));
  m.tolerance = t.number_in("tolerance", 1e-6, 1e-15, 0.5, "a relative residual in [1e-15, 0.5]");
  m.regularization = t.number_in("regularization", 1e-3, 0.0, 1.0, "a fraction of the Rayleigh quotient in [0, 1]");
  m.regularize_polarization_only = t.choice("regularize", "all", {"all", "polarization"}) == "polarization";
  m.target_fwhm = t.number_in("target_fwhm_deg", 0.0, 0.0, 90.0, "0 (none) or a FWHM in degrees below 90") * deg;
}

// What the deconvolving map-maker does not do, said where the file asks for it.
void check(const SimulationConfig& c, const Table& t) {
  if (!c.output.maps) t.fail("type", "\"deconvolve\" makes maps: set [output] maps = true");
  if (c.sky.unseen == UnseenPolicy::flag)
    t.fail("type", "\"deconvolve\" models every sample; it cannot leave out the samples [sky] unseen = \"flag\" flags");
  if (c.hwp.ideal_mapmaker)
    t.fail("type", "\"deconvolve\" models each detector's own plate; [hwp] mapmaker = \"ideal\" is for the binned map-maker");
}

// The sky's own NSIDE: the engine's, which the solution is the sky at.
int maps_nside(const SimulationConfig& c, const Sky& sky) {
  if (c.output.maps_nside > 0 && c.output.maps_nside != sky.nside())
    throw Error(c.source.string() + ": [output] maps_nside: [mapmaker] type = \"deconvolve\" solves for the sky at its NSIDE " +
                std::to_string(sky.nside()) + "; got " + std::to_string(c.output.maps_nside) +
                " (leave maps_nside out, or set it to the sky's)");
  return sky.nside();
}

}  // namespace

const MapmakerKindEntry deconvolve_mapmaker_kind{
    MapmakerKind::deconvolve,
    "deconvolve",
    {"iterations", "tolerance", "regularization", "regularize", "target_fwhm_deg"},
    read,
    check,
    maps_nside,
    [](const MapmakerSetup& s) -> std::unique_ptr<RunMapmaker> { return std::make_unique<DeconvolveRun>(s); },
};

}  // namespace pisco::detail
