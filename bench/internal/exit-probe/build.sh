#!/usr/bin/env bash
# Builds exit_probe for sm_90 with a static CUDA runtime into .device/bin (after scripts/device.sh bundle).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
nvcc -O2 -arch=sm_90 -cudart static "$root/bench/internal/exit-probe/exit_probe.cu" -o "${1:-$root/.device/bin/exit_probe}"
