// [scan] type = "satellite": a spinning, precessing spacecraft (pisco::SatelliteScan; docs/config.md,
// "[scan]"); every key is checked here so that its error names it.
#include <cmath>
#include <string>

#include "pisco/scan.hpp"
#include "scans/scan_kind.hpp"

namespace pisco::detail {
namespace {

class Satellite : public ScanGenerator {
 public:
  explicit Satellite(const SatelliteScan& scan) : scan_(scan) {}
  std::size_t samples() const override { return scan_.samples; }
  bool quaternions() const override { return true; }
  bool by_blocks() const override { return true; }
  void generate(std::size_t first, std::size_t count, Pointing&, std::vector<Quat>& quats) const override {
    scan_.generate(first, count, quats);
  }

 private:
  SatelliteScan scan_;
};

void read(Table& t, ScanConfig& s) {
  SatelliteScan& c = s.satellite;
  auto angle = [&](const std::string& key, double fallback, bool open_interval) {
    const double v = t.number(key, fallback);
    if (!std::isfinite(v) || v < 0 || v > 180 || (open_interval && (v == 0 || v == 180)))
      t.fail(key, std::string("expected an angle within ") + (open_interval ? "(0, 180)" : "[0, 180]") + " deg, got " +
                      std::to_string(v));
    return v * deg;
  };
  auto finite = [&](const std::string& key, double fallback) {
    const double v = t.number(key, fallback);
    if (!std::isfinite(v)) t.fail(key, "expected a finite number");
    return v;
  };
  c.spin_sun_angle = angle("spin_sun_angle_deg", 45.0, false);
  c.spin_boresight_angle = angle("spin_boresight_angle_deg", 50.0, true);
  c.precession_period = t.positive("precession_period_min", 192.348, 60);
  c.spin_period = t.positive("spin_period_min", 20.0, 60);
  c.sample_rate = t.positive("sample_rate_hz", 19.0);
  c.start_time = finite("start_time_s", 0.0);
  c.precession_phase = finite("precession_phase_deg", 0.0) * deg;
  c.spin_phase = finite("spin_phase_deg", 0.0) * deg;
  const std::string frame = t.choice("frame", "ecliptic", {"ecliptic", "equatorial", "galactic"});
  c.frame = frame == "ecliptic"     ? SatelliteScan::Frame::ecliptic
            : frame == "equatorial" ? SatelliteScan::Frame::equatorial
                                    : SatelliteScan::Frame::galactic;
  c.samples = read_samples(t, c.sample_rate);
  s.nside = t.nside("nside", 64);  // the maps' default NSIDE
  // The scan's own check, among it what float64 carries over the run (docs/formats.md, "Times, rates
  // and angles"), its fields named by their keys.
  try {
    c.check();
  } catch (const Error& e) {
    t.fail_checked(e, {{"start_time", "start_time_s"}, {"spin_period", "spin_period_min"},
                       {"precession_period", "precession_period_min"}},
                   "satellite scan: ");
  }
}

}  // namespace

const ScanKindEntry satellite_scan_kind{
    ScanKind::satellite, "satellite", read,
    [](const ScanConfig& s) -> std::unique_ptr<ScanGenerator> { return std::make_unique<Satellite>(s.satellite); },
    [](const ScanConfig& s) { return s.satellite.sample_rate; }, [](const ScanConfig& s) { return s.satellite.samples; }};

}  // namespace pisco::detail
