#!/usr/bin/env bash
# Sets up, builds and runs the bundled quick-start end to end.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
exec "$root/build/tools/pisco-quickstart" "$@"
