#!/usr/bin/env bash
# Installs the Debian 12 packages PISCO-VK needs (only when one is missing, so repeated runs are fast
# and need no network), then configures and builds the project in <repo>/build.
# Works from any directory, as root or as a user with sudo.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
packages=(build-essential cmake ninja-build pkg-config libhealpix-cxx-dev libcfitsio-dev
          libgtest-dev libglm-dev libtomlplusplus-dev libcli11-dev libhdf5-dev healpy-data python3-healpy python3-numpy python3-matplotlib python3-venv python3-dev
          libgsl-dev libfftw3-dev libchealpix-dev
          libvulkan-dev libvulkan-volk-dev glslang-tools mesa-vulkan-drivers vulkan-validationlayers
          libhwy-dev
          openmpi-bin libopenmpi-dev libhdf5-openmpi-dev
          # clang and its libFuzzer runtime: scripts/run-fuzz.sh
          clang libclang-rt-14-dev)

missing=()
for p in "${packages[@]}"; do
  status="$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)"
  [[ $status == "install ok installed" ]] || missing+=("$p")
done

if ((${#missing[@]})); then
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "setup: apt-get is not available (PISCO-VK's set-up expects Debian 12)." >&2
    echo "setup: install these packages or their equivalents by hand: ${missing[*]}" >&2
    exit 1
  fi
  sudo=()
  if [[ $(id -u) -ne 0 ]]; then
    if ! command -v sudo >/dev/null 2>&1; then
      echo "setup: not root and sudo is not available; as root, run:" >&2
      echo "  apt-get update && apt-get install -y ${missing[*]}" >&2
      exit 1
    fi
    sudo=(sudo)
  fi
  echo "setup: installing ${missing[*]}"
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
    "${missing[@]}"
fi

# Configure quietly, but show everything if it fails.
if ! log="$(cmake -S "$root" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE=Release 2>&1)"; then
  printf '%s\n' "$log" >&2
  echo "setup: configuring $root/build failed (if it was configured with another generator," \
       "remove $root/build and retry)" >&2
  exit 1
fi
cmake --build "$root/build" -j"$(nproc)"
