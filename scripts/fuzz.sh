#!/usr/bin/env bash
# Builds the libFuzzer targets (every fuzz/fuzz_<reader>.cpp; the `fuzz` preset: clang,
# ASan+UBSan) and runs each for SECONDS on its seed corpus fuzz/corpus/<reader>/. New inputs
# go to build-fuzz/corpus/<reader>/ (the committed seeds stay as they are); a crash, sanitizer
# report, timeout or exception other than vmap::Error stops that target and fails the script,
# leaving the input as build-fuzz/<target>-crash-* (or leak-, timeout-, oom-).
# Usage: scripts/fuzz.sh [SECONDS per target, default 60] [JOBS in parallel, default 1]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
secs=${1:-60}
jobs=${2:-1}
[[ "$secs" =~ ^[0-9]+$ && "$jobs" =~ ^[1-9][0-9]*$ ]] || {
    echo "usage: scripts/fuzz.sh [SECONDS] [JOBS]" >&2
    exit 2
}

cmake --preset fuzz >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target fuzzers

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
run_one() {
    local name=$1 reader=${1#fuzz_}
    local seeds="fuzz/corpus/$reader" work="build-fuzz/corpus/$reader" log="build-fuzz/$1.log"
    [ -d "$seeds" ] || { echo "fuzz: $name: no seed corpus $seeds" >&2; return 1; }
    mkdir -p "$work"
    if ! "build-fuzz/fuzz/$name" -max_total_time="$secs" -print_final_stats=1 -timeout=10 \
        -rss_limit_mb=2048 -artifact_prefix="build-fuzz/$name-" "$work" "$seeds" >"$log" 2>&1; then
        echo "fuzz: $name: FINDING (log: $log)" >&2
        grep -E "ERROR|runtime error|terminate|Assertion|Test unit written" "$log" | head -5 >&2
        return 1
    fi
    local execs
    execs=$(awk '/stat::number_of_executed_units/ {print $2}' "$log")
    echo "fuzz: $name: ${execs:-0} executions in ${secs} s, no finding"
}

status=0
names=()
for src in fuzz/fuzz_*.cpp; do names+=("$(basename "$src" .cpp)"); done
pids=()
for name in "${names[@]}"; do
    run_one "$name" >"build-fuzz/$name.summary" 2>&1 &
    pids+=($!)
    while (($(jobs -rp | wc -l) >= jobs)); do wait -n || true; done
done
for pid in "${pids[@]}"; do wait "$pid" || status=1; done
total=0
for name in "${names[@]}"; do
    cat "build-fuzz/$name.summary"
    n=$(sed -n 's/.*: \([0-9]*\) executions.*/\1/p' "build-fuzz/$name.summary")
    total=$((total + ${n:-0}))
done
echo "fuzz: ${#names[@]} targets, $total executions in all$([ $status -eq 0 ] && echo ", no finding" || echo ", FINDINGS above")"
exit $status
