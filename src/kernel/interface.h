// The interface between the host and the kernels, included by both the C++ code (src/vulkan/) and
// the GLSL (src/kernel/*.comp), so that bindings, workgroup size and push constants cannot drift apart.
#ifndef PISCO_SHADER_INTERFACE_H
#define PISCO_SHADER_INTERFACE_H

// Samples per workgroup: one invocation convolves one sample.
#define PISCO_WG_SIZE 32

// Bindings. The read-only tables (0 to 4) are uniform texel buffers of R32G32B32A32_UINT texels
// carrying the bits of float32, float64 and integer values as each binding says: lavapipe fetches a
// texel for eight invocations with eight vector loads, where a storage-buffer load becomes a loop
// over the invocations with a bounds check each, and GPUs read them through the texture cache.
#define PISCO_BINDING_SKY 0        // texels, 2 per pixel: (kx, ky, kz, I - I0), (Q, U, V, 0)
#define PISCO_BINDING_SKY_LO 1     // texels, 1 per pixel: k - float(k), so that float(k) + lo = k in float64
#define PISCO_BINDING_RINGS 2      // texels, 1 per ring: z (low word, high word), first pixel, count | shifted << 31;
                                   // then 2: the monopole's weights by cap_boundary_ring (1, last, edge, belt)
#define PISCO_BINDING_WEIGHTS 3    // texels: each node's COLUMNS weights, then its neighbour's; every detector's grid
#define PISCO_BINDING_WEIGHTS64 4  // texels, 1 per node: float64 (w_I, Omega_pix B_TT / Omega~), low word first;
                                   // with PLATE 3 per node: (w_I, wn), (w_Q, w_U), (w_V, 0); and the plates' M0
#define PISCO_BINDING_POINTING 5   // storage: 4 doubles per sample: (theta, phi, psi, 0) or a quaternion (x, y, z, w);
                                   // without float64, always the quaternion
#define PISCO_BINDING_TOD 6        // storage: 1 double per sample of the chunk
#define PISCO_BINDING_COUNT 7      // storage: 1 uint per sample: pixels in its disc
#define PISCO_BINDING_PLATE 8      // storage: 1 double per sample: the plate's angle from the detector's axis;
                                   // without float64, 2: cos 2 angle, sin 2 angle
#define PISCO_BINDINGS 9
// The adjoint kernel's (adjoint.comp) two more bindings.
#define PISCO_BINDING_MAPS 9       // storage: 4 int64 per pixel (I, Q, U, V), the fixed-point sums
#define PISCO_BINDING_VALUES 10    // storage: 1 double per sample: the scaled value the sample scatters
#define PISCO_ADJOINT_BINDINGS 11

#define PISCO_FLAG_PER_SAMPLE 2u  // divide each sample by its own sum of Omega_pix B_TT / Omega~
#define PISCO_FLAG_QUATERNION 4u  // the pointing is boresight quaternions, not angles
#define PISCO_FLAG_OFFSET 8u      // the detector is off the boresight: apply offset_quat

// Specialization constant ids: one pipeline per combination in use.
#define PISCO_SPEC_RADIAL 0   // the detector's weights are a radial profile in r = sin(rho)
#define PISCO_SPEC_FLOAT64 1  // run the float64 path: I0 sum_k w_I(k) and the per-sample norm
#define PISCO_SPEC_PARTS 2    // invocations per sample (a power of two <= PISCO_WG_SIZE)
#define PISCO_SPEC_COLUMNS 3  // weights stored per node: 2 (w_I, w_Q; w_U = w_V = 0) or 4
#define PISCO_SPEC_PLATE 4    // a half-wave plate at the aperture: effective weights w M(theta) per pixel
#define PISCO_SPEC_NORMS 5    // adjoint.comp: compute each sample's normalization instead of scattering
#define PISCO_SPEC_SQUARES 6  // adjoint.comp: scatter v g^2 (the diagonal of A^T A) instead of v g
#define PISCO_SPEC_SKY_FIRST 7  // convolve.comp: the first pixel the sky tables hold (a polar copy's band)

#ifdef __cplusplus
#include <cstdint>
namespace pisco::detail::vk {
using uint = std::uint32_t;
constexpr bool is_texel_binding(uint b) {
  return b <= PISCO_BINDING_WEIGHTS64;
}
struct PushConstants {
#ifndef PISCO_F64
#define PISCO_F64 double  // the kernels' host tests define it as their float-float type
#endif
#else
layout(push_constant) uniform PushConstants {
#endif
  // PISCO_F64: a float64 number, or on devices without float64 a float-float pair (hi, lo) in its 8 bytes.
  PISCO_F64 rho_max;
  PISCO_F64 cos_rho_max;
  PISCO_F64 monopole;        // I0, subtracted from the float32 sky and added back in float64
  PISCO_F64 grid_a;          // half-width of the beam grid (= sin rho_max)
  PISCO_F64 grid_inv_step;   // 1 / node spacing
  PISCO_F64 offset_quat[4];  // the detector's offset from the boresight (x, y, z, w)
  float grid_a32;
  float grid_inv_step32;
  float cos_zeta;
  float sin_zeta;
  uint grid_n;            // nodes per axis (radial: along r)
  uint grid_offset;       // first texel of this detector's grid in the weight texels
  uint grid_offset64;     // its first node in the float64 weights
  uint nside;
  uint flags;             // PISCO_FLAG_*
  uint sample_count;      // samples in this chunk
  uint groups_x;          // workgroups along x: sample = (group.y * groups_x + group.x) * (WG / parts) + local / parts
  uint plate_offset64;    // PLATE: the first texel of the plate's M0 (8 texels, 16 float64 row by row)
#ifdef __cplusplus
};
static_assert(sizeof(PushConstants) == 120, "push constants must match the GLSL block");
}  // namespace pisco::detail::vk
#else
} pc;
#endif

#endif
