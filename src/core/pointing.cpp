#include "pisco/pointing.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include "core/detector_pointing.hpp"
#include "kernel/frame.hpp"
#include "core/text.hpp"
#include "core/thread_pool.hpp"
#include "pisco/error.hpp"

namespace pisco {
namespace {

detail::DetectorOffset kernel_offset(const Quat& q) { return detail::make_offset({q.x, q.y, q.z, q.w}); }

void set_sample(const detail::SampleFrame<double>& f, double theta, double phi, Pointing& out, std::size_t i) {
  out.theta[i] = theta;
  out.phi[i] = phi;
  out.psi[i] = detail::position_angle(f.theta_p, theta, phi);
}

void resize(Pointing& out, std::size_t n) {
  out.theta.resize(n);
  out.phi.resize(n);
  out.psi.resize(n);
}

}  // namespace

namespace detail {

void detector_pointing_range(const PointingView& b, const Quat& offset, Pointing& out, std::size_t begin,
                             std::size_t end) {
  const detail::DetectorOffset o = kernel_offset(offset);
  for (std::size_t i = begin; i < end; ++i) {
    if (!o.active) {
      out.theta[i] = b.theta[i];
      out.phi[i] = detail::wrap_phi(b.phi[i]);
      out.psi[i] = b.psi[i];
      continue;
    }
    double theta = 0.0, phi = 0.0;
    const auto f = detail::angle_sample(b.theta[i], b.phi[i], b.psi[i], o, 1.0, 0.0, theta, phi);
    set_sample(f, theta, phi, out, i);
  }
}

void detector_pointing_range(const QuatPointingView& b, const Quat& offset, Pointing& out, std::size_t begin,
                             std::size_t end) {
  const detail::DetectorOffset o = kernel_offset(offset);
  for (std::size_t i = begin; i < end; ++i) {
    const Quat& q = b.quats[i];
    double theta = 0.0, phi = 0.0;
    const auto f = detail::quat_sample({q.x, q.y, q.z, q.w}, o, 1.0, 0.0, theta, phi);
    set_sample(f, theta, phi, out, i);
  }
}

template <class View>
void detector_pointing(const View& b, const Quat& offset, Pointing& out, ThreadPool& pool) {
  resize(out, b.size());
  pool.parallel_for(b.size(), 4096, [&](std::size_t begin, std::size_t end) {
    detector_pointing_range(b, offset, out, begin, end);
  });
}

template void detector_pointing(const PointingView&, const Quat&, Pointing&, ThreadPool&);
template void detector_pointing(const QuatPointingView&, const Quat&, Pointing&, ThreadPool&);

void pointing_quats(const PointingView& a, std::vector<Quat>& out, ThreadPool& pool) {
  out.resize(a.size());
  pool.parallel_for(a.size(), 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) out[i] = quat_from_pointing(a.theta[i], a.phi[i], a.psi[i]);
  });
}

}  // namespace detail

void detector_pointing(const PointingView& b, const Quat& offset, Pointing& out) {
  resize(out, b.size());
  detail::detector_pointing_range(b, offset, out, 0, b.size());
}

void detector_pointing(const QuatPointingView& b, const Quat& offset, Pointing& out) {
  resize(out, b.size());
  detail::detector_pointing_range(b, offset, out, 0, b.size());
}

void offset_pointing(const PointingView& b, double xi, double eta, double gamma, Pointing& out) {
  detector_pointing(b, offset_quat(xi, eta, gamma), out);
}

void check_pointing(const PointingView& p, const char* origin) {
  if (p.phi.size() != p.theta.size() || p.psi.size() != p.theta.size())
    throw Error(std::string(origin) + ": theta, phi and psi have different lengths (" +
                std::to_string(p.theta.size()) + ", " + std::to_string(p.phi.size()) + ", " +
                std::to_string(p.psi.size()) + ")");
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double t = p.theta[i];
    if (!std::isfinite(t) || !std::isfinite(p.phi[i]) || !std::isfinite(p.psi[i]))
      throw Error(std::string(origin) + ": sample " + std::to_string(i) +
                  " has a non-finite theta, phi or psi");
    if (t < 0.0 || t > std::numbers::pi)
      throw Error(std::string(origin) + ": sample " + std::to_string(i) + " has theta = " +
                  std::to_string(t) + " rad, outside [0, pi]");
  }
}

void check_pointing(const QuatPointingView& p, const char* origin) {
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (const std::string problem = rotation_problem(p.quats[i]); !problem.empty())
      throw Error(std::string(origin) + ": quaternion of sample " + std::to_string(i) + " " + problem);
  }
}

}  // namespace pisco
