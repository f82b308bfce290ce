// The C++ side of the per-pixel arithmetic, src/kernel/pixel.glsl (one text for every backend; the
// documentation is there and in contribution.hpp), without an include guard and without a namespace:
// contribution.hpp includes it into pisco::detail for the float64 reference and the CUDA kernels, and
// the simd backend (src/simd/simd_kernel.cpp) includes it again into each of its Highway target
// namespaces, where T is a vector of float32 lanes. Here: what GLSL has built in and C++ has not
// (vectors, dot, max, roundEven, the scalar hooks of the interpolation), the macros that make the
// functions of pixel.glsl, plate.glsl and fixed_point.glsl templates of the number type T, and the
// host-only frame builder make_frame.

template <class T>
struct Vec3 {
  T x, y, z;
};

template <class T>
struct Vec4 {
  T x, y, z, w;
};

template <class T>
PISCO_HD T dot(const Vec3<T>& a, const Vec3<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

template <class T>
PISCO_HD Vec4<T> operator*(const T& c, const Vec4<T>& v) {
  return {c * v.x, c * v.y, c * v.z, c * v.w};
}

template <class T>
PISCO_HD Vec4<T> operator+(const Vec4<T>& a, const Vec4<T>& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z, a.w + b.w};
}

template <class T>
PISCO_HD Vec4<T> operator-(const Vec4<T>& a, const Vec4<T>& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z, a.w - b.w};
}

// GLSL's roundEven for the adjoint's fixed point (fixed_point.glsl): to nearest, ties to even, in the
// default rounding mode, on the host and on a CUDA device alike.
PISCO_HD double roundEven(double x) { return ::rint(x); }

// sqrt of the argument's own precision, as GLSL's (and CUDA's device overloads): unqualified, a float
// would otherwise find the C library's sqrt(double) on the host.
PISCO_HD float sqrt(float x) { return sqrtf(x); }
PISCO_HD double sqrt(double x) { return ::sqrt(x); }

// GLSL's max(r2, 0.0): r2 where it is positive, else 0 (also for NaN).
template <class T>
PISCO_HD T max(const T& a, float b) {
  return a > T(b) ? a : T(b);
}

// The index and mask types of the number type T: int and bool for scalars (the simd backend
// specializes them for its vectors).
template <class T>
struct Lanes {
  using Index = int;
  using Mask = bool;
};

// The interpolation's hooks for scalars (src/kernel/pixel.glsl): the node below u, and the weights where
// inside. int(u) only where inside: a conversion of a NaN or of a number out of int's range is
// undefined in C++.
template <class T>
PISCO_HD int node_index(const T& u, bool inside, int top) {
  const int i = inside ? static_cast<int>(u) : 0;
  return i < 0 ? 0 : (i > top ? top : i);
}

template <class T>
PISCO_HD Vec4<T> select_weights(bool inside, const Vec4<T>& w) {
  return inside ? w : Vec4<T>{T(0), T(0), T(0), T(0)};
}

// A beam grid stored as 4 consecutive weights a node (the reference's layout), for
// interpolate_weights and interpolate_radial.
template <class T>
struct ArrayGrid {
  const T* weights;
  int n;          // nodes per axis (radial: along r)
  T a, inv_step;  // nodes at x_i = -a + i * step (radial: r_i = i * step)
};

// A node and the next: four weights each.
template <class T>
PISCO_HD void node_pair(const T* p, Vec4<T>& w, Vec4<T>& next) {
  w = {p[0], p[1], p[2], p[3]};
  next = {p[4], p[5], p[6], p[7]};
}
#if defined(__CUDA_ARCH__)
// On a CUDA device, the float32 tables' nodes as two aligned 16-byte loads (float4) rather than eight
// scalar ones: the same values. Every table starts a device allocation and a node is 16 bytes
// (src/cuda/device_data.cpp checks the alignment). The float64 tables (the monopole's and per-sample
// sums) keep scalar loads: double2 loads there cost those variants up to 20 registers and an
// occupancy step (tests/cuda/kernel_budgets.txt).
__device__ __forceinline__ void node_pair(const float* p, Vec4<float>& w, Vec4<float>& next) {
  const float4* q = reinterpret_cast<const float4*>(p);
  const float4 a = q[0], b = q[1];
  w = {a.x, a.y, a.z, a.w};
  next = {b.x, b.y, b.z, b.w};
}
#endif

template <class T>
PISCO_HD void weight_pair(const ArrayGrid<T>& g, int k, Vec4<T>& w, Vec4<T>& next) {
  node_pair(g.weights + 4 * k, w, next);
}

// A beam grid of two columns stored a node pair to four values: entry k holds (w_I, w_Q) of node k
// and of node k + 1, so that weight_pair is one 16-byte load on a CUDA device (the vulkan backend's
// COLUMNS == 2 layout; src/cuda/device_data.hpp builds it). For detectors whose w_U and w_V vanish
// (core/prepared.hpp, weight_columns): the weights' U and V come out as zeros.
template <class T>
struct IQPairGrid {
  const T* weights;
  int n;
  T a, inv_step;
};

