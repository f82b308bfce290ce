#!/usr/bin/env bash
# The MPI build (docs/scaling.md): configures <repo>/build-mpi with PISCO_WITH_MPI=ON (Open MPI and
# parallel HDF5, Debian's openmpi-bin, libopenmpi-dev and libhdf5-openmpi-dev, which scripts/setup.sh
# installs), builds the library, pisco-vk and the mpi tests there, and runs them (label mpi: 1, 2
# and 3 ranks against one process, a failing rank, the class_like example under 2 ranks). Called by
# .ci/run after scripts/run-tests.sh; extra arguments go to ctest.
#
# A build tree of its own: the serial HDF5 of build/ and the parallel one define the same symbols, so
# one process cannot load both, and FindHDF5 takes one per tree. The cuda backend is left out here
# (the tests run on cpu); a cluster build adds it as build/ does (-DPISCO_WITH_CUDA=ON).
#
# PISCO_SANITIZE=1 (scripts/run-sanitizers.sh sets it) builds in <repo>/build-mpi-asan with
# AddressSanitizer, UndefinedBehaviorSanitizer and float-cast-overflow instead, and runs the same tests
# there: pisco-vk under mpirun, each rank sanitized (leaks are not checked: Open MPI's own allocations
# live until exit).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build-mpi"
config=(-DCMAKE_BUILD_TYPE=Release)
if [ "${PISCO_SANITIZE:-0}" = 1 ]; then
  build="$root/build-mpi-asan"
  flags="-fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=undefined,float-cast-overflow -fno-omit-frame-pointer"
  config=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1"
          -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1" -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_C_FLAGS="$flags"
          -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined"
          -DPISCO_WITH_VULKAN=OFF -DPISCO_WITH_SIMD=OFF)  # the tests run on cpu; Highway under ASan takes minutes
  export ASAN_OPTIONS="detect_leaks=0:halt_on_error=1:allocator_may_return_null=1"
  export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
  # Open MPI's memory hooks patch the allocator's calls, which AddressSanitizer owns.
  export OMPI_MCA_memory=^patcher
fi
for tool in mpirun h5pcc; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "run-mpi-tests: $tool not found; run scripts/setup.sh (it installs openmpi-bin, libopenmpi-dev" \
         "and libhdf5-openmpi-dev)" >&2
    exit 1
  fi
done
if ! log="$(cmake -S "$root" -B "$build" -G Ninja "${config[@]}" -DPISCO_WITH_MPI=ON \
              -DPISCO_BUILD_PYTHON=OFF -DPISCO_WITH_CUDA=OFF 2>&1)"; then
  printf '%s\n' "$log" >&2
  echo "run-mpi-tests: configuring $build failed" >&2
  exit 1
fi
cmake --build "$build" -j"$(nproc)" --target pisco-vk test_mpi
export OMP_WAIT_POLICY=passive
# mpirun refuses to start as root unless told (containers, CI machines).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
exec ctest --test-dir "$build" --output-on-failure -L mpi "$@"
