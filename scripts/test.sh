#!/usr/bin/env bash
# Set up (Debian packages, models), build everything, run the test suite. GPU tests (label gpu)
# report SKIPPED without a device; scripts/device.sh runs them on a GPU machine.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
cmake --preset default >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)" "$@"