template <class T>
PISCO_HD void weight_pair(const IQPairGrid<T>& g, int k, Vec4<T>& w, Vec4<T>& next) {
  const T* p = g.weights + 4 * k;
  w = {p[0], p[1], T(0), T(0)};
  next = {p[2], p[3], T(0), T(0)};
}
#if defined(__CUDA_ARCH__)
__device__ __forceinline__ void weight_pair(const IQPairGrid<float>& g, int k, Vec4<float>& w, Vec4<float>& next) {
  const float4 t = reinterpret_cast<const float4*>(g.weights)[k];
  w = {t.x, t.y, 0.0f, 0.0f};
  next = {t.z, t.w, 0.0f, 0.0f};
}
#endif

// The edges' curvature terms of cell (i, j), k = j n + i, after the nodes (src/kernel/grid_curvature.hpp),
// in either table's layout.
template <class G>
struct NodeTable : std::false_type {};
template <class T>
struct NodeTable<ArrayGrid<T>> : std::true_type {};
template <class T>
struct NodeTable<IQPairGrid<T>> : std::true_type {};
template <class G, class T, std::enable_if_t<NodeTable<G>::value, int> = 0>
PISCO_HD void edge_x_pair(const G& g, int /*k*/, int i, int j, Vec4<T>& ex0, Vec4<T>& ex1) {
  weight_pair(g, i * g.n + j + g.n * g.n, ex0, ex1);
}
template <class G, class T, std::enable_if_t<NodeTable<G>::value, int> = 0>
PISCO_HD void edge_y_pair(const G& g, int k, Vec4<T>& ey0, Vec4<T>& ey1) {
  weight_pair(g, k + 2 * g.n * g.n, ey0, ey1);
}

// pixel.glsl, plate.glsl and fixed_point.glsl as C++ templates of T (and of the grid type G), between
// kernel/text_begin.hpp and text_end.hpp.
#include "kernel/text_begin.hpp"
#define PISCO_TEMPLATE template <class T>
#define PISCO_TEMPLATE_GRID template <class T, class G>
#define PISCO_REAL T
#define PISCO_V3 Vec3<T>
#define PISCO_V4 Vec4<T>
#define PISCO_INDEX typename Lanes<T>::Index
#define PISCO_MASK typename Lanes<T>::Mask
#define PISCO_IN(T) const T&
#define PISCO_GRID G
#define PISCO_FRAME SampleFrame<T>
#define PISCO_GEOMETRY PixelGeometry<T>
#define PISCO_VEC3(a, b, c) \
  Vec3<T> { a, b, c }
#define PISCO_PLATE_TEMPLATE template <class T>
#define PISCO_PLATE_REAL T
#define PISCO_PLATE_V4 Vec4<T>
#define PISCO_PLATE_VEC4(a, b, c, d) \
  Vec4<T> { a, b, c, d }
using uint = unsigned int;
#include "kernel/pixel.glsl"
#include "kernel/plate.glsl"
#include "kernel/fixed_point.glsl"
#undef PISCO_TEMPLATE
#undef PISCO_TEMPLATE_GRID
#undef PISCO_REAL
#undef PISCO_V3
#undef PISCO_V4
#undef PISCO_INDEX
#undef PISCO_MASK
#undef PISCO_IN
#undef PISCO_GRID
#undef PISCO_FRAME
#undef PISCO_GEOMETRY
#undef PISCO_VEC3
#undef PISCO_PLATE_TEMPLATE
#undef PISCO_PLATE_REAL
#undef PISCO_PLATE_V4
#undef PISCO_PLATE_VEC4
#include "kernel/text_end.hpp"

// Antenna basis (docs/physics.md) from trigonometric values of the pointing and of zeta.
template <class T>
PISCO_HD SampleFrame<T> make_frame(T cos_theta, T sin_theta, T cos_phi, T sin_phi, T cos_psi,
                                   T sin_psi, T cos_zeta, T sin_zeta) {
  const Vec3<T> p{sin_theta * cos_phi, sin_theta * sin_phi, cos_theta};
  const Vec3<T> th{cos_theta * cos_phi, cos_theta * sin_phi, -sin_theta};
  const Vec3<T> ph{-sin_phi, cos_phi, T(0)};
  SampleFrame<T> f;
  f.p = p;
  f.theta_p = {cos_psi * th.x + sin_psi * ph.x, cos_psi * th.y + sin_psi * ph.y,
               cos_psi * th.z + sin_psi * ph.z};
  f.phi_p = {-sin_psi * th.x + cos_psi * ph.x, -sin_psi * th.y + cos_psi * ph.y,
             -sin_psi * th.z + cos_psi * ph.z};
  f.e_c = {cos_zeta * f.theta_p.x + sin_zeta * f.phi_p.x, cos_zeta * f.theta_p.y + sin_zeta * f.phi_p.y,
           cos_zeta * f.theta_p.z + sin_zeta * f.phi_p.z};
  return f;
}

