// The survey's plan of jobs over the processes and its replay for the deconvolving map-maker (survey.hpp).
#include "pipeline/survey.hpp"

#include <algorithm>
#include <functional>
#include <thread>
#include <vector>

namespace pisco::detail {

JobPlan plan_jobs(std::size_t ndet, std::size_t samples, std::size_t chunk, bool detectors_outermost,
                  const RunContext& cl, const std::function<double(std::size_t)>& disc) {
  auto ceil_div = [](std::size_t a, std::size_t b) { return (a + b - 1) / b; };
  JobPlan p;
  p.ndet = ndet;
  p.samples = samples;
  p.detectors_outermost = detectors_outermost;
  p.span = chunk;
  if (cl.parallel() && samples > 0) {
    const std::size_t spans_needed = ceil_div(4 * std::size_t(cl.size()), std::max<std::size_t>(ndet, 1));
    p.span = std::max<std::size_t>(1, std::min(chunk, ceil_div(samples, spans_needed)));
  }
  p.spans = samples == 0 ? 0 : ceil_div(samples, p.span);
  p.njobs = p.spans * ndet;
  if (!cl.parallel()) {
    p.my_end = p.rounds = p.njobs;
    return p;
  }
  std::vector<double> cost_of(ndet);
  for (std::size_t d = 0; d < ndet; ++d) cost_of[d] = disc(d);
  double all = 0;
  for (std::size_t i = 0; i < p.njobs; ++i) {
    const JobPlan::Span j = p.at(i);
    all += double(j.count) * cost_of[j.detector];
  }
  std::vector<std::size_t> per_rank(std::size_t(cl.size()), 0);
  double before = 0;
  p.my_first = p.njobs;
  for (std::size_t i = 0; i < p.njobs; ++i) {
    const JobPlan::Span j = p.at(i);
    const double cost = double(j.count) * cost_of[j.detector];
    const int owner = all > 0 ? std::min(cl.size() - 1, int((before + 0.5 * cost) / all * cl.size())) : 0;
    before += cost;
    ++per_rank[std::size_t(owner)];
    if (owner == cl.rank()) {
      p.my_first = std::min(p.my_first, i);
      p.my_end = i + 1;
    }
  }
  if (p.my_first > p.my_end) p.my_first = p.my_end;
  p.rounds = *std::max_element(per_rank.begin(), per_rank.end());
  return p;
}

// The survey as the deconvolving map-maker replays it each iteration: this process's jobs of `plan`,
// in order, a chunk at a time.
void replay_survey(const JobPlan& plan, const SimulationConfig& c, const FocalPlane& fp, const ScanSource& scan,
                   const std::function<void(const pisco::SurveyChunk&)>& visit) {
  JobPointing pointing(c, fp, scan);
  std::vector<double> hwp;
  for (std::size_t i = plan.my_first; i < plan.my_end; ++i) visit(pointing.load(plan.at(i), hwp));
}


// The threads of this process's per-sample host work in the stream: the engine's own on the cpu and
// simd backends when they are set, else the host's hardware threads shared by the node's processes.
unsigned stream_host_threads(const SimulationConfig& c, const Engine& engine, const RunContext& cl) {
  if (backend_has_setting(engine.backend_name(), "threads"))
    if (const std::size_t threads = c.engine.options.number("threads"); threads > 0) return unsigned(threads);
  return std::max(1u, std::thread::hardware_concurrency() / unsigned(std::max(1, cl.node_size())));
}

}  // namespace pisco::detail
