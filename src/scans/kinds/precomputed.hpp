// The generated test scans (pixel centres, random offsets, rasters): the whole pointing made at once,
// and read a range at a time.
#pragma once

#include "scans/scan_kind.hpp"

namespace pisco::detail {

class PrecomputedScan : public ScanGenerator {
 public:
  explicit PrecomputedScan(Pointing all) : all_(std::move(all)) {}
  std::size_t samples() const override { return all_.size(); }
  bool quaternions() const override { return false; }
  void generate(std::size_t first, std::size_t count, Pointing& angles, std::vector<Quat>&) const override {
    const PointingView v = all_.view().subspan(first, count);
    angles.theta.assign(v.theta.begin(), v.theta.end());
    angles.phi.assign(v.phi.begin(), v.phi.end());
    angles.psi.assign(v.psi.begin(), v.psi.end());
  }

 private:
  Pointing all_;
};

inline double untimed(const ScanConfig&) { return 0.0; }
inline std::size_t known_when_made(const ScanConfig&) { return 0; }

}  // namespace pisco::detail
