// The vulkan kernel's per-sample frame (src/kernel/frame.glsl, compiled here as C++ from the shader
// source itself, with the shaders' own sine, cosine and arctangent) against src/kernel/frame.hpp, the
// same text with the C library's, which the float64 reference and the CUDA kernel run: boresight
// angles on and off the boresight, and boresight quaternions composed with offsets. Where no sine,
// cosine or arctangent enters (a quaternion's basis), the two builds give the same bits.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "kernel/frame.hpp"
#include "pisco/quaternion.hpp"

// The few GLSL vector types frame.glsl uses.
namespace glsl {
using std::floor;
using std::sqrt;
struct dvec3 {
  double x, y, z;
  dvec3() = default;
  dvec3(double a, double b, double c) : x(a), y(b), z(c) {}
};
struct dvec4 {
  double x, y, z, w;
  dvec4() = default;
  dvec4(double a, double b, double c, double d) : x(a), y(b), z(c), w(d) {}
};
#include "frame_host.hpp"  // src/kernel/frame.glsl (with fp64.glsl)
}  // namespace glsl

namespace {

constexpr double pi = std::numbers::pi;
using pisco::detail::Vec3;

double gap(const glsl::dvec3& a, const Vec3<double>& b) { return std::hypot(a.x - b.x, a.y - b.y, a.z - b.z); }

struct Worst {
  double basis = 0, theta = 0, phi = 0;
  double quaternion_basis = 0;  // no trigonometry: must be 0
};

void compare(bool quaternion, const glsl::dvec4& b, const pisco::Quat& offset, Worst& w) {
  const auto o = pisco::detail::make_offset({offset.x, offset.y, offset.z, offset.w});
  double theta = 0, phi = 0;
  const auto f = quaternion ? pisco::detail::quat_sample({b.x, b.y, b.z, b.w}, o, 1.0, 0.0, theta, phi)
                            : pisco::detail::angle_sample(b.x, b.y, b.z, o, 1.0, 0.0, theta, phi);
  glsl::dvec3 tp, pp, p;
  double gt = 0, gp = 0;
  glsl::pisco_sample_frame(quaternion, o.active, b, glsl::dvec4(offset.x, offset.y, offset.z, offset.w), tp, pp, p, gt,
                           gp);
  const double basis = std::max({gap(tp, f.theta_p), gap(pp, f.phi_p), gap(p, f.p)});
  w.basis = std::max(w.basis, basis);
  if (quaternion) w.quaternion_basis = std::max(w.quaternion_basis, basis);
  w.theta = std::max(w.theta, std::abs(gt - theta));
  w.phi = std::max(w.phi, std::abs(std::remainder(gp - phi, 2 * pi)) * std::sin(theta));
  EXPECT_GE(gp, 0.0);
  EXPECT_LT(gp, 2 * pi);
}

TEST(KernelFrame, ShaderFrameEqualsReference) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  const pisco::Quat offsets[] = {pisco::Quat{}, pisco::offset_quat(0.05, -0.02, 0.7),
                                 pisco::offset_quat(-0.2, 0.15, -2.9)};
  Worst w;
  for (int i = 0; i < 20000; ++i) {
    const double t = i % 10 == 0 ? u(rng) * 0.02 : std::acos(1 - 2 * u(rng));  // some near the pole
    const double p = 2 * pi * u(rng), s = 2 * pi * u(rng) - pi;
    const pisco::Quat q = pisco::quat_from_pointing(t, p, s);
    for (const pisco::Quat& o : offsets) {
      compare(false, glsl::dvec4(t, p, s, 0.0), o, w);
      compare(true, glsl::dvec4(q.x, q.y, q.z, q.w), o, w);
    }
  }
  std::cout << "frame.glsl vs frame.hpp: basis " << w.basis << ", theta " << w.theta << " rad, phi (on the sky) "
            << w.phi << " rad; quaternions' basis " << w.quaternion_basis << "\n";
  // The two differ only by the kernels' own sine, cosine and arctangent (within 2 ulp of the C library).
  EXPECT_LT(w.basis, 1e-15);
  EXPECT_LT(w.theta, 1e-15);
  EXPECT_LT(w.phi, 1e-15);
  EXPECT_EQ(w.quaternion_basis, 0.0);
}

}  // namespace
