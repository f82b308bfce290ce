// [scan] type = "raster": the pixel centres around a point (paper 6.1; docs/config.md, "[scan]").
#include "pisco/scan.hpp"
#include "scans/kinds/precomputed.hpp"

namespace pisco::detail {

const ScanKindEntry raster_scan_kind{
    ScanKind::raster, "raster",
    [](Table& t, ScanConfig& s) {
      s.psi = read_psi(t);
      s.nside = t.nside("nside", 64);
      s.theta = t.number_in("theta_deg", 45.0, 0, 180, "a colatitude in [0, 180] deg") * deg;
      s.phi = t.number("phi_deg", 0.0) * deg;
      const double radius = t.positive("radius_deg", 5.0);
      if (radius >= 180) t.fail("radius_deg", "expected a radius below 180 deg, got " + Table::format(radius));
      s.radius = radius * deg;
    },
    [](const ScanConfig& s) -> std::unique_ptr<ScanGenerator> {
      return std::make_unique<PrecomputedScan>(raster_scan(s.theta, s.phi, s.radius, s.nside, s.psi));
    },
    untimed, known_when_made};

}  // namespace pisco::detail
