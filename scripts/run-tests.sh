#!/usr/bin/env bash
# Sets up, builds and runs the test suite; extra arguments go to ctest (e.g. -L unit, -R engine).
# ctest prints its summary; the script exits with ctest's status.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"

# The Python package (docs/python.md): the python tests' virtual environment build/python-venv (TOAST,
# litebird_sim, nanobind, pytest, ... from PyPI: created once, then reused without the network) and
# the module pisco._pisco built in build/ for its Python. Where PyPI cannot be reached the package is
# not built, and its tests (label python) skip, saying why; with PISCO_REQUIRE_PEERS=1 (.ci/run) the
# run fails instead, and so does every test that would skip for want of a peer package.
venv="$root/build/python-venv"
venv_status=0
/usr/bin/python3 "$root/tests/python/python_env.py" "$venv" || venv_status=$?
if ((venv_status == 0)); then
  python_flags=(-DPISCO_BUILD_PYTHON=ON "-DPython_EXECUTABLE=$venv/bin/python")
elif [[ "${PISCO_REQUIRE_PEERS:-}" == 1 ]]; then
  # .ci/run: the frameworks and peers must be tested; a run without them fails (docs/validation.md).
  echo "run-tests: the python tests' environment $venv could not be completed (above), and PISCO_REQUIRE_PEERS=1" \
    "requires it" >&2
  exit 1
else
  python_flags=(-DPISCO_BUILD_PYTHON=OFF)
fi
if ! log="$(cmake -S "$root" -B "$root/build" "${python_flags[@]}" 2>&1)"; then
  printf '%s\n' "$log" >&2
  echo "run-tests: configuring $root/build with ${python_flags[*]} failed" >&2
  exit 1
fi
cmake --build "$root/build" -j"$(nproc)"

# libhealpix_cxx runs OpenMP threads (map2alm, alm2map); passive waiting keeps idle ones from spinning.
export OMP_WAIT_POLICY=passive
exec ctest --test-dir "$root/build" --output-on-failure -j2 "$@"
