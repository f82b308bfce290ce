// The per-pixel contribution of the measurement equation (docs/physics.md, "Antenna basis, co-polarization and chi" and "The measurement equation"), written once for the float64
// reference, the CUDA kernels, the simd backend and the shaders: the formulas are in src/kernel/pixel.glsl,
// in the common subset of GLSL and C++, which contribution-inl.hpp makes C++ templates of the number
// type; this header includes that into pisco::detail and the simd backend includes it again into each
// of its instruction sets' namespaces (docs/simd.md).
//
// For one sample with antenna basis (theta', phi', p') and detector angle zeta, let
//   e_c = cos(zeta) theta' + sin(zeta) phi'         (co-polarization at the beam centre)
// and, for a sky pixel with unit vector k,
//   x = k.theta', y = k.phi', z = k.p', t = k.e_c = cos(zeta) x + sin(zeta) y.
// the Ludwig-3 co-polarization vector (docs/physics.md) E = e0 theta' + e1 phi' + e2 p' with
//   e = (cos zeta - x t/(1+z), sin zeta - y t/(1+z), -t)
// simplifies, using x theta' + y phi' = k - z p', to   E = e_c - t/(1+z) (k + p').
// Against the pixel's meridian basis scaled by sin(theta_k) (which leaves 2chi unchanged),
//   theta~ = (kz kx, kz ky, -(kx^2+ky^2)),  phi~ = (-ky, kx, 0),   and k.theta~ = k.phi~ = 0:
//   c = E.theta~ = (kz t - e_c,z) - t/(1+z) (kz z - p'_z)
//   s = E.phi~   = (kx e_c,y - ky e_c,x) - t/(1+z) (kx p'_y - ky p'_x)
//   cos 2chi = (c^2 - s^2)/(c^2 + s^2),  sin 2chi = 2 c s/(c^2 + s^2).
// No trigonometric function is evaluated per pixel. The beam weight is interpolated at the
// orthographic coordinates (x, y), which are the beamsor grid's coordinates (docs/physics.md, "Beamsors").
#pragma once

#include <cmath>
#include <type_traits>

#include "kernel/hd.hpp"

namespace pisco::detail {

#include "kernel/contribution-inl.hpp"

}  // namespace pisco::detail
