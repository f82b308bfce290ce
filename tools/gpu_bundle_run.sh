#!/usr/bin/env bash
# The GPU checks of a bundle made by tools/gpu_bundle.sh, on the GPU machine, from the repository's
# root (copied there as gpu-bundle/run.sh):
#   gpu-bundle/run.sh [LOG_DIR]            (default: $OUT where set, else gpu-logs-DATE/)
# Unpacks the bundle into /tmp, points the programs at its libraries and at healpy-data's files, links
# the paths the tests were built with (the checkout's and healpy-data's) where the machine has none,
# then runs, each step under its own timeout and the whole within about 9 minutes (later steps are
# skipped past that): the device tests (cuda, its validation cases, the adjoint on cuda), the Table 1
# bench on cuda (first call and best of three, every Table 1 radius), the kernels' registers by
# variant against ptxas's choice (the two libraries alternated, round and elliptical beam), the bench
# on vulkan and on simd over the host's cores, the stream's host work, and class_like.toml on cuda.
# Writes LOG_DIR/summary.txt (each step's status and the benches' tables) and LOG_DIR/all.log.
set -u
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
logs=${1:-${OUT:-$root/gpu-logs-$(date +%Y%m%d-%H%M%S)}}
mkdir -p "$logs"
summary=$logs/summary.txt
all=$logs/all.log
: >"$summary"
: >"$all"
start=$SECONDS
budget=${PISCO_GPU_BUDGET_S:-540}

work=/tmp/pisco-gpu-bundle
rm -rf "$work"
mkdir -p "$work"
tar -C "$work" -xJf "$here/gpu-bundle.tar.xz"
b=$work/gpu-bundle
export LD_LIBRARY_PATH=$b/lib
export PISCO_HEALPY_DATA_DIR=$b/data
for pair in "$(cat "$b/source_dir"):$root" "$(cat "$b/healpy_data_dir"):$b/data"; do
  path=${pair%%:*} target=${pair#*:}
  if [ ! -e "$path" ]; then mkdir -p "$(dirname "$path")" && ln -s "$target" "$path"; fi
done
# NVIDIA's Vulkan driver where the loader finds none by itself.
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
pisco=$b/bin/pisco-vk
cd "$root" || exit 1

step() {  # step NAME TIMEOUT_S COMMAND...
  local name=$1 limit=$2
  shift 2
  if [ $((SECONDS - start)) -ge "$budget" ]; then
    echo "== $name: skipped (the run's ${budget} s are spent)" | tee -a "$summary"
    return
  fi
  echo "== $name: $*" | tee -a "$summary" >>"$all"
  local t0=$SECONDS rc=0
  timeout "$limit" "$@" >"$logs/step.log" 2>&1 || rc=$?
  cat "$logs/step.log" >>"$all"
  echo "   exit $rc, $((SECONDS - t0)) s" | tee -a "$summary"
  case $name in
    devices|bench*|registers*|class*) grep -v '^\s*$' "$logs/step.log" | tail -14 >>"$summary" ;;
    stream*) grep -v '^\s*$' "$logs/step.log" | tail -18 >>"$summary" ;;  # the host work, then the engine's
    test*) grep -E '^\[  (PASSED|FAILED|SKIPPED) ' "$logs/step.log" | tail -20 >>"$summary" ;;
  esac
  rm -f "$logs/step.log"
}

{
  date -u
  uname -a
  nvidia-smi || echo "nvidia-smi not found"
  echo "bundle of: $(cat "$b/commit")"
  nproc
} >>"$summary" 2>&1
step devices 60 "$pisco" devices
step test-cuda 150 "$b/bin/test_cuda"
step test-cuda-validation 120 "$b/bin/test_cuda_validation"
step test-adjoint-cuda 120 "$b/bin/test_adjoint" --gtest_filter='*cuda*'
step bench-cuda-first-call 60 "$pisco" bench -b cuda --repeat 1 --rho-max 1 5 10
step bench-cuda 150 "$pisco" bench -b cuda --repeat 3 --rho-max 5 7.5 10 15 20 25 30
for round in 1 2; do
  for lib in lib lib-ptxas; do
    step "registers-$lib-$round" 60 env "LD_LIBRARY_PATH=$b/$lib:$b/lib" "$pisco" bench -b cuda --repeat 2 --rho-max 5 10
    step "registers-elliptical-$lib-$round" 60 env "LD_LIBRARY_PATH=$b/$lib:$b/lib" "$pisco" bench -b cuda \
      --beam elliptical --repeat 2 --rho-max 5 10
  done
done
step class-like-cuda 150 "$pisco" run assets/examples/class_like.toml -b cuda --no-plots -o "$work/class_like_out"
step stream-host-work 90 "$pisco" bench --stream --repeat 3 --threads "$(nproc)"
step bench-vulkan 90 "$pisco" bench -b vulkan --repeat 2 --rho-max 5 10
step bench-simd 90 "$pisco" bench -b simd --repeat 2 --rho-max 5 10 --threads "$(nproc)"
echo "total $((SECONDS - start)) s; logs in $logs" | tee -a "$summary"
