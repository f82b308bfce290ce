#!/usr/bin/env bash
# Everything to run on a machine with an NVIDIA GPU, as-is, from anywhere in the checkout:
#   tools/gpu_steps.sh [LOG_DIR]
# configures and builds with CUDA and Vulkan, runs the device tests (ctest -L 'cuda|vulkan', and the
# unit label, which holds the adjoint's, the poles' and the sidelobes' tests on every backend), the
# Table 1 benchmark with the adjoint on both GPU backends and on the host's simd backend over 1 to 16
# threads, the ducc0 comparison and the crossover map (tools/crossover.py),
# writing each step's output to
# LOG_DIR (default gpu-logs-DATE/) and a summary at the end. Steps that fail are reported and the
# script goes on; its exit status is non-zero if any failed.
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
logs=${1:-$root/gpu-logs-$(date +%Y%m%d-%H%M%S)}
build=${PISCO_BUILD_DIR:-$root/build-gpu}
radii="5 7.5 10 15 20 25 30"  # Table 1
mkdir -p "$logs"
logs=$(cd "$logs" && pwd)
failed=()

step() {  # step NAME COMMAND...: runs COMMAND, output to LOG_DIR/NAME.log
  local name=$1
  shift
  echo "== $name: $*" | tee -a "$logs/summary.txt"
  if "$@" >"$logs/$name.log" 2>&1; then
    echo "   ok" | tee -a "$logs/summary.txt"
  else
    echo "   FAILED (exit $?), see $logs/$name.log" | tee -a "$logs/summary.txt"
    failed+=("$name")
  fi
}

{
  date -u
  uname -a
  nvidia-smi || echo "nvidia-smi not found"
  nvcc --version || /usr/local/cuda/bin/nvcc --version || echo "nvcc not found"
  vulkaninfo --summary || echo "vulkaninfo not found"
  git -C "$root" log -1 --oneline
} >"$logs/machine.txt" 2>&1

cuda_arch=${CMAKE_CUDA_ARCHITECTURES:-80;90}
# The crossover map needs the python tests' environment (ducc0, litebird_sim), made where PyPI is
# reachable (scripts/run-tests.sh) and carried to this machine as build/python-venv.
venv=${PISCO_VENV:-$root/build/python-venv}
python_flags=()
[ -x "$venv/bin/python" ] && python_flags=(-DPISCO_BUILD_PYTHON=ON "-DPython_EXECUTABLE=$venv/bin/python")
step configure cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DPISCO_WITH_CUDA=ON -DPISCO_WITH_VULKAN=ON "-DCMAKE_CUDA_ARCHITECTURES=$cuda_arch" \
  -DPISCO_TEST_VK_VALIDATION=auto "${python_flags[@]}"
step build cmake --build "$build" -j "$(nproc)"
step devices "$build/tools/pisco-vk" devices
step ctest-gpu ctest --test-dir "$build" -L 'cuda|vulkan' --output-on-failure -V
step ctest-unit ctest --test-dir "$build" -L unit -j "$(nproc)" --output-on-failure
for backend in cuda vulkan; do
  # shellcheck disable=SC2086
  step "bench-$backend" "$build/tools/pisco-vk" bench -b "$backend" --adjoint --repeat 2 --rho-max $radii
done
# The simd adjoint over the host's threads (its tasks and windows: docs/physics.md, "Determinism").
for threads in 1 2 4 8 16; do
  [ "$threads" -le "$(nproc)" ] && step "bench-simd-$threads" "$build/tools/pisco-vk" bench -b simd --adjoint --repeat 2 \
    --rho-max 5 10 --threads "$threads"
done
step bench-cpu-5deg "$build/tools/pisco-vk" bench -b cpu --rho-max 5
# The bench's first call against its best (the polar copy made at set-up), and the streamed run's host
# work per detector-sample on one thread and on all of them.
step bench-cuda-repeat1 "$build/tools/pisco-vk" bench -b cuda --repeat 1 --rho-max 1 5 10
step bench-cuda-elliptical "$build/tools/pisco-vk" bench -b cuda --beam elliptical --repeat 2 --rho-max 5 10
step bench-stream "$build/tools/pisco-vk" bench --stream --repeat 3
# The kernels' registers by variant (convolve.cu's min_blocks) against ptxas's own choice, in one run:
# a second build of the command line with -DPISCO_CUDA_REGISTERS_BY_VARIANT=OFF, the two alternated
# (docs/cuda.md, "Budgets").
step configure-ptxas cmake -S "$root" -B "$build-ptxas" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DPISCO_WITH_CUDA=ON -DPISCO_WITH_VULKAN=OFF -DPISCO_BUILD_TESTS=OFF "-DCMAKE_CUDA_ARCHITECTURES=$cuda_arch" \
  -DPISCO_CUDA_REGISTERS_BY_VARIANT=OFF
step build-ptxas cmake --build "$build-ptxas" -j "$(nproc)" --target pisco-vk
for round in 1 2; do
  for b in "$build" "$build-ptxas"; do
    step "registers-$round-$(basename "$b")" "$b/tools/pisco-vk" bench -b cuda --repeat 2 --rho-max 5 10
    step "registers-elliptical-$round-$(basename "$b")" "$b/tools/pisco-vk" bench -b cuda --beam elliptical \
      --repeat 2 --rho-max 5 10
  done
done
# shellcheck disable=SC2086
step ducc0 python3 "$root/tools/ducc0_compare.py" --pisco "$build/tools/pisco-vk" -b cuda --rho-max $radii

if [ ${#python_flags[@]} -gt 0 ]; then
  step crossover env PYTHONPATH="$build/python" "$venv/bin/python" "$root/tools/crossover.py" --out "$logs/crossover"
else
  echo "== crossover: skipped ($venv/bin/python not found: run scripts/run-tests.sh where PyPI is reachable)" |
    tee -a "$logs/summary.txt"
fi

echo | tee -a "$logs/summary.txt"
for f in bench-cuda bench-cuda-repeat1 bench-cuda-elliptical bench-stream bench-vulkan bench-simd-1 bench-simd-2 bench-simd-4 bench-simd-8 bench-simd-16 ducc0 \
  registers-{,elliptical-}{1,2}-"$(basename "$build")" registers-{,elliptical-}{1,2}-"$(basename "$build")-ptxas"; do
  [ -f "$logs/$f.log" ] && { echo "--- $f"; cat "$logs/$f.log"; } >>"$logs/summary.txt"
done
echo "logs in $logs"
if [ ${#failed[@]} -gt 0 ]; then
  echo "failed steps: ${failed[*]}"
  exit 1
fi
echo "all steps passed"
