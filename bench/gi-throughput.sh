#!/usr/bin/env bash
# GI solver throughput of two vmap binaries (e.g. before and after a change to the GI kernels),
# with `vmap bench-gi` on one backend, runs interleaved (before, after, before, after, ...) so
# that drift of the machine shows as a difference between rounds, not between binaries. Writes
# into OUT each run's bench-gi.md/.csv (OUT/gi-LABEL-ROUND/) and log, and gi-throughput.md: per
# point count the setup and per-bounce medians of every round side by side, the ratio after /
# before of their means, and whether both did the same work (links, interactions).
# Usage: bench/gi-throughput.sh OUT VMAP_BEFORE VMAP_AFTER
#   BACKEND     cpu or cuda (default cuda)
#   GT_SCENE    scene file (default scenes/cornell-two-models.json)
#   GT_POINTS   point counts (default 40000,150000)
#   GT_RUNS     solver runs per size (bench-gi --runs, default 3); GT_BOUNCES bounces per run
#               (default 10); GT_ROUNDS rounds of (before, after) (default 2)
#   GT_TIMEOUT  seconds one bench-gi call may take (default 90; past it the call is stopped
#               and its round is missing from the table)
#   GT_ARGS     more bench-gi options (e.g. "--theta 1 --max-height 10")
#   e.g. BACKEND=cpu GT_SCENE=scenes/cornell-empty.json GT_POINTS=2000,4000 GT_RUNS=1 \
#        bench/gi-throughput.sh /tmp/git /tmp/vmap-before build-cpu/vmap
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage="usage: bench/gi-throughput.sh OUT VMAP_BEFORE VMAP_AFTER"
out="${1:?$usage}" before="${2:?$usage}" after="${3:?$usage}"
backend="${BACKEND:-cuda}"
[[ "$backend" == cpu || "$backend" == cuda ]] || { echo "gi-throughput: BACKEND=$backend: cpu or cuda" >&2; exit 2; }
for b in "$before" "$after"; do
    [[ -x "$b" ]] || { echo "gi-throughput: $b: not an executable" >&2; exit 2; }
done
export VMAP_DATA_DIR="${VMAP_DATA_DIR:-$root}"
mkdir -p "$out"
read -r -a extra <<< "${GT_ARGS:-}"
args=(bench-gi --backends "$backend" --scene "${GT_SCENE:-$root/scenes/cornell-two-models.json}"
      --points "${GT_POINTS:-40000,150000}" --runs "${GT_RUNS:-3}"
      --bounces "${GT_BOUNCES:-10}" --brute-max 0 "${extra[@]}")
rc=0
for ((r = 1; r <= ${GT_ROUNDS:-2}; r++)); do
    for label in before after; do
        bin=$before
        [[ $label == after ]] && bin=$after
        dir="$out/gi-$label-$r"
        t0=$(date +%s.%N)
        status=0
        timeout "${GT_TIMEOUT:-90}" "$bin" "${args[@]}" --out "$dir" > "$dir.log" 2>&1 || status=$?
        if [[ $status != 0 ]]; then
            rc=1
            echo "gi-throughput: $label round $r failed (rc $status), see $dir.log" >&2
            tail -3 "$dir.log" >&2
        fi
        echo "$label round $r: $(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN {printf "%.1f", b - a}') s wall" |
            tee -a "$out/gi-throughput.wall" >&2
    done
done

# The side-by-side table from every bench-gi.csv (columns: points 1, links 3, interactions 4,
# setup_cpu 6, bounce_cpu 7, setup_gpu 10, bounce_gpu 11).
col_setup=6 col_bounce=7
[[ "$backend" == cuda ]] && col_setup=10 col_bounce=11
{
    echo "GI throughput, \`vmap ${args[*]}\`, before = $before, after = $after," \
        "$(date -u '+%F %H:%M UTC'); rounds interleaved (before, after, ...)."
    head -1 "$out/gi-after-1/bench-gi.md" 2>/dev/null || true
    echo
    for f in "$out"/gi-*-*/bench-gi.csv; do
        [[ -s "$f" ]] || continue
        d=$(basename "$(dirname "$f")")
        tail -n +2 "$f" | awk -F, -v d="$d" -v s="$col_setup" -v b="$col_bounce" \
            '{split(d, p, "-"); print p[2], p[3], $1, $3, $4, $s, $b}'
    done | sort -k3,3n -k1,1r -k2,2n | awk '
        function mean(list,   n, k, v, t) { n = split(list, v, " "); t = 0
            for (k = 1; k <= n; k++) t += v[k]; return n ? t / n : 0 }
        function ratio(a, b) { return (a > 0 && b > 0) ? sprintf("%.3f", a / b) : "-" }
        function show(list,   n, k, v, t) { n = split(list, v, " "); t = ""
            for (k = 1; k <= n; k++) t = t (k > 1 ? ", " : "") sprintf("%.3g", v[k])
            return n ? t : "-" }
        { key = $3; if (!(key in seen)) { seen[key] = 1; order[++nk] = key }
          setup[$1, key] = setup[$1, key] (setup[$1, key] == "" ? "" : " ") $6
          bounce[$1, key] = bounce[$1, key] (bounce[$1, key] == "" ? "" : " ") $7
          work = $4 "/" $5
          if ((($1 SUBSEP key) in w) && w[$1, key] != work) w[$1, key] = "varies"; else w[$1, key] = work }
        END {
            print "| points | setup s before | setup s after | setup after/before |" \
                  " bounce s before | bounce s after | bounce after/before | same work |"
            print "|---:|---|---|---:|---|---|---:|---|"
            for (i = 1; i <= nk; i++) {
                k = order[i]
                sb = mean(setup["before", k]); sa = mean(setup["after", k])
                bb = mean(bounce["before", k]); ba = mean(bounce["after", k])
                same = (("before" SUBSEP k) in w) && w["before", k] == w["after", k] && w["before", k] != "varies"
                printf "| %s | %s | %s | %s | %s | %s | %s | %s |\n", k,
                    show(setup["before", k]), show(setup["after", k]),
                    ratio(sa, sb),
                    show(bounce["before", k]), show(bounce["after", k]),
                    ratio(ba, bb), (same ? "yes" : "NO")
            }
            print ""
            print "Each cell lists the rounds in order: the median over that run of every solver run" \
                  " (setup) or of every bounce of every run (bounce); the ratios are of the" \
                  " rounds'\'' means. Same work: links and interactions equal in every run of both."
        }'
    echo
    cat "$out/gi-throughput.wall"
} > "$out/gi-throughput.md"
rm -f "$out/gi-throughput.wall"
cat "$out/gi-throughput.md"
exit $rc
