#!/usr/bin/env bash
# Sets up, builds and runs the test suite; extra arguments go to ctest (e.g. -L unit, -R engine).
# ctest prints its summary; the script exits with ctest's status.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
# libhealpix_cxx runs OpenMP threads (map2alm, alm2map); passive waiting keeps idle ones from spinning.
export OMP_WAIT_POLICY=passive
exec ctest --test-dir "$root/build" --output-on-failure -j2 "$@"
