// src/kernel/rings.glsl as C++ (tests/glsl_to_cpp.cmake) in a translation unit compiled with contraction
// into fused multiply-adds (-ffp-contract=fast -mfma, tests/CMakeLists.txt): what a shader compiler
// may do to every operation that `precise` (mul_rn) does not protect. test_kernel_host.cpp holds these
// to the reference's ring arithmetic bit for bit. Internal linkage throughout, so that no inline
// function compiled here with FMA instructions replaces one of the other translation units.
#include <cmath>

namespace contracted_rings {
namespace {
using std::floor;
using std::sqrt;
using uint = unsigned int;
const double PISCO_PI = 3.141592653589793238462643383279502884;
double pisco_cos(double x) { return std::cos(x); }
double pisco_atan2_nonneg_y(double y, double x) { return std::atan2(y, x); }
#include "rings_host.hpp"
}  // namespace

int above(int nside, double z) { return ring_above(nside, z); }
double edge_x(double z, double z0, double xa, double cos_rho) { return ring_edge_x(z, z0, xa, cos_rho); }
double edge_ysq(double z, double x) { return ring_edge_ysq(z, x); }
double bound(unsigned count, bool shifted, double phi) { return ring_bound(count, shifted, phi); }

}  // namespace contracted_rings
