// [beams.NAME] type = "sequence": a beam that changes with time (docs/changing.md), made of other
// tables' beams.
#include <cmath>
#include <string>

#include "beams/beam_kind.hpp"
#include "pisco/units.hpp"

namespace pisco::detail {
namespace {

// type = "sequence": a beam that changes with time (docs/beams.md): other beams at times; their names
// are checked once every table is read (check_sequences).
void read(Table& t, BeamConfig& b) {
  b.node_times = t.numbers("times_s", {});
  b.nodes = t.strings("beams", {});
  if (b.nodes.size() < 2) t.fail("beams", "a beam that changes with time needs two or more beams (names of [beams] tables)");
  if (b.node_times.size() != b.nodes.size())
    t.fail("times_s", "expected one time (seconds from the run's first sample) for each of the " +
                          std::to_string(b.nodes.size()) + " beams, got " + std::to_string(b.node_times.size()));
  for (std::size_t k = 0; k < b.node_times.size(); ++k) {
    if (!std::isfinite(b.node_times[k])) t.fail("times_s", "time " + std::to_string(k) + " is not finite");
    if (k > 0 && !(b.node_times[k] > b.node_times[k - 1]))
      t.fail("times_s", "time " + std::to_string(k) + " (" + Table::format(b.node_times[k]) + " s) is not after time " +
                            std::to_string(k - 1) + " (" + Table::format(b.node_times[k - 1]) +
                            " s); expected strictly ascending times");
  }
}

}  // namespace

const BeamKindEntry sequence_beam_kind{BeamKind::sequence, "sequence", read, nullptr, false, true};

}  // namespace pisco::detail
