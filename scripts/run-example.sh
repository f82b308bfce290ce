#!/usr/bin/env bash
# Sets up, builds and runs the bundled quick-start end to end; arguments go to `pisco-vk run`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
exec "$root/build/tools/pisco-vk" run "$@"
