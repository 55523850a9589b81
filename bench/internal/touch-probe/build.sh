#!/usr/bin/env bash
# Builds touch_probe and write_probe (bench/internal/write-probe) as plain static-libstdc++
# programs next to their sources (git-ignored: name both in the device tool's carry); then on
# the GPU machine: bash bench/internal/write-probe/run.sh bench/internal/write-probe/write_probe
#                  bench/internal/touch-probe/touch_probe
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
for p in touch-probe/touch_probe write-probe/write_probe; do
    g++ -O2 -std=c++20 -static-libstdc++ -static-libgcc -pthread \
        "$root/bench/internal/$p.cpp" -o "$root/bench/internal/$p"
done
