// Detectors and focal planes (paper section 3, eq. M_pol and copol_bolo).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace pisco {

struct Detector {
  std::string name;
  double zeta = 0.0;     // polarization angle from theta' towards phi', radians
  double epsilon = 0.0;  // cross-polar leakage: polarization efficiency is 1 - epsilon
  double gain = 1.0;     // responsivity s
  std::size_t beam = 0;  // index of this detector's beamsor in the engine's beam list
  // Offset from the boresight in focal-plane coordinates (radians): the detector's beam axis lies at
  // distance sqrt(xi^2 + eta^2) from the boresight towards atan2(eta, xi), measured from the
  // boresight's theta' axis towards phi' (azimuthal-equidistant), and its own theta' axis is the
  // boresight's carried along that great circle, then turned by gamma. Zero: on the boresight.
  double xi = 0.0, eta = 0.0, gamma = 0.0;
  bool has_offset() const noexcept { return xi != 0.0 || eta != 0.0 || gamma != 0.0; }
};

class FocalPlane {
 public:
  FocalPlane() = default;
  explicit FocalPlane(std::vector<Detector> detectors) : detectors_(std::move(detectors)) {}

  // Adds one detector; returns its index.
  std::size_t add(Detector detector);
  // Adds a PSB pair: detectors name+"a" at zeta and name+"b" at zeta - 90 deg, each with its own
  // beam. Returns the index of the first.
  std::size_t add_pair(const std::string& name, double zeta, std::size_t beam_a, std::size_t beam_b,
                       double epsilon = 0.0, double gain_a = 1.0, double gain_b = 1.0);

  const std::vector<Detector>& detectors() const noexcept { return detectors_; }
  std::size_t size() const noexcept { return detectors_.size(); }
  const Detector& operator[](std::size_t i) const { return detectors_.at(i); }

 private:
  std::vector<Detector> detectors_;
};

}  // namespace pisco
