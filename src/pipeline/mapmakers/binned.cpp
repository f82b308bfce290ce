// [mapmaker] type = "binned", the default (docs/config.md): pisco::BinnedMapmaker over the sky's TOD.
#include "pipeline/mapmakers/binned.hpp"

namespace pisco::detail {

BinnedRun::BinnedRun(const MapmakerSetup& s) : sky_(s.maps_nside, s.c.output.rcond_min) {
  sky_.set_threads(s.host_threads);
  if (s.ground) ground_.emplace(s.maps_nside, s.c.output.rcond_min).set_threads(s.host_threads);
}

// The boresight's quaternions where the job has them (one conversion per time chunk for every
// detector, the offset applied per sample), else the detector's angles.
void BinnedRun::add(const MapmakerJob& job) {
  const auto bin = [&](BinnedMapmaker& m, std::span<const double> tod) {
    if (job.boresight.size() > 0)
      m.add_from_boresight(job.modelled, job.boresight, tod, job.chunk.hwp_angle, job.flags);
    else
      m.add(job.modelled, job.detector, tod, job.chunk.hwp_angle, job.flags);
  };
  bin(sky_, job.tod);
  if (ground_ && !job.ground.empty()) bin(*ground_, job.ground);
}

std::uint64_t BinnedRun::reduce(RunContext& cl) {
  std::uint64_t bytes = cl.sum(cl.reduce(sky_));
  if (ground_) bytes += cl.sum(cl.reduce(*ground_));
  return bytes;
}

void BinnedRun::write_ground(const MapmakerEnd& end, MapOutputs& out) {
  if (!ground_ || !out.nothing_solved.empty()) return;
  for (const auto& f : write_ground_maps(end.c, end.sky, end.maps_nside, *ground_, end.log)) out.written.push_back(f);
}

MapOutputs BinnedRun::write(const MapmakerEnd& end) {
  MapOutputs out = write_binned_maps(end.c, end.sky, end.maps_nside, sky_, end.flagging, end.log);
  write_ground(end, out);
  return out;
}

const MapmakerKindEntry binned_mapmaker_kind{
    MapmakerKind::binned,
    "binned",
    {},
    [](Table&, MapmakerConfig&) {},
    [](const SimulationConfig&, const Table&) {},
    [](const SimulationConfig& c, const Sky& sky) { return pisco::maps_nside(c, sky); },
    [](const MapmakerSetup& s) -> std::unique_ptr<RunMapmaker> { return std::make_unique<BinnedRun>(s); },
};

}  // namespace pisco::detail
