// What lets one file be both GLSL and C++ (the kernels' includes are compiled as C++ by the host
// tests, tests/glsl_to_cpp.cmake): function qualifiers, out and inout parameters, and `precise`.
// In that common subset vectors are built by constructor, swizzles are read but never assigned,
// float32 literals carry `f` and float64 literals `lf` (removed for C++), since an unsuffixed literal
// is float32 in GLSL and float64 in C++.
#ifndef PISCO_COMMON_GLSL
#define PISCO_COMMON_GLSL

#ifdef __cplusplus
#define PISCO_FN inline
#define PISCO_OUT(T) T&
#define PISCO_INOUT(T) T&
#define PISCO_PRECISE
// rings.glsl's mul_rn, a float64 product rounded by itself: GLSL's `precise` on the product, here a
// store through a volatile, which no compiler fuses with the addition it feeds (tests/CMakeLists.txt
// compiles the ring arithmetic with contraction on to hold it to that).
inline double mul_rn(double a, double b) {
  volatile double r = a * b;
  return r;
}
#else
#define PISCO_FN
#define PISCO_OUT(T) out T
#define PISCO_INOUT(T) inout T
#define PISCO_PRECISE precise
#endif

#endif
