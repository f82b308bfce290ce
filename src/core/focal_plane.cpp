#include "pisco/focal_plane.hpp"

#include <cmath>
#include <numbers>
#include <unordered_map>

#include "core/text.hpp"
#include "pisco/error.hpp"

namespace pisco {

std::size_t FocalPlane::add(Detector detector) {
  detectors_.push_back(std::move(detector));
  return detectors_.size() - 1;
}

std::size_t FocalPlane::add_pair(const std::string& name, double zeta, std::size_t beam_a,
                                 std::size_t beam_b, double epsilon, double gain_a, double gain_b) {
  // A pair (docs/config.md, focal_plane.pairs): detector b's co-polarization is detector a's rotated by -90 deg.
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

void check_focal_plane(const FocalPlane& focal_plane, std::size_t beams) {
  using detail::number_text;
  if (focal_plane.size() == 0) throw Error("focal plane: no detectors");
  std::unordered_map<std::string, std::size_t> seen;
  for (std::size_t i = 0; i < focal_plane.size(); ++i) {
    const Detector& d = focal_plane[i];
    if (d.name.empty())
      throw Error("focal plane: detector " + std::to_string(i) + " has an empty name (expected unique names)");
    const auto [it, added] = seen.emplace(d.name, i);
    if (!added)
      throw Error("focal plane: detectors " + std::to_string(it->second) + " and " + std::to_string(i) +
                  " are both named '" + d.name + "' (expected unique detector names)");
    const std::string who = "detector '" + d.name + "'";
    if (!(std::isfinite(d.gain) && d.gain > 0.0))
      throw Error(who + ": gain = " + number_text(d.gain) + " (its responsivity) must be positive and finite");
    if (!(d.epsilon >= 0.0 && d.epsilon <= 1.0))
      throw Error(who + ": epsilon = " + number_text(d.epsilon) + " (cross-polar leakage) is outside [0, 1]");
    if (!std::isfinite(d.zeta)) throw Error(who + ": zeta = " + number_text(d.zeta) + " is not finite");
    const Quat& o = d.offset;
    if (const std::string problem = rotation_problem(o); !problem.empty())
      throw Error(who + ": the offset quaternion (" + number_text(o.x, 12) + ", " + number_text(o.y, 12) + ", " +
                  number_text(o.z, 12) + ", " + number_text(o.w, 12) + ") " + problem);
    if (d.beam >= beams)
      throw Error(who + ": beam index " + std::to_string(d.beam) + " but only " + std::to_string(beams) +
                  " beamsors were given");
    if (d.hwp) d.hwp->check(who);
    if (d.beam_sequence.size() == 1)
      throw Error(who + ": its beam_sequence has one node; a beam that changes with time needs two or more (a fixed "
                  "beam is `beam`)");
    for (std::size_t k = 0; k < d.beam_sequence.size(); ++k) {
      const BeamNode& n = d.beam_sequence[k];
      const std::string node = who + ": beam_sequence node " + std::to_string(k);
      if (!std::isfinite(n.time)) throw Error(node + ": time = " + number_text(n.time) + " is not finite");
      if (k > 0 && !(n.time > d.beam_sequence[k - 1].time))
        throw Error(node + ": time = " + number_text(n.time, 12) + " s is not after node " + std::to_string(k - 1) +
                    "'s " + number_text(d.beam_sequence[k - 1].time, 12) + " s (expected strictly ascending times)");
      if (n.beam >= beams)
        throw Error(node + ": beam index " + std::to_string(n.beam) + " but only " + std::to_string(beams) +
                    " beamsors were given");
    }
    if (const auto& p = d.plate_beams) {
      if (d.hwp)
        throw Error(who + ": has both plate_beams (beams with the plate in them) and a half-wave plate (hwp), which "
                          "would count the plate twice; give one");
      if (!d.beam_sequence.empty())
        throw Error(who + ": has both plate_beams and a beam_sequence; a detector's beam changes with one of them");
      if (p->beams.size() < 2)
        throw Error(who + ": plate_beams has " + std::to_string(p->beams.size()) +
                    " beams; a beam that turns with the plate needs two or more (a fixed beam is `beam`)");
      if (!(std::isfinite(p->period) && p->period > 0))
        throw Error(who + ": plate_beams period = " + number_text(p->period) +
                    " rad; expected a positive period (pi for a half-wave plate)");
      if (!std::isfinite(p->gamma)) throw Error(who + ": plate_beams gamma = " + number_text(p->gamma) + " is not finite");
      if (!(std::isfinite(p->omega) && p->omega >= 0))
        throw Error(who + ": plate_beams omega = " + number_text(p->omega) +
                    " sr; expected 0 (their mean Omega~) or the beam's solid angle without the plate");
      for (std::size_t k = 0; k < p->beams.size(); ++k)
        if (p->beams[k] >= beams)
          throw Error(who + ": plate_beams beam " + std::to_string(k) + ": index " + std::to_string(p->beams[k]) +
                      " but only " + std::to_string(beams) + " beamsors were given");
    }
  }
}

}  // namespace pisco
