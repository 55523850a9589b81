#!/usr/bin/env bash
# The bad-input catalogue (tests/bad_input/cases.tsv): every case runs vmap in a scratch folder
# of fixtures and must give exactly the expected exit status and first line of stderr.
#
# Usage: run.sh <path-to-vmap-binary> <source-dir> [name-filter]
# In the table, SRC in an expected line stands for the source folder. With UPDATE=1 the table is
# rewritten with what vmap does now (review the diff before committing it).
set -u
if [ $# -lt 2 ]; then
    echo "usage: $0 <path-to-vmap-binary> <source-dir> [name-filter]" >&2
    exit 2
fi
VMAP=$(realpath "$1")
SRC=$(realpath "$2")
FILTER=${3:-}
HERE="$SRC/tests/bad_input"
WORK=$(mktemp -d "${TMPDIR:-/tmp}/vmap_bad_input.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
cd "$WORK" || exit 1

# ---- fixtures --------------------------------------------------------------------------------
cp "$HERE"/fixtures/* .
cp "$SRC/scenes/cornell-empty.json" s.json
ln -s s.json link.json
ln s.json hard.json
mkdir folder folder.json folder.ply
mkfifo fifo.ply fifo.json fifo.vmap
"$VMAP" build s.json --points 400 --max-height 4 --backend cpu -o ref.vmap >/dev/null 2>&1 ||
    { echo "FAIL: cannot build the fixture ref.vmap" >&2; exit 1; }
cp ref.vmap keep.vmap
head -c 20 ref.vmap >truncated.vmap
"$VMAP" build cloud.ply --backend cpu -o cloud.vmap >/dev/null 2>&1 ||
    { echo "FAIL: cannot build the fixture cloud.vmap" >&2; exit 1; }

# ---- the cases -------------------------------------------------------------------------------
failures=0
count=0
updated="$WORK/cases.tsv.new"
: >"$updated"
while IFS=$'\t' read -r name want_rc want_line args; do
    if [[ -z "$name" || "$name" == \#* || (-n "$FILTER" && "$name" != *$FILTER*) ]]; then
        printf '%s\n' "$name${want_rc:+	$want_rc}${want_line:+	$want_line}${args:+	$args}" >>"$updated"
        continue
    fi
    count=$((count + 1))
    eval "set -- $args"
    # A case that blocks (a FIFO opened) or starts hours of work ends at the limit: rc 124.
    timeout 3 "$VMAP" "$@" >out.txt 2>err.txt </dev/null
    rc=$?
    line=$(head -n 1 err.txt | sed "s|$SRC|SRC|g; s|$WORK/||g")
    printf '%s\t%s\t%s\t%s\n' "$name" "$rc" "${line:--}" "$args" >>"$updated"
    [[ "$want_line" == "-" ]] && want_line=""
    if [[ "$rc" == "$want_rc" && "$line" == "$want_line" ]]; then
        echo "ok:   $name"
    else
        echo "FAIL: $name: vmap $args"
        echo "  expected: exit $want_rc, stderr: $want_line"
        echo "  got:      exit $rc, stderr: $line"
        failures=$((failures + 1))
    fi
    # No case may leave a temporary behind, nor change the fixtures it must not write.
    if ls -A | grep -q '\.tmp$'; then
        echo "FAIL: $name left a temporary: $(ls -A | grep '\.tmp$' | tr '\n' ' ')"
        failures=$((failures + 1))
        rm -f .*.tmp
    fi
    if ! cmp -s s.json "$SRC/scenes/cornell-empty.json" || ! cmp -s ref.vmap keep.vmap; then
        echo "FAIL: $name changed an input"
        failures=$((failures + 1))
        cp "$SRC/scenes/cornell-empty.json" s.json
        cp keep.vmap ref.vmap
    fi
done <"$HERE/cases.tsv"

if [[ "${UPDATE:-}" == 1 ]]; then
    cp "$updated" "$HERE/cases.tsv"
    echo "rewrote $HERE/cases.tsv"
fi
echo "$count cases, $failures failed"
[ "$count" -gt 0 ] && [ "$failures" -eq 0 ]
