#!/usr/bin/env bash
# The sanitizer build: the library, the command line, the Python module and the unit, cli, robustness
# and simd tests built with AddressSanitizer and UndefinedBehaviorSanitizer (float-to-integer overflow
# included) in <repo>/build-asan, and those tests run there, so that a memory error, a leak or
# undefined behaviour fails the test it happens in; then the python.api tests against the sanitized
# module (its runtime preloaded into Python), and the MPI build's tests sanitized
# (scripts/run-mpi-tests.sh with PISCO_SANITIZE=1, in <repo>/build-mpi-asan). Called by .ci/run after
# scripts/run-tests.sh (which sets the machine up and makes the Python tests' environment); extra
# arguments go to the first ctest run, and without them the ground's tests run after it.
#
# - The cuda backend is left out: nvcc's device code cannot be sanitized (its host side is the same
#   as the other backends'). The vulkan backend is in, on lavapipe.
# - Tests that install the build and compile a consumer against it (consumer_find_package,
#   readme_library_example, cli_installed) are left out: a consumer built without the sanitizers
#   cannot load a sanitized library.
# - One run of every test with the Vulkan driver (lavapipe) and leak detection: memory errors,
#   undefined behaviour and leaks everywhere, the vulkan backend included. tests/sanitizers/lsan.supp
#   lists the leaks of other libraries, with their reasons. PISCO_SANITIZE_NO_VULKAN=1 runs the tests
#   without a Vulkan driver instead (the vulkan tests skip, saying why), for a driver whose own
#   globals LeakSanitizer reports as leaked once the loader has unloaded it (no suppression can name
#   a library that is no longer loaded).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build-asan"
flags="-fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=undefined,float-cast-overflow"
flags="$flags -fno-omit-frame-pointer"
# The simd backend's x86 code for AVX2 and the baseline only (src/simd/targets.hpp): each further
# instruction set is minutes of instrumented compilation, and the plain build tests them all.
flags="$flags -DPISCO_SIMD_FEW_TARGETS"
venv="$root/build/python-venv"
python_flags=(-DPISCO_BUILD_PYTHON=OFF)
if [ -x "$venv/bin/python" ]; then
  python_flags=(-DPISCO_BUILD_PYTHON=ON "-DPython_EXECUTABLE=$venv/bin/python")
  # The Python tests run in BUILD/python-venv: this tree shares build/'s (frameworks and all).
  mkdir -p "$build"
  [ -e "$build/python-venv" ] || ln -s "$venv" "$build/python-venv"
fi
if ! log="$(cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
              -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1" \
              -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_C_FLAGS="$flags" \
              -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
              -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
              -DPISCO_WITH_CUDA=OFF "${python_flags[@]}" 2>&1)"; then
  printf '%s\n' "$log" >&2
  echo "run-sanitizers: configuring $build failed" >&2
  exit 1
fi
cmake --build "$build" -j"$(nproc)"
export OMP_WAIT_POLICY=passive
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export LSAN_OPTIONS="suppressions=$root/tests/sanitizers/lsan.supp:print_suppressions=0"
# Two examples run whole are left to the plain build, each over four minutes under the sanitizers:
# Cli.DeconvolveExampleAsTheReadmeSays (assets/examples/deconvolve.toml; SimulationTest.
# DeconvolvingMapmakerTakesTheBeamMismatchOut takes the same code through a smaller run) and
# Cli.GroundExampleAsTheReadmeSays (ground_pickup.toml's 108,000 samples of 6,000-pixel discs; the
# ground's own tests, Ground.* and GroundRun.MistakesAreNamed, run here instead, below).
tests=(--test-dir "$build" --output-on-failure -j"$(nproc)" -L "unit|cli|robustness|simd"
       -E "consumer_find_package|readme_library_example|cli_installed|Cli.DeconvolveExampleAsTheReadmeSays|Cli.GroundExampleAsTheReadmeSays")
ground=(--test-dir "$build" --output-on-failure -j"$(nproc)" -R "^Ground\.|^GroundRun\.MistakesAreNamed$")
# allocator_may_return_null: a corrupted FITS header can make CFITSIO ask for an impossible allocation,
# which the C library refuses (CFITSIO then reports a memory error, and the reader names the file);
# AddressSanitizer aborts on it unless told to refuse it the same way.
asan="halt_on_error=1:strict_string_checks=1:allocator_may_return_null=1"
no_vulkan=()
if [ "${PISCO_SANITIZE_NO_VULKAN:-0}" = 1 ]; then
  echo "run-sanitizers: memory errors, undefined behaviour and leaks (no Vulkan driver)"
  no_vulkan=(VK_DRIVER_FILES=/nonexistent.json VK_ICD_FILENAMES=/nonexistent.json)
else
  echo "run-sanitizers: memory errors, undefined behaviour and leaks (vulkan on lavapipe)"
fi
env "${no_vulkan[@]}" ASAN_OPTIONS="detect_leaks=1:$asan" ctest "${tests[@]}" "$@"
# The ground's tests, unless extra arguments chose the tests.
(($#)) || env "${no_vulkan[@]}" ASAN_OPTIONS="detect_leaks=1:$asan" ctest "${ground[@]}"
if [ -x "$venv/bin/python" ]; then
  # Python itself is not sanitized: the module's runtimes are preloaded so that they come first, and
  # leaks are not checked (the interpreter keeps its objects until exit).
  echo "run-sanitizers: the Python module (python.api)"
  preload="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)"
  LD_PRELOAD="$preload" ASAN_OPTIONS="detect_leaks=0:$asan:verify_asan_link_order=0" \
    ctest --test-dir "$build" --output-on-failure -R '^python\.api$'
else
  echo "run-sanitizers: the Python module left out ($venv/bin/python not found: run scripts/run-tests.sh first)"
fi
echo "run-sanitizers: the MPI build's tests (build-mpi-asan)"
PISCO_SANITIZE=1 "$root/scripts/run-mpi-tests.sh"
