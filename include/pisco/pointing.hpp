// Pointing: per-detector (theta, phi, psi) arrays, the paper's input form. Views, not owners.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

namespace pisco {

struct PointingView {
  std::span<const double> theta;  // co-latitude of the beam axis, [0, pi]
  std::span<const double> phi;    // longitude
  std::span<const double> psi;    // position angle of theta' from the local meridian theta^
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
  void push_back(double t, double p, double s) { theta.push_back(t); phi.push_back(p); psi.push_back(s); }
  PointingView view() const { return {theta, phi, psi}; }
  operator PointingView() const { return view(); }
};

// The pointing of a detector at focal-plane offset (xi, eta, gamma) (see Detector) from a boresight
// pointing: the boresight's antenna frame rotated by the offset, appended to `out` (cleared first).
void offset_pointing(const PointingView& boresight, double xi, double eta, double gamma, Pointing& out);

// Throws pisco::Error naming `origin` and the first sample with a non-finite value or theta outside
// [0, pi], or arrays of different length.
void check_pointing(const PointingView& pointing, const char* origin);

}  // namespace pisco
