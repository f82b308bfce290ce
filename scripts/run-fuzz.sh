#!/usr/bin/env bash
# Coverage-guided fuzzing of the readers of user files (tests/fuzz; docs/validation.md, "Fuzzing the
# readers"): builds the libFuzzer targets with clang in <repo>/build-fuzz (-DPISCO_FUZZ=ON: the library
# instrumented, with AddressSanitizer and UndefinedBehaviorSanitizer), runs each target from its seed
# corpus tests/fuzz/corpus/<target>/ for a bounded time, then once over every saved input of
# tests/fuzz/regressions/<target>/. Called by .ci/run after scripts/run-sanitizers.sh; needs the packages
# scripts/setup.sh installs (clang, libclang-rt-14-dev).
#
# A finding is an input on which a reader crashes, hangs (-timeout=10), leaks, meets undefined behaviour,
# lets an exception other than pisco::Error escape, allocates 1 GiB or more at once (-malloc_limit_mb) or
# grows past 2 GiB (-rss_limit_mb). Each is run again on its own and classified by its stack
# (scripts/fuzz-classify.awk): one in PISCO-VK's code fails the run (exit status 1), naming the target,
# the input and the report; one inside CFITSIO or HDF5 (libraries that crash or loop on some corrupted
# files whatever the caller does) is reported the same way but fails the run only with
# PISCO_FUZZ_STRICT=1.
#
# Usage: scripts/run-fuzz.sh [TARGET ...]        (default: every target; names as in tests/fuzz/)
# Environment:
#   PISCO_FUZZ_SECONDS  fuzzing time per target (default 90: the 12 targets, two at a time on two cores,
#                       take about 10 minutes)
#   PISCO_FUZZ_JOBS     targets fuzzed at once (default: the number of processors)
#   PISCO_FUZZ_STRICT   1: findings inside CFITSIO or HDF5 fail the run too
#
# The committed corpus is never written: each run's new inputs go to a scratch corpus in
# build-fuzz/fuzz-run/<target>/corpus, which is listed first (libFuzzer writes into its first corpus
# directory only), and the committed seeds are read from the second. A finding's input is saved as
# build-fuzz/fuzz-run/<target>/artifacts/<kind>-<sha1>; copy it into tests/fuzz/regressions/<target>/
# under a name that says what it is, so that every later run checks it.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build-fuzz"
fuzz="$root/tests/fuzz"
seconds="${PISCO_FUZZ_SECONDS:-90}"
jobs="${PISCO_FUZZ_JOBS:-$(nproc)}"

# Each target, its longest input (bytes; the seeds are well within it) and its dictionary.
declare -A max_len=(
  [fuzz_simulation_toml]=8192 [fuzz_focal_plane_csv]=4096 [fuzz_focal_plane_toml]=4096
  [fuzz_focal_plane_hdf5]=32768 [fuzz_grasp_grd]=16384 [fuzz_grasp_cut]=16384 [fuzz_blm_fits]=32768
  [fuzz_beamsor_fits]=32768 [fuzz_sky_fits]=32768 [fuzz_pointing_hdf5]=40960 [fuzz_cl_table]=4096
  [fuzz_source_track_csv]=4096)
declare -A dict=(
  [fuzz_simulation_toml]=simulation_toml [fuzz_focal_plane_csv]=focal_plane_csv
  [fuzz_focal_plane_toml]=focal_plane_toml [fuzz_focal_plane_hdf5]=hdf5 [fuzz_grasp_grd]=grasp
  [fuzz_grasp_cut]=grasp [fuzz_blm_fits]=fits [fuzz_beamsor_fits]=fits [fuzz_sky_fits]=fits
  [fuzz_pointing_hdf5]=hdf5 [fuzz_cl_table]=cl_table
  [fuzz_source_track_csv]=source_track_csv)
all_targets=(fuzz_simulation_toml fuzz_focal_plane_csv fuzz_focal_plane_toml fuzz_focal_plane_hdf5
             fuzz_grasp_grd fuzz_grasp_cut fuzz_blm_fits fuzz_beamsor_fits fuzz_sky_fits
             fuzz_pointing_hdf5 fuzz_cl_table fuzz_source_track_csv)
