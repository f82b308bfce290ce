// The registry of scan kinds (scan_kind.hpp; docs/library.md, "How to add a scan"): a new kind is a
// file in kinds/ and one line here.
#include <cmath>
#include <cstdio>

#include "scans/scan_kind.hpp"
#include "core/registry.hpp"

namespace pisco::detail {
namespace {

const ScanKindEntry* const kinds[] = {
    &pixel_centres_scan_kind,
    &random_offsets_scan_kind,
    &raster_scan_kind,
    &ces_scan_kind,
    &satellite_scan_kind,
    &pointing_file_scan_kind,
};

}  // namespace

std::span<const ScanKindEntry* const> scan_kinds() { return kinds; }

const ScanKindEntry& scan_kind(ScanKind kind) {
  if (const ScanKindEntry* k = registered_kind(scan_kinds(), kind)) return *k;
  throw Error("scan kind " + std::to_string(static_cast<int>(kind)) + " is not registered", ErrorKind::internal);
}

const ScanKindEntry* scan_kind_named(const std::string& name) { return registered_name(scan_kinds(), name); }

std::vector<double> read_psi(Table& t) {
  std::vector<double> psi;
  for (double p : t.numbers("psi_deg", {0.0, 45.0, 90.0})) psi.push_back(p * deg);
  return psi;
}

// At least one sample, at most 1e15.
std::size_t read_samples(Table& t, double sample_rate) {
  const double hours = t.positive("duration_hours", 1.0);
  const double samples = std::round(hours * 3600 * sample_rate);
  if (!(samples >= 1)) t.fail("duration_hours", "shorter than one sample at sample_rate_hz");
  if (samples > 1e15) t.fail("duration_hours", "more than 1e15 samples at sample_rate_hz");
  return static_cast<std::size_t>(samples);
}

double parse_utc(Table& t, const std::string& key, const std::string& text) {
  int y, mo, d, h, mi;
  double sec;
  char z = 0;
  // Field widths keep every integer within int; the seconds must be a number in [0, 61).
  if (std::sscanf(text.c_str(), "%4d-%2d-%2dT%2d:%2d:%lf%c", &y, &mo, &d, &h, &mi, &sec, &z) != 7 || z != 'Z' || mo < 1 ||
      mo > 12 || d < 1 || d > 31 || h < 0 || h > 23 || mi < 0 || mi > 59 || !(sec >= 0 && sec < 61))
    t.fail(key, "expected a UTC time like \"2019-06-01T00:00:00Z\", got \"" + text + "\"");
  // Days from civil (proleptic Gregorian), Howard Hinnant's algorithm.
  y -= mo <= 2;
  const int era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (mo + (mo > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  const long days = era * 146097L + static_cast<long>(doe) - 719468L;
  return days * 86400.0 + h * 3600.0 + mi * 60.0 + sec;
}

}  // namespace pisco::detail
