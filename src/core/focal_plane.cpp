#include "pisco/focal_plane.hpp"

#include <numbers>

namespace pisco {

std::size_t FocalPlane::add(Detector detector) {
  detectors_.push_back(std::move(detector));
  return detectors_.size() - 1;
}

std::size_t FocalPlane::add_pair(const std::string& name, double zeta, std::size_t beam_a,
                                 std::size_t beam_b, double epsilon, double gain_a, double gain_b) {
  // Paper eq. copol_bolo: detector b's co-polarization is detector a's rotated by -90 deg.
  Detector a, b;
  a.name = name + "a";
  b.name = name + "b";
  a.zeta = zeta;
  b.zeta = zeta - std::numbers::pi / 2;
  a.epsilon = b.epsilon = epsilon;
  a.gain = gain_a;
  b.gain = gain_b;
  a.beam = beam_a;
  b.beam = beam_b;
  const std::size_t first = add(a);
  add(b);
  return first;
}

}  // namespace pisco
