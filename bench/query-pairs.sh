#!/usr/bin/env bash
# Batch point-pair queries from the CLI, end to end (process start, .vmap load and checksum,
# pairs file read, answers written): `vmap query MAP --pairs FILE`, text pairs to text answers,
# and .npy pairs to an .npy of answers. Prints a Markdown table of wall and CPU (user + sys)
# seconds, median and range over RUNS runs after one warm-up, with the machine, date and commit.
# Usage: bench/query-pairs.sh [MAP] [PAIRS] [RUNS] [VMAP]
#   defaults: out/cornell-bunny.vmap (scripts/main.sh makes it), 1000000, 5, build/vmap
#   (build-cpu/vmap when build/ has none). The .npy row needs python3 with numpy.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
map="${1:-$root/out/cornell-bunny.vmap}"
n="${2:-1000000}"
runs="${3:-5}"
vmap="${4:-}"
[[ -z "$vmap" ]] && { vmap="$root/build/vmap"; [[ -x "$vmap" ]] || vmap="$root/build-cpu/vmap"; }
[[ -f "$map" ]] || { echo "query-pairs: no $map (run scripts/main.sh, or give a .vmap)" >&2; exit 1; }
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

points=$("$vmap" info "$map" --json | sed -n 's/^ *"points": \([0-9]*\),*$/\1/p')
awk -v n="$n" -v p="$points" 'BEGIN { srand(1); for (k = 0; k < n; k++)
    printf "%d %d\n", int(rand() * p), int(rand() * p) }' >"$work/pairs.txt"
have_npy=0
py=python3
[[ -x /usr/bin/python3 ]] && py=/usr/bin/python3  # Debian's, where python3-numpy is
if "$py" -c 'import numpy' 2>/dev/null; then
    "$py" -c "import numpy as np; np.save('$work/pairs.npy', np.loadtxt('$work/pairs.txt', dtype=np.int64).reshape(-1, 2))"
    have_npy=1
fi

# time_runs LABEL COUNT CMD...: one warm-up, then RUNS timed runs; prints a table row.
TIMEFORMAT="%R %U %S"
time_runs() {
    local label=$1 count=$2
    shift 2
    "$@" >/dev/null 2>&1
    : >"$work/t"
    for ((r = 0; r < runs; r++)); do { time "$@" >/dev/null 2>&1; } 2>>"$work/t"; done
    awk -v label="$label" -v n="$count" '
        { wall[NR] = $1; cpu[NR] = $2 + $3 }
        function median(a, m,   i, j, t, b) { for (i = 1; i <= m; i++) b[i] = a[i]
            for (i = 1; i <= m; i++) for (j = i + 1; j <= m; j++) if (b[j] < b[i]) { t = b[i]; b[i] = b[j]; b[j] = t }
            lo = b[1]; hi = b[m]; return (m % 2) ? b[(m + 1) / 2] : (b[m / 2] + b[m / 2 + 1]) / 2 }
        END { w = median(wall, NR); wl = lo; wh = hi; c = median(cpu, NR)
              printf "| %s | %d | %.2f (%.2f-%.2f) | %.2f (%.2f-%.2f) | %.2g |\n", label, n, w, wl, wh, c, lo, hi, n / w }' "$work/t"
}

echo "Batch queries: $map ($points points, $(stat -c %s "$map") bytes), $n pairs, $runs runs"
echo "machine: $(nproc) cores, $(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1); load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "date: $(date -u +%Y-%m-%dT%H:%MZ); commit: $("$vmap" --version)"
echo
echo "| input -> output | pairs | wall s, median (range) | CPU s (user+sys), median (range) | pairs/s (wall) |"
echo "|---|---|---|---|---|"
time_runs "text -> text (stdout)" "$n" "$vmap" query "$map" --pairs "$work/pairs.txt"
time_runs "text -> .npy" "$n" "$vmap" query "$map" --pairs "$work/pairs.txt" --out "$work/a.npy"
if ((have_npy)); then
    time_runs ".npy -> .npy" "$n" "$vmap" query "$map" --pairs "$work/pairs.npy" --out "$work/a.npy"
fi
time_runs "one pair (load alone)" 1 "$vmap" query "$map" --pair 0 1
