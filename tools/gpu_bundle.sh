#!/usr/bin/env bash
# The GPU checks, built here and carried to a GPU machine that lacks this project's build packages
# (docs/cuda.md, "Running on a GPU"):
#   tools/gpu_bundle.sh [BUNDLE_DIR]      here: builds and packs (default BUNDLE_DIR: gpu-bundle/, ignored by git)
#   gpu-bundle/run.sh [LOG_DIR]           there, from the repository's root: about 8 minutes
# Two Release builds with the CUDA kernels' line information (for the profilers): build-gpu-bundle
# (pisco-vk, the cuda tests, the adjoint's tests) and build-gpu-bundle-ptxas (the library alone, its
# kernels' registers left to ptxas: -DPISCO_CUDA_REGISTERS_BY_VARIANT=OFF). The bundle holds them with
# the shared libraries ldd lists (the C library's own left out: the machine's must serve its kernel),
# the Vulkan loader, healpy-data's files and tools/gpu_bundle_run.sh, packed with xz so that the
# working tree and the bundle stay within the device tool's 64 MiB. Exit status non-zero on a failed
# build or a bundle over that size.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$root/gpu-bundle}
main=$root/build-gpu-bundle
ptxas=$root/build-gpu-bundle-ptxas
common=(-G Ninja -DCMAKE_BUILD_TYPE=Release -DPISCO_WITH_CUDA=ON -DPISCO_WITH_VULKAN=ON
        "-DCMAKE_CUDA_ARCHITECTURES=${CMAKE_CUDA_ARCHITECTURES:-80;90}" -DCMAKE_CUDA_FLAGS=-lineinfo)
tests=(test_cuda test_cuda_validation test_adjoint)

[ -f "$main/CMakeCache.txt" ] || cmake -S "$root" -B "$main" "${common[@]}" -DPISCO_BUILD_TESTS=ON
cmake --build "$main" --target pisco-vk "${tests[@]}"
[ -f "$ptxas/CMakeCache.txt" ] ||
  cmake -S "$root" -B "$ptxas" "${common[@]}" -DPISCO_BUILD_TESTS=OFF -DPISCO_CUDA_REGISTERS_BY_VARIANT=OFF
cmake --build "$ptxas" --target pisco

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
b=$stage/gpu-bundle
mkdir -p "$b/bin" "$b/lib" "$b/lib-ptxas" "$b/data"
cp "$main/tools/pisco-vk" "$b/bin/"
for t in "${tests[@]}"; do cp "$main/tests/$t" "$b/bin/"; done
cp -L "$main/src/libpisco.so.0" "$b/lib/"
cp -L "$ptxas/src/libpisco.so.0" "$b/lib-ptxas/"
# The shared libraries of the programs and the library, but glibc's own.
for f in "$b/bin/"* "$b/lib/libpisco.so.0"; do
  LD_LIBRARY_PATH=$b/lib ldd "$f" | awk '$2 == "=>" && $3 ~ /^\// { print $3 }'
done | sort -u | while read -r lib; do
  case $(basename "$lib") in
    libc.so.*|libm.so.*|libpthread.so.*|libdl.so.*|librt.so.*|libresolv.so.*|libutil.so.*|ld-linux*) ;;
    libpisco.so.*) ;;
    *) cp -L "$lib" "$b/lib/" ;;
  esac
done
# The Vulkan loader: libpisco loads it at run time (volk), so ldd does not list it.
loader=$(ldconfig -p | awk '/libvulkan\.so\.1 .*x86-64/ { print $NF; exit }')
[ -n "$loader" ] && cp -L "$loader" "$b/lib/"
cp -L "$(awk -F= '/^PISCO_HEALPY_DATA_DIR:/ { print $2 }' "$main/CMakeCache.txt")"/* "$b/data/"
# Where the tests look for their assets and for healpy-data: the paths they were built with.
echo "$root" >"$b/source_dir"
awk -F= '/^PISCO_HEALPY_DATA_DIR:/ { print $2 }' "$main/CMakeCache.txt" >"$b/healpy_data_dir"
git -C "$root" log -1 --oneline >"$b/commit"

rm -rf "$out"
mkdir -p "$out"
tar -C "$stage" -cJf "$out/gpu-bundle.tar.xz" gpu-bundle
cp "$root/tools/gpu_bundle_run.sh" "$out/run.sh"
tree_bytes=$(git -C "$root" ls-files -z | xargs -0 cat | wc -c)
bundle_bytes=$(du -cb "$out"/* | tail -1 | cut -f1)
echo "bundle: $out ($((bundle_bytes / 1048576)) MiB, the working tree $((tree_bytes / 1048576)) MiB)"
if [ $((bundle_bytes + tree_bytes)) -gt $((64 * 1048576)) ]; then
  echo "the bundle and the working tree exceed 64 MiB" >&2
  exit 1
fi
