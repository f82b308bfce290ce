// The binned map-maker as a run's map-maker (pisco::BinnedMapmaker; mapmaker_kind.hpp): the sky's TOD
// binned into maps.fits and hits.fits, and with [ground] the ground's TOD alone binned beside it. The
// deconvolving kind keeps one beside its own solve (its binned maps and hits). Internal.
#pragma once

#include <optional>

#include "pipeline/mapmaker_kind.hpp"
#include "pisco/mapmaker.hpp"

namespace pisco::detail {

class BinnedRun : public RunMapmaker {
 public:
  explicit BinnedRun(const MapmakerSetup& s);
  void add(const MapmakerJob& job) override;
  std::uint64_t reduce(RunContext& cl) override;
  MapOutputs write(const MapmakerEnd& end) override;

 protected:
  // [ground]'s maps, once the sky's maps solved some pixel, added to `out`.
  void write_ground(const MapmakerEnd& end, MapOutputs& out);
  BinnedMapmaker sky_;
  std::optional<BinnedMapmaker> ground_;
};

}  // namespace pisco::detail
