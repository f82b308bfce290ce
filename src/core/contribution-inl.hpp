// The per-pixel formulas of contribution.hpp (the documentation is there), without an include guard
// and without a namespace: contribution.hpp includes them into pisco::detail for the float64
// reference and the CUDA kernels, and the simd backend (src/simd/simd_kernel.cpp) includes them again
// into each of its Highway target namespaces, where T is a SIMD vector of float32 lanes. One text of
// the arithmetic, compiled once per instruction set. Written with +, -, *, /, T(constant) and dot():
// anything else a formula needs must exist for the simd backend's vector type too.

template <class T>
struct Vec3 {
  T x, y, z;
};

template <class T>
PISCO_HD T dot(const Vec3<T>& a, const Vec3<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

// Per-sample quantities: the antenna basis and the beam-centre co-polarization vector.
template <class T>
struct SampleFrame {
  Vec3<T> theta_p, phi_p, p;  // theta', phi', p'
  Vec3<T> e_c;                // cos(zeta) theta' + sin(zeta) phi'
};

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

// Antenna coordinates of a sky direction and the polarization rotation 2chi between the detector's
// co-polarization there and the pixel's meridian.
//
// Everything is computed from d = k - p', small across the disc, rather than from k: in float32,
// k.theta' (|k| = 1) loses the beam coordinate to cancellation (6e-8 absolute, 1e-5 of the beam's
// slope), while d.theta' keeps it to float32's relative precision; and r^2 = x^2 + y^2 is taken as
// |d|^2 - (d.p')^2, which does not depend on psi at all, so that a round beam weighs a pixel the same
// at every boresight angle and leaks no temperature into polarization (docs/validation.md, "C"). With
// z = 1 + d.p', k.e_c = d.e_c and k.p'_perp = d.p'_perp, the expressions of the header are unchanged.
template <class T>
struct PixelGeometry {
  T x, y, z;  // antenna coordinates: (x, y) orthographic beam coordinates, z = cos(rho)
  T r2;       // x^2 + y^2, independent of psi
  T cos2chi, sin2chi;
};

template <class T>
PISCO_HD PixelGeometry<T> pixel_geometry(const SampleFrame<T>& f, const Vec3<T>& k) {
  PixelGeometry<T> g;
  const Vec3<T> d{k.x - f.p.x, k.y - f.p.y, k.z - f.p.z};
  g.x = dot(d, f.theta_p);
  g.y = dot(d, f.phi_p);
  const T dz = dot(d, f.p);  // z - 1
  g.z = T(1) + dz;
  g.r2 = dot(d, d) - dz * dz;
  const T t = dot(d, f.e_c);
  // c and s times (1 + z): the common factor cancels in cos 2chi and sin 2chi, saving a division.
  // k_z z - p'_z = d_z + k_z dz and k_x p'_y - k_y p'_x = d_x p'_y - d_y p'_x.
  const T zp = T(2) + dz;
  const T c = (k.z * t - f.e_c.z) * zp - t * (d.z + k.z * dz);
  const T s = (k.x * f.e_c.y - k.y * f.e_c.x) * zp - t * (d.x * f.p.y - d.y * f.p.x);
  const T inv = T(1) / (c * c + s * s);
  g.cos2chi = (c * c - s * s) * inv;
  g.sin2chi = T(2) * c * s * inv;
  return g;
}

// Bilinear interpolation of a 4-vector field on the square grid of n x n nodes at
// x_i = -a + i*step (x fastest), node values stored as 4 consecutive T. Outside the grid: zero.
template <class T>
PISCO_HD void interpolate_weights(const T* grid, int n, T a, T inv_step, T x, T y, T w[4]) {
  const T u = (x + a) * inv_step;
  const T v = (y + a) * inv_step;
  w[0] = w[1] = w[2] = w[3] = T(0);
  if (!(u >= T(0) && v >= T(0) && u <= T(n - 1) && v <= T(n - 1))) return;
  int i = static_cast<int>(u);
  int j = static_cast<int>(v);
  if (i > n - 2) i = n - 2;
  if (j > n - 2) j = n - 2;
  const T fu = u - T(i);
  const T fv = v - T(j);
  const T* g00 = grid + 4 * (j * n + i);
  const T* g10 = g00 + 4;
  const T* g01 = g00 + 4 * n;
  const T* g11 = g01 + 4;
  const T c00 = (T(1) - fu) * (T(1) - fv), c10 = fu * (T(1) - fv), c01 = (T(1) - fu) * fv, c11 = fu * fv;
  for (int m = 0; m < 4; ++m) w[m] = c00 * g00[m] + c10 * g10[m] + c01 * g01[m] + c11 * g11[m];
}

// Linear interpolation in r = sqrt(r2) (r2 = x^2 + y^2, PixelGeometry::r2) of a radial profile of
// 4-vectors at r = i*step: exactly invariant under rotations about the beam axis. Beyond the last
// node: zero.
template <class T>
PISCO_HD void interpolate_radial(const T* profile, int n, T inv_step, T r2, T w[4]) {
  const T u = sqrt(r2 > T(0) ? r2 : T(0)) * inv_step;
  w[0] = w[1] = w[2] = w[3] = T(0);
  if (!(u <= T(n - 1))) return;
  int i = static_cast<int>(u);
  if (i > n - 2) i = n - 2;
  const T f = u - T(i);
  const T* g0 = profile + 4 * i;
  const T* g1 = g0 + 4;
  for (int m = 0; m < 4; ++m) w[m] = (T(1) - f) * g0[m] + f * g1[m];
}

// w . Lambda(-chi) S: the detector-weighted Stokes response of one pixel (docs/physics.md, "The measurement equation").
template <class T>
PISCO_HD T stokes_response(const T w[4], T cos2chi, T sin2chi, T I, T Q, T U, T V) {
  return w[0] * I + w[1] * (Q * cos2chi + U * sin2chi) + w[2] * (U * cos2chi - Q * sin2chi) + w[3] * V;
}

// One pixel's contribution to d(q): geometry, beam interpolation, polarization rotation.
// The weights come from a 2D grid, or from a radial profile when Radial.
template <bool Radial, class T>
PISCO_HD T pixel_contribution(const SampleFrame<T>& f, const Vec3<T>& k, T I, T Q, T U, T V,
                              const T* grid, int n, T a, T inv_step) {
  const PixelGeometry<T> g = pixel_geometry(f, k);
  T w[4];
  if (Radial)
    interpolate_radial(grid, n, inv_step, g.r2, w);
  else
    interpolate_weights(grid, n, a, inv_step, g.x, g.y, w);
  return stokes_response(w, g.cos2chi, g.sin2chi, I, Q, U, V);
}

// v = w M (a row vector times M, row-major): the effective weights of a pixel behind the plate.
template <class T>
PISCO_HD void effective_weights(const T w[4], const T* m, T v[4]) {
  for (int b = 0; b < 4; ++b) v[b] = w[0] * m[b] + w[1] * m[4 + b] + w[2] * m[8 + b] + w[3] * m[12 + b];
}
