// A vector of float64 lanes as a number type of the kernels' shared texts (the simd kernel's float64
// sums, kernel/interpolate.glsl; the simd disc walk's ring edges, kernel/rings.glsl): D, with its index
// vector L (int64 lanes) and mask MD, and +, -, * lane by lane, so that a text written for T runs
// with T = D as the reference runs it with T = double. Included by each Highway target's namespace
// (src/simd/simd_kernel.cpp, simd_disc.cpp), once per target: no include guard.
using DD = hn::ScalableTag<double>;
using DL = hn::RebindToSigned<DD>;
struct L {
  hn::Vec<DL> v;
};
struct MD {
  hn::Mask<DD> v;
};
// Trivially constructible, as double is (the texts' aggregates of D get implicit constructors).
struct D {
  hn::Vec<DD> v;
  D() = default;
  HWY_INLINE D(double x) : v(hn::Set(DD(), x)) {}                      // NOLINT: 1.0f, 0.0f in the texts
  HWY_INLINE D(hn::Vec<DD> x) : v(x) {}                                // NOLINT
  HWY_INLINE explicit D(const L& i) : v(hn::ConvertTo(DD(), i.v)) {}  // double(i)
};
HWY_INLINE D operator+(const D& a, const D& b) { return D(hn::Add(a.v, b.v)); }
HWY_INLINE D operator-(const D& a, const D& b) { return D(hn::Sub(a.v, b.v)); }
HWY_INLINE D operator*(const D& a, const D& b) { return D(hn::Mul(a.v, b.v)); }
HWY_INLINE MD operator>=(const D& a, const D& b) { return {hn::Ge(a.v, b.v)}; }
HWY_INLINE MD operator<=(const D& a, const D& b) { return {hn::Le(a.v, b.v)}; }  // false for NaN
HWY_INLINE MD operator&&(const MD& a, const MD& b) { return {hn::And(a.v, b.v)}; }
HWY_INLINE L operator+(const L& a, const L& b) { return {hn::Add(a.v, b.v)}; }
HWY_INLINE L operator+(const L& a, int b) { return {hn::Add(a.v, hn::Set(DL(), b))}; }
HWY_INLINE L operator*(const L& a, int b) { return {hn::Mul(a.v, hn::Set(DL(), b))}; }
// rings.glsl's product rounded by itself: a product of lanes is, where the file compiles expressions
// as written (simd_disc.cpp; kernel/hd.hpp's for doubles stays visible beside it).
using detail::mul_rn;
HWY_INLINE D mul_rn(const D& a, const D& b) { return a * b; }
