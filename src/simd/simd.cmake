# The simd backend (docs/simd.md): the float32 kernel on the CPU's vector units, written with Google's
# Highway (Debian's libhwy-dev), which compiles it once per instruction set and picks the best the
# processor supports at run time. Built when Highway is found (its CMake package, else pkg-config
# libhwy); without it the library builds without the backend.
option(PISCO_WITH_SIMD "Build the simd backend when Highway (libhwy-dev) is found" ON)
set(PISCO_HAVE_SIMD OFF CACHE INTERNAL "The simd backend is built")
if(NOT PISCO_WITH_SIMD)
  return()
endif()

set(pisco_hwy "")
find_package(hwy CONFIG QUIET)
if(TARGET hwy::hwy)
  set(pisco_hwy hwy::hwy)
else()
  pkg_check_modules(HWY QUIET IMPORTED_TARGET libhwy)
  if(HWY_FOUND)
    set(pisco_hwy PkgConfig::HWY)
  endif()
endif()
if(NOT pisco_hwy)
  message(STATUS "simd backend: Highway not found (Debian: apt-get install libhwy-dev); building without it")
  return()
endif()
message(STATUS "simd backend: Highway ${hwy_VERSION}${HWY_VERSION}")

target_sources(pisco PRIVATE simd/simd_backend.cpp simd/simd_kernel.cpp simd/simd_disc.cpp)
target_link_libraries(pisco PRIVATE ${pisco_hwy})
target_compile_definitions(pisco PRIVATE PISCO_HAVE_SIMD)
set(PISCO_HAVE_SIMD ON CACHE INTERNAL "The simd backend is built")
# The float32 kernel lets the compiler fuse multiply-adds (the rest of the project compiles expressions
# as written, CMakeLists.txt): up to 1.07x faster on the Table 1 workload, 1.09x to 1.16x with a plate
# (BENCHMARKS.md, 2026-11-24), within float32 rounding of the unfused arithmetic; the parity bars hold
# either way.
# GCC would also turn the adjoint's copies of a few vectors of unit vectors into calls of memmove
# (simd_kernel.cpp, Scatter): 5% of its time at 5 deg.
# Under AddressSanitizer (scripts/run-sanitizers.sh) GCC's use-after-scope checks of the kernel's
# flattened functions, every small vector a scope of its own, made this one file 14 minutes of the
# sanitizer build's compilation; without them it is one minute, and every other check stays (the heap,
# the globals, the stack's bounds, undefined behaviour).
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
  set(pisco_simd_kernel_options -ffp-contract=fast -fno-tree-loop-distribute-patterns)
  if(CMAKE_CXX_FLAGS MATCHES "-fsanitize=[^ ]*address")
    list(APPEND pisco_simd_kernel_options -fno-sanitize-address-use-after-scope)
  endif()
  set_source_files_properties(simd/simd_kernel.cpp PROPERTIES COMPILE_OPTIONS "${pisco_simd_kernel_options}")
elseif(CMAKE_CXX_COMPILER_ID MATCHES "Clang")
  set_source_files_properties(simd/simd_kernel.cpp PROPERTIES COMPILE_OPTIONS "-ffp-contract=fast")
endif()