targets=("$@")
((${#targets[@]})) || targets=("${all_targets[@]}")
for t in "${targets[@]}"; do
  [[ -n ${max_len[$t]:-} ]] || { echo "run-fuzz: unknown target '$t' (targets: ${all_targets[*]})" >&2; exit 2; }
done
[[ $seconds =~ ^[1-9][0-9]*$ ]] || { echo "run-fuzz: PISCO_FUZZ_SECONDS must be a positive integer" >&2; exit 2; }
[[ $jobs =~ ^[1-9][0-9]*$ ]] || { echo "run-fuzz: PISCO_FUZZ_JOBS must be a positive integer" >&2; exit 2; }

# clang and its libFuzzer runtime (Debian: clang, libclang-rt-14-dev; scripts/setup.sh installs them).
if ! command -v clang >/dev/null || ! command -v clang++ >/dev/null; then
  echo "run-fuzz: clang is not installed; run scripts/setup.sh (Debian packages clang, libclang-rt-14-dev)" >&2
  exit 1
fi
runtime="$(clang -print-resource-dir)/lib/linux/libclang_rt.fuzzer-$(uname -m).a"
if [ ! -f "$runtime" ]; then
  echo "run-fuzz: clang's libFuzzer runtime ($runtime) is missing; run scripts/setup.sh" \
       "(Debian package libclang-rt-14-dev)" >&2
  exit 1
fi

# -O1 -g1: fast enough to fuzz, with line numbers in the sanitizers' stacks.
build_start=$SECONDS
if ! log="$(CC=clang CXX=clang++ cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
              -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1" \
              -DPISCO_FUZZ=ON 2>&1)"; then
  printf '%s\n' "$log" >&2
  echo "run-fuzz: configuring $build failed (if it was configured with another compiler, remove it and retry)" >&2
  exit 1
fi
cmake --build "$build" -j"$(nproc)" --target pisco_fuzz
echo "run-fuzz: configured and built in $((SECONDS - build_start)) s"

work="$build/fuzz-run"
rm -rf "$work"
mkdir -p "$work"
export ASAN_OPTIONS="halt_on_error=1:strict_string_checks=1:allocator_may_return_null=1:detect_leaks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export LSAN_OPTIONS="suppressions=$root/tests/sanitizers/lsan.supp:print_suppressions=0"
export OMP_WAIT_POLICY=passive
# The HDF5 readers' first read in a child process (src/io/hdf5.hpp, run_isolated) gives up on a file
# the library loops on before libFuzzer's own -timeout would call it a hang of the reader.
export PISCO_HDF5_PROBE_SECONDS=5
limits=(-timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024)

# One target's fuzzing, in its own directory: the scratch corpus, the artifacts, the log, the readers'
# temporary files (TMPDIR). stdin is /dev/null, so that no input can make a reader wait on a terminal.
# -fork=1 runs the fuzzing in a child process that is restarted after a crash, a hang or an oversized
# allocation (each input saved in artifacts/), so that one finding (in CFITSIO or HDF5 as well as in
# PISCO-VK's code) does not end the target's run.
fuzz_one() {
  local t="$1" dir="$work/$1"
  mkdir -p "$dir/corpus" "$dir/artifacts" "$dir/tmp"
  local status=0
  (cd "$dir" && TMPDIR="$dir/tmp" timeout -k 10 $((seconds + 120)) "$build/tests/fuzz/$t" \
     -fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 -max_total_time="$seconds" \
     "${limits[@]}" -max_len="${max_len[$t]}" -dict="$fuzz/dict/${dict[$t]}.dict" \
     -artifact_prefix="$dir/artifacts/" "$dir/corpus" "$fuzz/corpus/$t" </dev/null >"$dir/log" 2>&1) || status=$?
  echo "$status" >"$dir/status"
}

# Runs target $1 once on input $2, its log in $3, and prints scripts/fuzz-classify.awk's verdict:
# "<where> TAB <kind> TAB <frame>", where is pisco, third-party or none.
classify() {
  local t="$1" input="$2" log="$3" dir
  dir="$(dirname "$log")"
  mkdir -p "$dir/tmp"
  (cd "$dir" && TMPDIR="$dir/tmp" timeout -k 10 120 "$build/tests/fuzz/$t" "${limits[@]}" \
     -artifact_prefix="$dir/rerun-" "$input" </dev/null >"$log" 2>&1) || true
  awk -v root="$root" -f "$root/scripts/fuzz-classify.awk" "$log"
}

echo "run-fuzz: ${#targets[@]} targets, ${seconds} s each, $jobs at a time"
start=$SECONDS
running=0
for t in "${targets[@]}"; do
  if ((running >= jobs)); then
    wait -n || true
    running=$((running - 1))
  fi
  fuzz_one "$t" &
  running=$((running + 1))
done
wait
echo "run-fuzz: fuzzing took $((SECONDS - start)) s"

# Each saved input run again on its own and classified: a finding in PISCO-VK's code fails the run; one
# in CFITSIO or HDF5 (a crash or hang inside the library on a corrupted file) is reported, and fails the
# run only with PISCO_FUZZ_STRICT=1. At most 20 inputs a target are run again (each kind of finding is
# usually saved many times over); the rest are listed.
failing=()   # "target<TAB>input<TAB>log<TAB>verdict"
reported=()
record() {  # target, input, log, verdict
  local where="${4%%$'\t'*}"
  case "$where" in
    none) ;;
    third-party) if [ "${PISCO_FUZZ_STRICT:-0}" = 1 ]; then failing+=("$1"$'\t'"$2"$'\t'"$3"$'\t'"$4")
                 else reported+=("$1"$'\t'"$2"$'\t'"$3"$'\t'"$4"); fi ;;
    *) failing+=("$1"$'\t'"$2"$'\t'"$3"$'\t'"$4") ;;
  esac
}
printf '%-24s %10s %8s %8s %8s %7s  %s\n' target executions exec/s cov ft corpus "saved inputs (oom/timeout/crash)"
for t in "${targets[@]}"; do
  dir="$work/$t"
  status="$(cat "$dir/status")"
  # The fork mode's last progress line: "#N: cov: C ft: F corp: K exec/s E oom/timeout/crash: a/b/c ...".
  last="$(grep -E '^#[0-9]+: cov:' "$dir/log" | tail -n 1 || true)"
  execs="$(sed -n 's/^#\([0-9]*\):.*/\1/p' <<<"$last")"
  cov="$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")"
  ft="$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")"
  corp="$(sed -n 's/.* corp: \([0-9]*\).*/\1/p' <<<"$last")"
  rate="$(sed -n 's/.* exec\/s \([0-9]*\).*/\1/p' <<<"$last")"
  counts="$(sed -n 's/.* oom\/timeout\/crash: \([0-9\/]*\).*/\1/p' <<<"$last")"
  printf '%-24s %10s %8s %8s %8s %7s  %s\n' "$t" "${execs:--}" "${rate:--}" "${cov:--}" "${ft:--}" "${corp:--}" \
    "${counts:--}"
  # The fork mode's parent exits with 0, or 1 after saving inputs; ending without its closing line
  # ("INFO: exiting: ...") it was killed (the time limit above) or failed itself.
  if [ "$status" != 0 ] && ! grep -q '^INFO: exiting: ' "$dir/log"; then
    failing+=("$t"$'\t'"-"$'\t'"$dir/log"$'\t'"pisco"$'\t'"the fuzzer itself ended with status $status"$'\t'"-")
  fi
  n=0
  for input in "$dir"/artifacts/*; do
    [ -f "$input" ] || continue
    n=$((n + 1))
    ((n <= 20)) || continue
    log="$dir/classify/$(basename "$input").log"
    record "$t" "$input" "$log" "$(classify "$t" "$input" "$log")"
  done
  ((n <= 20)) || echo "run-fuzz: $t: $((n - 20)) more saved inputs in $dir/artifacts not run again"
done

# The inputs of past findings (tests/fuzz/regressions/<target>/), each run once on its own.
for t in "${targets[@]}"; do
  [ -d "$fuzz/regressions/$t" ] || continue
  for input in "$fuzz/regressions/$t"/*; do
    [ -f "$input" ] || continue
    log="$work/$t/regressions/$(basename "$input").log"
    verdict="$(classify "$t" "$input" "$log")"
    case "${verdict%%$'\t'*}" in
      none) echo "run-fuzz: $t: regression input ${input#"$root"/} reads cleanly" ;;
      third-party) echo "run-fuzz: $t: regression input ${input#"$root"/} still fails inside a library:" \
                        "$(tr '\t' ' ' <<<"${verdict#*$'\t'}")" ;;
    esac
    record "$t" "$input" "$log" "$verdict"
  done
done

# One report per distinct finding (target, where, kind and frame), with every input that gave it.
report() {  # title, entries...
  local title="$1" entry key
  shift
  ((${#@})) || return 0
  echo
  echo "run-fuzz: $title"
  local -A first=() also=()
  local -a keys=()
  for entry in "$@"; do
    IFS=$'\t' read -r t input log where kind frame <<<"$entry"
    key="$t|$where|$kind|$frame"
    if [ -n "${first[$key]:-}" ]; then
      also[$key]+="    also: ${input#"$root"/}"$'\n'
    else
      first[$key]="$entry"
      keys+=("$key")
    fi
  done
  for key in "${keys[@]}"; do
    IFS=$'\t' read -r t input log where kind frame <<<"${first[$key]}"
    echo
    echo "--- $t: $where: $kind, at $frame"
    echo "    input: ${input#"$root"/}"
    printf '%s' "${also[$key]:-}"
    echo "    log:   ${log#"$root"/}"
    # The report: from the sanitizer's or libFuzzer's first error line, its first 40 lines.
    if [ -f "$log" ]; then
      sed -n '/ERROR: \(AddressSanitizer\|LeakSanitizer\|libFuzzer\)\|runtime error:\|^pisco fuzz: finding/,$p' "$log" |
        grep -v 'in fuzzer::\|in __libc_start\|in _start \|in main ' | head -n 40 |
        sed 's/ (BuildId: [0-9a-f]*)//; s/^/    /'
    fi
  done
}
report "findings in CFITSIO or HDF5 on corrupted files (reported; PISCO_FUZZ_STRICT=1 fails on them):" \
  "${reported[@]}"
report "FINDINGS in PISCO-VK's readers:" "${failing[@]}"
echo
if ((${#failing[@]})); then
  echo "run-fuzz: failed: ${#failing[@]} input(s) above; copy each new one into" \
       "tests/fuzz/regressions/<target>/ under a name that says what it is"
  exit 1
fi
echo "run-fuzz: no findings in PISCO-VK's code (${#reported[@]} input(s) failing inside CFITSIO or HDF5, above)"
