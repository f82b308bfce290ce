// Pointing in the two forms the field uses, as views (not owners): (theta, phi, psi) angle arrays,
// the paper's input form, and boresight quaternions per sample, the frameworks' (TOAST 3,
// litebird_sim). Either describes the boresight: the engine applies each detector's offset
// (pisco::Detector::offset), so a detector on the boresight sees exactly the pointing given.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "pisco/quaternion.hpp"

namespace pisco {

struct PointingView {
  std::span<const double> theta;  // co-latitude of the beam axis, [0, pi]
  std::span<const double> phi;    // longitude
  std::span<const double> psi;    // position angle of theta' from the local meridian theta^ towards phi^
  std::size_t size() const noexcept { return theta.size(); }
  PointingView subspan(std::size_t offset, std::size_t count) const {
    return {theta.subspan(offset, count), phi.subspan(offset, count), psi.subspan(offset, count)};
  }
};

// An owning (theta, phi, psi) stream, as the scan generators return.
struct Pointing {
  std::vector<double> theta, phi, psi;
  std::size_t size() const noexcept { return theta.size(); }
  void reserve(std::size_t n) { theta.reserve(n); phi.reserve(n); psi.reserve(n); }
  void clear() noexcept { theta.clear(); phi.clear(); psi.clear(); }
  void push_back(double t, double p, double s) { theta.push_back(t); phi.push_back(p); psi.push_back(s); }
  PointingView view() const { return {theta, phi, psi}; }
  operator PointingView() const { return view(); }
};

// Boresight quaternions, one per sample, scalar last (quaternion.hpp): q z^ q* is the line of sight,
// q x^ q* the boresight's theta'. Their norm must be 1 to within 1e-6; the engine renormalizes.
struct QuatPointingView {
  std::span<const Quat> quats;
  std::size_t size() const noexcept { return quats.size(); }
  QuatPointingView subspan(std::size_t offset, std::size_t count) const { return {quats.subspan(offset, count)}; }
};

// The pointing of a detector with offset `offset` (pisco::offset_quat) from a boresight pointing,
// in (theta, phi, psi), appended to `out` (cleared first): what the engine computes per sample, on the
// host, for the map-maker and the TOD files. Same arithmetic as the float64 reference.
void detector_pointing(const PointingView& boresight, const Quat& offset, Pointing& out);
void detector_pointing(const QuatPointingView& boresight, const Quat& offset, Pointing& out);
// The same from focal-plane coordinates (xi, eta, gamma): detector_pointing(b, offset_quat(...), out).
void offset_pointing(const PointingView& boresight, double xi, double eta, double gamma, Pointing& out);

// Throws pisco::Error naming `origin` and the first sample with a non-finite value or theta outside
// [0, pi], or arrays of different length.
void check_pointing(const PointingView& pointing, const char* origin);
// Throws pisco::Error naming `origin` and the first sample with a non-finite component or a norm
// further than 1e-6 from 1.
void check_pointing(const QuatPointingView& pointing, const char* origin);

}  // namespace pisco
