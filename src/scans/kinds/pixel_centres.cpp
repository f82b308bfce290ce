// [scan] type = "pixel_centres": every pixel centre of NSIDE at each psi (docs/config.md, "[scan]").
#include "pisco/scan.hpp"
#include "scans/kinds/precomputed.hpp"

namespace pisco::detail {

const ScanKindEntry pixel_centres_scan_kind{
    ScanKind::pixel_centres, "pixel_centres",
    [](Table& t, ScanConfig& s) {
      s.psi = read_psi(t);
      s.nside = t.nside("nside", 64);
    },
    [](const ScanConfig& s) -> std::unique_ptr<ScanGenerator> {
      return std::make_unique<PrecomputedScan>(pixel_centre_scan(s.nside, s.psi));
    },
    untimed, known_when_made};

}  // namespace pisco::detail
