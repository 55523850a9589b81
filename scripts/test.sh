#!/usr/bin/env bash
# Set up (Debian packages, models), build everything, run the test suite; then the suite again
# under ASan+UBSan, and a short smoke run of every fuzz target. GPU tests (label gpu) report
# SKIPPED without a device; scripts/device.sh runs them on a GPU machine.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
cmake --preset default >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)" "$@"

# The same suite built with AddressSanitizer and UBSan (the debug preset; UB aborts the test).
# Not the package test (a consumer built without the sanitizers cannot link the instrumented
# library) nor the browser test (chromium under a slowed server proves nothing more).
cmake --preset debug >/dev/null
cmake --build build-debug -j"$(nproc)"
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
    ctest --test-dir build-debug --output-on-failure -j"$(nproc)" -E '^Package\.' -LE browser "$@"

# Every libFuzzer target (fuzz/fuzz_*.cpp) for a short smoke run on its seed corpus.
scripts/fuzz.sh "${VMAP_FUZZ_SMOKE_SECONDS:-20}" "$(nproc)"
