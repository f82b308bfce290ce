#!/usr/bin/env bash
# The sanitizer build: the library, the command line and the unit, cli, robustness and simd tests built with
# AddressSanitizer and UndefinedBehaviorSanitizer in <repo>/build-asan, and those tests run there, so
# that a memory error, a leak or undefined behaviour fails the test it happens in. Called by .ci/run
# after scripts/run-tests.sh (which sets the machine up); extra arguments go to both ctest runs.
#
# - The cuda backend is left out: nvcc's device code cannot be sanitized (its host side is the same
#   as the other backends'). The vulkan backend is in, on lavapipe.
# - Tests that install the build and compile a consumer against it (consumer_find_package,
#   readme_library_example, cli_installed) are left out: a consumer built without the sanitizers
#   cannot load a sanitized library.
# - Two runs. First every test with the Vulkan driver (lavapipe) and without leak detection: memory
#   errors and undefined behaviour everywhere, the vulkan backend included. Then every test again
#   with leak detection and no Vulkan driver (the vulkan tests skip, saying why): the Vulkan loader
#   unloads its driver when an instance is destroyed, and LeakSanitizer then reports what the
#   driver's own globals held as leaked, in a library it can no longer name, which no suppression
#   can match. tests/sanitizers/lsan.supp lists the leaks of other libraries, with their reasons.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build-asan"
flags="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
if ! log="$(cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
              -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1" \
              -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_C_FLAGS="$flags" \
              -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
              -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
              -DPISCO_WITH_CUDA=OFF 2>&1)"; then
  printf '%s\n' "$log" >&2
  echo "run-sanitizers: configuring $build failed" >&2
  exit 1
fi
cmake --build "$build" -j"$(nproc)"
export OMP_WAIT_POLICY=passive
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export LSAN_OPTIONS="suppressions=$root/tests/sanitizers/lsan.supp:print_suppressions=0"
tests=(--test-dir "$build" --output-on-failure -j"$(nproc)" -L "unit|cli|robustness|simd"
       -E "consumer_find_package|readme_library_example|cli_installed")
# allocator_may_return_null: a corrupted FITS header can make CFITSIO ask for an impossible allocation,
# which the C library refuses (CFITSIO then reports a memory error, and the reader names the file);
# AddressSanitizer aborts on it unless told to refuse it the same way.
asan="halt_on_error=1:strict_string_checks=1:allocator_may_return_null=1"
echo "run-sanitizers: memory errors and undefined behaviour (vulkan on lavapipe)"
ASAN_OPTIONS="detect_leaks=0:$asan" ctest "${tests[@]}" "$@"
echo "run-sanitizers: leaks (no Vulkan driver)"
ASAN_OPTIONS="detect_leaks=1:$asan" \
  VK_DRIVER_FILES=/nonexistent.json VK_ICD_FILENAMES=/nonexistent.json ctest "${tests[@]}" "$@"
