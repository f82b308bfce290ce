// [scan] type = "random_offsets": pixel centres with random offsets (paper 6.3; docs/config.md, "[scan]").
#include <cstdint>

#include "pisco/scan.hpp"
#include "scans/kinds/precomputed.hpp"

namespace pisco::detail {

const ScanKindEntry random_offsets_scan_kind{
    ScanKind::random_offsets, "random_offsets",
    [](Table& t, ScanConfig& s) {
      s.psi = read_psi(t);
      s.nside = t.nside("nside", 64);
      s.f = t.number_in("f", 0.1, 0, 1, "a fraction of the pixel size in [0, 1]");
      s.symmetric = t.boolean("symmetric", false);
      s.seed = static_cast<std::uint64_t>(t.integer_in("seed", 1, 0, INT64_MAX, "a non-negative integer"));
    },
    [](const ScanConfig& s) -> std::unique_ptr<ScanGenerator> {
      return std::make_unique<PrecomputedScan>(random_offset_scan(s.nside, s.psi, s.f, s.seed, s.symmetric));
    },
    untimed, known_when_made};

}  // namespace pisco::detail
