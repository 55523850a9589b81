#!/usr/bin/env bash
# The whole `vmap build` command, end to end (octree to saved .vmap), timed for one or more vmap
# binaries, runs interleaved (binary 1, binary 2, ..., then again) so that they see about the
# same load on a shared machine. Prints a Markdown table: per binary the median [min-max] of the
# wall and user seconds over RUNS runs, the load average before the runs, and the work counted
# (leaf pairs walked, node tests, occluder tests; from --json), and checks that every run wrote
# the same bytes. With the machine, date and commit.
# Usage: bench/build-runs.sh RUNS VMAP [VMAP...] -- [vmap build arguments]
#   e.g. bench/build-runs.sh 3 /tmp/vmap-before build-cpu/vmap -- --threads 2
#        bench/build-runs.sh 3 build-cpu/vmap -- scenes/cornell-two-models.json --max-height 8
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
runs="${1:?usage: bench/build-runs.sh RUNS VMAP [VMAP...] -- [build arguments]}"
shift
bins=()
while [[ $# -gt 0 && "$1" != "--" ]]; do bins+=("$1"); shift; done
[[ $# -gt 0 ]] && shift
[[ ${#bins[@]} -gt 0 ]] || { echo "build-runs: no vmap binary given" >&2; exit 2; }
export VMAP_DATA_DIR="${VMAP_DATA_DIR:-$root}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

for ((r = 1; r <= runs; r++)); do
    for ((b = 0; b < ${#bins[@]}; b++)); do
        cut -d' ' -f1 /proc/loadavg >>"$work/load.$b"
        /usr/bin/time -f "%e %U" -o "$work/time.$b.$r" "${bins[$b]}" build "$@" \
            -o "$work/out.$b.$r.vmap" --json >"$work/json.$b.$r" 2>"$work/err.$b.$r" ||
            { cat "$work/err.$b.$r" >&2; exit 1; }
        cat "$work/time.$b.$r" >>"$work/times.$b"
    done
done

same=yes
for f in "$work"/out.*.vmap; do cmp -s "$f" "$work/out.0.1.vmap" || same=no; done
stat() {  # column of a file of numbers: median [min-max]
    awk -v c="$2" '{ print $c }' "$1" | sort -g | awk '{ v[NR] = $1 } END {
        m = (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2
        printf "%.1f [%.1f-%.1f]", m, v[1], v[NR] }'
}
field() { sed -n "s/^ *\"$2\": \([0-9.e+]*\),*$/\1/p" "$1" | head -1; }
echo "$(nproc) cores ($(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1)), $(date -u +%F)," \
    "commit $(git -C "$root" rev-parse --short HEAD), \`vmap build $*\`, $runs runs each;" \
    "all outputs byte-identical: $same"
echo
echo "| binary | wall s | user s | load before | leaf pairs walked | node tests | occluder tests |"
echo "|---|---:|---:|---:|---:|---:|---:|"
for ((b = 0; b < ${#bins[@]}; b++)); do
    j="$work/json.$b.1"
    echo "| ${bins[$b]} | $(stat "$work/times.$b" 1) | $(stat "$work/times.$b" 2) |" \
        "$(stat "$work/load.$b" 1) | $(field "$j" leaf_pairs_walked) | $(field "$j" node_tests) |" \
        "$(field "$j" occluder_tests) |"
done
