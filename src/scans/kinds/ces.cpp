// [scan] type = "ces": constant-elevation scans from a ground site (pisco::CesScan; docs/config.md,
// "[scan]").
#include "pisco/scan.hpp"
#include "scans/scan_kind.hpp"

namespace pisco::detail {
namespace {

class Ces : public ScanGenerator {
 public:
  explicit Ces(const CesScan& scan) : scan_(scan) {}
  std::size_t samples() const override { return scan_.samples; }
  bool quaternions() const override { return false; }
  bool by_blocks() const override { return true; }
  void generate(std::size_t first, std::size_t count, Pointing& angles, std::vector<Quat>&) const override {
    scan_.generate(first, count, angles);
  }

 private:
  CesScan scan_;
};

void read(Table& t, ScanConfig& s) {
  CesScan& c = s.ces;
  c.latitude = t.number_in("latitude_deg", -22.96, -90, 90, "a latitude in [-90, 90] deg") * deg;
  c.longitude = t.number("longitude_deg", -67.79) * deg;
  const double elevation = t.number("elevation_deg", 45.0);
  if (!(elevation > 0 && elevation < 90)) t.fail("elevation_deg", "expected an elevation within (0, 90) deg, got " + Table::format(elevation));
  c.elevation = elevation * deg;
  c.az_centre = t.number("az_centre_deg", 180.0) * deg;
  c.az_throw = t.number_in("az_throw_deg", 720.0, 0, 1e9, "a non-negative azimuth throw") * deg;
  c.az_speed = t.positive("az_speed_deg_s", 1.0) * deg;
  c.sample_rate = t.positive("sample_rate_hz", 20.0);
  c.start_unix = parse_utc(t, "start", t.string("start", "2019-06-01T00:00:00Z"));
  c.samples = read_samples(t, c.sample_rate);
  c.boresight_angles.clear();
  for (double b : t.numbers("boresight_deg", {0.0})) c.boresight_angles.push_back(b * deg);
  c.boresight_period = t.positive("boresight_period_hours", 24.0, 3600);
  s.nside = t.nside("nside", 128);  // the maps' default NSIDE
  // The scan's own check, among it what float64 carries over the run (docs/formats.md, "Times, rates
  // and angles"), its fields named by their keys.
  try {
    c.check();
  } catch (const Error& e) {
    t.fail_checked(e, {{"start_unix", "start"}, {"az_speed", "az_speed_deg_s"}, {"boresight_period", "boresight_period_hours"}},
                   "constant-elevation scan: ");
  }
}

}  // namespace

const ScanKindEntry ces_scan_kind{
    ScanKind::ces, "ces", read,
    [](const ScanConfig& s) -> std::unique_ptr<ScanGenerator> { return std::make_unique<Ces>(s.ces); },
    [](const ScanConfig& s) { return s.ces.sample_rate; }, [](const ScanConfig& s) { return s.ces.samples; }};

}  // namespace pisco::detail
