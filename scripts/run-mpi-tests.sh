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
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build-mpi"
for tool in mpirun h5pcc; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "run-mpi-tests: $tool not found; run scripts/setup.sh (it installs openmpi-bin, libopenmpi-dev" \
         "and libhdf5-openmpi-dev)" >&2
    exit 1
  fi
done
if ! log="$(cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPISCO_WITH_MPI=ON \
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
