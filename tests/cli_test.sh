#!/usr/bin/env bash
# The vmap command-line tool end to end: summaries, exit codes (0 success, 1 input error,
# 2 usage error), one-line error messages that name the file, and no half-written files.
#
# Usage: cli_test.sh <path-to-vmap-binary> <source-dir>
# Runs every check, prints "ok:" or "FAIL:" for each, and exits non-zero if any failed.
set -u

if [ $# -ne 2 ]; then
    echo "usage: $0 <path-to-vmap-binary> <source-dir>" >&2
    exit 2
fi
VMAP=$(realpath "$1")
SRC=$(realpath "$2")
DATA="$SRC/tests/data/cli"
SCENE="$SRC/scenes/cornell-empty.json"
[ -x "$VMAP" ] || { echo "FAIL: $VMAP is not an executable" >&2; exit 1; }
[ -f "$SCENE" ] || { echo "FAIL: $SCENE is missing" >&2; exit 1; }

WORK=$(mktemp -d "${TMPDIR:-/tmp}/vmap_cli_test.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
cd "$WORK" || exit 1

failures=0
fail() {
    echo "FAIL: $*"
    failures=$((failures + 1))
}
ok() { echo "ok:   $*"; }

# run ARGS...: runs vmap, leaving stdout in out.txt, stderr in err.txt and the status in $rc.
rc=0
run() {
    "$VMAP" "$@" >out.txt 2>err.txt
    rc=$?
}
show() {
    echo "  command: vmap $*"
    echo "  exit status: $rc"
    sed 's/^/  stdout: /' out.txt | head -20
    sed 's/^/  stderr: /' err.txt | head -20
}

# expect_ok NAME ARGS...: exit status 0 and nothing that looks like an error on stderr.
expect_ok() {
    local name=$1
    shift
    run "$@"
    if [ "$rc" -ne 0 ]; then
        fail "$name: exit status $rc, expected 0"
        show "$@"
        return 1
    fi
    if grep -qi 'error' err.txt; then
        fail "$name: succeeded but printed an error"
        show "$@"
        return 1
    fi
    ok "$name"
}

# expect_stdout NAME REGEX: the last command's stdout has a line matching REGEX (grep -E).
expect_stdout() {
    if grep -Eq -- "$2" out.txt; then
        ok "$1"
    else
        fail "$1: no stdout line matches '$2'"
        sed 's/^/  stdout: /' out.txt | head -30
    fi
}

# expect_usage_error NAME ARGS...: exit status 2 and something on stderr.
expect_usage_error() {
    local name=$1
    shift
    run "$@"
    if [ "$rc" -ne 2 ]; then
        fail "$name: exit status $rc, expected 2 (usage error)"
        show "$@"
    elif [ ! -s err.txt ]; then
        fail "$name: exit status 2 but nothing on stderr"
        show "$@"
    else
        ok "$name"
    fi
}

# expect_input_error NAME FILE ARGS...: exit status 1, exactly one line on stderr, starting
# "vmap: error:" and naming FILE, and nothing on stdout.
expect_input_error() {
    local name=$1 file=$2
    shift 2
    run "$@"
    local lines
    lines=$(wc -l <err.txt)
    if [ "$rc" -ne 1 ]; then
        fail "$name: exit status $rc, expected 1 (input error)"
        show "$@"
    elif [ "$lines" -ne 1 ]; then
        fail "$name: $lines lines on stderr, expected one"
        show "$@"
    elif ! grep -q '^vmap: error: ' err.txt; then
        fail "$name: stderr does not start with 'vmap: error: '"
        show "$@"
    elif ! grep -qF -- "$file" err.txt; then
        fail "$name: the message does not name '$file'"
        show "$@"
    elif [ -s out.txt ]; then
        fail "$name: printed to stdout although it failed"
        show "$@"
    else
        ok "$name"
    fi
}

# temps_of PATH: the temporaries of PATH in its folder (.NAME.<pid>.<n>.<t>.tmp), if any.
temps_of() {
    ls -d "$(dirname "$1")/.$(basename "$1")."*.tmp 2>/dev/null
}

# expect_no_file NAME PATH: neither PATH nor a temporary of it exists.
expect_no_file() {
    if [ -e "$2" ] || [ -n "$(temps_of "$2")" ]; then
        fail "$1: left $(ls -d "$2" $(temps_of "$2") 2>/dev/null | tr '\n' ' ')behind"
    else
        ok "$1"
    fi
}

# ---- build, info, query ----------------------------------------------------------------------

if expect_ok "build the empty Cornell room" \
    build "$SCENE" --points 3000 --max-height 5 -o x.vmap --backend cpu; then
    expect_stdout "build prints the point count" '^points: +3000$'
    expect_stdout "build prints the link count" '^links: +[1-9][0-9]*'
    expect_stdout "build prints the octree" '^octree: +max_height 5'
    expect_stdout "build says which backend ran" '^backend: +cpu'
    expect_stdout "build says what it wrote" '^wrote: +x\.vmap$'
fi
if [ -s x.vmap ]; then ok "x.vmap exists"; else fail "x.vmap was not written"; fi
if [ -n "$(temps_of x.vmap)" ]; then fail "build left a temporary behind"; else ok "no temporary of x.vmap"; fi

# Two builds of different maps into one path at once: the file is one of them, whole.
"$VMAP" build "$SCENE" --points 3000 --max-height 5 -o both.vmap --backend cpu >/dev/null 2>&1 &
"$VMAP" build "$SCENE" --points 2000 --max-height 4 -o both.vmap --backend cpu >/dev/null 2>&1 &
wait
if "$VMAP" info both.vmap >info2.txt 2>&1 && grep -Eq '^points: +(3000|2000)$' info2.txt &&
    [ -z "$(temps_of both.vmap)" ]; then
    ok "two builds into one path leave one whole map"
else
    fail "two builds into one path: $(head -1 info2.txt)"
fi
links=$(sed -nE 's/^links: +([0-9]+).*/\1/p' out.txt)

if expect_ok "info" info x.vmap; then
    expect_stdout "info prints the point count" '^points: +3000$'
    expect_stdout "info prints the same link count as build" "^links: +${links:-none}\$"
    expect_stdout "info prints the octree" '^octree: +max_height 5'
fi

if expect_ok "query --pair 0 1" query x.vmap --pair 0 1; then
    expect_stdout "query --pair answers visible, hidden or same-leaf" \
        '^0 1 (visible|hidden|same-leaf)$'
fi
if expect_ok "query --pair 2999 0" query x.vmap --pair 2999 0; then
    expect_stdout "query --pair works for the last point" '^2999 0 (visible|hidden|same-leaf)$'
fi

if expect_ok "query --from 0" query x.vmap --from 0; then
    expect_stdout "query --from prints a count" '^[0-9]+ points visible from 0 \(of 3000\)$'
fi
count=$(sed -nE 's/^([0-9]+) points visible.*/\1/p' out.txt)
if expect_ok "query --from 0 --ids" query x.vmap --from 0 --ids; then
    ids=$(wc -l <out.txt)
    if [ "$ids" = "${count:-none}" ]; then
        ok "--ids lists as many ids as the count"
    else
        fail "--ids listed $ids ids for a count of ${count:-none}"
    fi
    if grep -Evq '^[0-9]+$' out.txt; then fail "--ids printed more than ids on stdout"; else
        ok "--ids prints ids only on stdout"; fi
    if grep -q "^$count points visible from 0" err.txt; then ok "--ids says the count on stderr"
    else fail "--ids: no count on stderr"; fi
    sort -n out.txt >ids_from0.txt
fi

# ---- conventions: --version, -q, -v -------------------------------------------------------------
if expect_ok "vmap --version" --version; then
    expect_stdout "--version names the version, commit and CUDA" '^vmap [0-9]+\.[0-9]+\.[0-9]+ \(commit [^,]+, CUDA (on|off)\)$'
fi
if expect_ok "build -q" -q build "$SCENE" --points 1000 --max-height 4 -o q.vmap --backend cpu; then
    if [ -s out.txt ] || [ -s err.txt ]; then fail "build -q printed something"; else ok "build -q is silent"; fi
fi
if expect_ok "build -v" build "$SCENE" --points 1000 --max-height 4 -o v.vmap --backend cpu -v; then
    expect_stdout "build -v has the timing breakdown" '^ +plan and node tests [0-9.]+ s, waiting on backend'
    expect_stdout "build -v has the links per level" '^ +level +nodes +leaves +links$'
fi
if grep -q 'waiting on backend' <("$VMAP" build "$SCENE" --points 1000 --max-height 4 -o d.vmap \
    --backend cpu 2>/dev/null); then fail "the default summary has the breakdown"; else
    ok "the default summary is short"; fi
if grep -Eq '^leaf pairs: [0-9]+ to do on cpu .*, about ' <("$VMAP" build "$SCENE" --points 1000 \
    --max-height 4 -o d.vmap --backend cpu 2>&1 >/dev/null); then
    ok "build says the job's size and an estimate before the work"; else
    fail "build: no size and estimate on stderr"; fi
if expect_ok "build --json" build "$SCENE" --points 1000 --max-height 4 -o j.vmap --backend cpu --json; then
    if /usr/bin/env python3 -c 'import json,sys; d=json.load(open("out.txt")); assert d["links"] > 0 and d["output"] == "j.vmap"' 2>/dev/null ||
        grep -q '"links": [1-9]' out.txt; then ok "build --json has the links"; else fail "build --json"; fi
    # The save's size and parts: the file's size, to the byte.
    if grep -q "\"file_bytes\": $(stat -c %s j.vmap)," out.txt && grep -q '"save_sync": ' out.txt; then
        ok "build --json gives the file's size and the save's parts"
    else fail "build --json: no file_bytes equal to the file's size, or no save_sync"; fi
fi

# ---- batches: --pairs (text, stdin, .npy), --out answers.npy, --from with many ids, --json ----
printf '0 1\n# a comment\n\n2999 0\n5,6\n' >pairs.txt
if expect_ok "query --pairs FILE" query x.vmap --pairs pairs.txt; then
    if [ "$(wc -l <out.txt)" = 3 ] && ! grep -Evq '^[0-9]+ [0-9]+ (visible|hidden|same-leaf)$' out.txt
    then ok "--pairs answers one line per pair"; else fail "--pairs output"; show query x.vmap --pairs pairs.txt; fi
    cp out.txt batch.txt
    : >single.txt
    for p in "0 1" "2999 0" "5 6"; do "$VMAP" query x.vmap --pair $p >>single.txt; done
    if cmp -s batch.txt single.txt; then ok "--pairs agrees with --pair one by one"; else
        fail "--pairs differs from --pair"; diff batch.txt single.txt | head; fi
fi
"$VMAP" query x.vmap --pairs - <pairs.txt >stdin.txt 2>err.txt
if cmp -s stdin.txt batch.txt; then ok "--pairs - reads stdin"; else fail "--pairs - (stdin)"; fi
# A hand-made .npy (version 1.0, little-endian int32, shape (3, 2)) of the same pairs.
{
    printf '\x93NUMPY\x01\x00\x76\x00'
    h="{'descr': '<i4', 'fortran_order': False, 'shape': (3, 2), }"
    printf '%s' "$h"
    printf '%*s\n' $((0x76 - ${#h} - 1)) ''
    printf '\x00\x00\x00\x00\x01\x00\x00\x00\xb7\x0b\x00\x00\x00\x00\x00\x00\x05\x00\x00\x00\x06\x00\x00\x00'
} >pairs.npy
if expect_ok "query --pairs .npy --out" query x.vmap --pairs pairs.npy --out ans.npy; then
    # The answers: 10-byte prefix + 118-byte header, then one byte per pair (0/1/2).
    want=$(awk '{print ($3=="hidden")?0:($3=="visible")?1:2}' batch.txt | tr -d '\n')
    got=$(tail -c 3 ans.npy | od -An -tu1 | tr -d ' \n')
    if [ "$(head -c 6 ans.npy | tail -c 5)" = NUMPY ] && [ "$got" = "$want" ]; then
        ok "--out writes the answers as .npy"; else fail "--out answers.npy: got '$got', want '$want'"; fi
fi
printf '0 1\n3 x\n' >bad_pairs.txt
expect_input_error "--pairs with a bad line" "bad_pairs.txt: line 2" query x.vmap --pairs bad_pairs.txt
printf '0 1\n7 3000\n' >range_pairs.txt
expect_input_error "--pairs id out of range" "range_pairs.txt: pair 1" query x.vmap --pairs range_pairs.txt
expect_usage_error "--out without --pairs" query x.vmap --pair 0 1 --out a.npy
if expect_ok "query --from with many ids --ids" query x.vmap --from 0 1 2 --ids; then
    if [ "$(wc -l <out.txt)" = 3 ]; then ok "--from I J K --ids: one line per point"; else
        fail "--from I J K --ids: $(wc -l <out.txt) lines"; fi
    head -1 out.txt | tr ' ' '\n' | sed '/^$/d' | sort -n >first.txt
    if cmp -s first.txt ids_from0.txt; then ok "the first line is --from 0's ids"; else
        fail "--from 0 1 2: the first line differs from --from 0 --ids"; fi
fi
if expect_ok "query --json" query x.vmap --pair 0 1 --from 0 --json; then
    if grep -q '"pairs"' out.txt && grep -q '"count"' out.txt; then ok "query --json has pairs and counts"
    else fail "query --json"; show query x.vmap --pair 0 1 --from 0 --json; fi
fi
if expect_ok "info --json" info x.vmap --json; then
    expect_stdout "info --json has the links" "\"links\": ${links:-none},"
fi

# The same scene built on one thread gives the same file, byte for byte.
if expect_ok "build on one thread" \
    --threads 1 build "$SCENE" --points 3000 --max-height 5 -o one.vmap --backend cpu; then
    if cmp -s x.vmap one.vmap; then
        ok "one thread and all threads write identical files"
    else
        fail "one thread and all threads write different files"
    fi
fi

# A raw point cloud without normals (they are estimated): 400 points on a sphere.
awk 'BEGIN {
    n = 400; pi = 3.14159265358979; g = pi * (3 - sqrt(5));
    printf "ply\nformat ascii 1.0\nelement vertex %d\n", n;
    printf "property float x\nproperty float y\nproperty float z\nend_header\n";
    for (i = 0; i < n; i++) {
        y = 1 - 2 * (i + 0.5) / n; r = sqrt(1 - y * y); a = g * i;
        printf "%.6f %.6f %.6f\n", 0.1 * r * cos(a), 0.1 * y, 0.1 * r * sin(a);
    }
}' >sphere.ply
if expect_ok "build a point cloud" build sphere.ply --max-height 4 -o sphere.vmap --backend cpu
then
    expect_stdout "build of a cloud prints its point count" '^points: +400$'
    expect_stdout "build of a cloud says what it wrote" '^wrote: +sphere\.vmap$'
    if grep -q '^vmap build: normals: estimated' err.txt && grep -q '^vmap build: splat radii' err.txt
    then
        ok "build of a cloud says what it estimated"
    else
        fail "build of a cloud does not say what it estimated"
        show build sphere.ply
    fi
fi
# Seen from outside, a lone sphere's points never face each other: the build warns.
if expect_ok "build a cloud with --normals outward" \
    build sphere.ply --normals outward --max-height 4 -o out.vmap --backend cpu; then
    if grep -q '^vmap build: warning: only .* of leaf pairs face each other' err.txt; then
        ok "build warns when almost no leaf pairs face"
    else
        fail "no warning for a cloud whose points never face each other"
        show build sphere.ply --normals outward
    fi
fi
if expect_ok "build a cloud with --viewpoint" \
    build sphere.ply --viewpoint 0,0,0 --max-height 4 -o in.vmap --backend cpu; then
    if grep -q 'toward the viewpoint (0, 0, 0)' err.txt && ! grep -q 'warning' err.txt; then
        ok "--viewpoint orients toward it, and the inside faces itself"
    else
        fail "--viewpoint 0,0,0 not reported, or a warning"
        show build sphere.ply --viewpoint 0,0,0
    fi
fi
# The same sphere 4 million units from the file's zero (a georeferenced scan; a float there is
# 0.5 apart): read around itself, and positions given and printed are the file's.
awk 'data { printf "%.6f %.6f %.6f\n", $1 + 512345, $2 + 4123456, $3 + 210; next }
     { sub(/property float/, "property double"); print }
     /^end_header/ { data = 1 }' sphere.ply >far.ply
if expect_ok "build a cloud far from its file's zero" \
    build far.ply --viewpoint 512345,4123456,210 --max-height 4 -o far.vmap --backend cpu; then
    if grep -q 'coordinates: relative to (512345, 4123456, 210)' err.txt &&
        grep -q 'toward the viewpoint (512345, 4123456, 210)' err.txt && ! grep -q 'warning' err.txt
    then
        ok "a far cloud is read around itself, and --viewpoint is in the file's coordinates"
    else
        fail "a far cloud: no note of its origin, the viewpoint not the file's, or a warning"
        show build far.ply --viewpoint 512345,4123456,210
    fi
    if expect_ok "query a far map by a position in the file's coordinates" \
        query far.vmap --from-pos 512345.1,4123456,210 &&
        grep -Eq 'nearest point [0-9]+ at \(512345\.(09|1)' err.txt; then
        ok "the far map's positions are the file's"
    else
        fail "the far map's nearest point is not printed in the file's coordinates"
        show query far.vmap --from-pos 512345.1,4123456,210
    fi
    if expect_ok "info on a far map" info far.vmap &&
        grep -q '^origin: *(512345, 4123456, 210)' out.txt; then
        ok "info says where the far map's points have their zero"
    else
        fail "info does not print the far map's origin"
        show info far.vmap
    fi
fi
# A scan's noise: the sphere again, 2000 points, moved by Gaussian noise of 2 mm (a quarter of
# their spacing). The build measures it and sets the predicate's roughness; the exact sphere
# measures none; --roughness replaces the measure; a .vmap has its own.
run build sphere.ply --max-height 4 -o exact.vmap --backend cpu
if [ "$rc" -eq 0 ] && grep -q '^vmap build: surface noise: none measured' err.txt; then
    ok "an exact cloud measures no surface noise"
else
    fail "an exact cloud's build does not say it measured no noise"
    show build sphere.ply --max-height 4
fi
awk -v n=2000 -v seed=3 -v s=0.002 -f "$SRC/tests/data/noisy_sphere.awk" >noisy.ply
if expect_ok "build a noisy cloud" build noisy.ply --max-height 6 -o noisy.vmap --backend cpu; then
    if grep -qE '^vmap build: surface noise: 0\.00(1[6-9]|2)[0-9]* \(.*do not occlude' err.txt &&
        run info noisy.vmap && grep -qE '^predicate: .*roughness 0\.00[89]' out.txt; then
        ok "a noisy cloud's noise is measured (2 mm) and kept as the map's roughness (3 sqrt 2 x)"
    else
        fail "a noisy cloud's noise not measured near 2 mm, or the roughness not in the map"
        show build noisy.ply --max-height 6
        show info noisy.vmap
    fi
fi
if expect_ok "build a noisy cloud with --roughness 0" \
    build noisy.ply --max-height 6 --roughness 0 -o rough0.vmap --backend cpu; then
    if ! grep -q 'surface noise' err.txt && run info rough0.vmap &&
        grep -qE '^predicate: .*roughness 0, core' out.txt; then
        ok "--roughness replaces the measured noise"
    else
        fail "--roughness 0: the noise still measured, or the map's roughness not 0"
        show info rough0.vmap
    fi
fi
# Noise of about a sample spacing: the build warns.
awk -v n=2000 -v seed=4 -v s=0.008 -f "$SRC/tests/data/noisy_sphere.awk" >heavy.ply
if expect_ok "build a very noisy cloud" build heavy.ply --max-height 5 -o heavy.vmap --backend cpu
then
    if grep -q '^vmap build: warning: the points scatter .* sample spacings off their surfaces' \
        err.txt && ! grep -q 'scatter' <(run build noisy.ply --max-height 5 -o n2.vmap \
        --backend cpu; cat err.txt); then
        ok "a very noisy cloud's build warns; a quarter spacing's does not"
    else
        fail "no warning for a cloud noisy by about a spacing, or one for a quarter"
        show build heavy.ply --max-height 5
    fi
fi
expect_usage_error "--roughness below 0" build noisy.ply --roughness -1
expect_input_error "--roughness on a .vmap" noisy.vmap render noisy.vmap --roughness 1 -o r.png
expect_input_error "--normals flip on a cloud without normals" sphere.ply \
    build sphere.ply --normals flip --max-height 4 -o flip.vmap
expect_no_file "a failed --normals flip writes nothing" flip.vmap
expect_usage_error "--normals with an unknown mode" build sphere.ply --normals sideways
expect_usage_error "--viewpoint with two numbers" build sphere.ply --viewpoint 1,2
expect_usage_error "--normals on a scene file" build "$SCENE" --normals flip

# ---- help ------------------------------------------------------------------------------------

run --help
if [ "$rc" -eq 0 ] && grep -q 'build' out.txt; then
    ok "vmap --help"
else
    fail "vmap --help: exit status $rc, or no mention of 'build'"
    show --help
fi
run build --help
if [ "$rc" -eq 0 ] && grep -q -- '--max-height' out.txt; then
    ok "vmap build --help"
else
    fail "vmap build --help: exit status $rc, or no mention of --max-height"
    show build --help
fi

# ---- usage errors: exit 2 --------------------------------------------------------------------

expect_usage_error "no subcommand"
expect_usage_error "unknown subcommand" frobnicate
expect_usage_error "unknown option" build "$SCENE" --bogus -o never.vmap
expect_usage_error "unknown global option" --bogus info x.vmap
expect_usage_error "--max-height 99" build "$SCENE" --max-height 99 -o never.vmap
expect_usage_error "--max-height 0" build "$SCENE" --max-height 0 -o never.vmap
expect_usage_error "--points not a number" build "$SCENE" --points many -o never.vmap
expect_usage_error "--backend unknown" build "$SCENE" --backend abacus -o never.vmap
expect_usage_error "query without --pair or --from" query x.vmap
expect_usage_error "query --pair with one id" query x.vmap --pair 0
expect_usage_error "info without a file" info
expect_no_file "usage errors write nothing" never.vmap

# ---- input errors: exit 1, one line naming the file ------------------------------------------

# expect_bad_build_input NAME INPUT: building INPUT into y.vmap is an input error naming INPUT,
# and writes nothing.
expect_bad_build_input() {
    expect_input_error "$1" "$2" build "$2" -o y.vmap --backend cpu
    expect_no_file "$1 writes nothing" y.vmap
}
expect_bad_build_input "missing scene file" "$WORK/no_such_scene.json"
expect_bad_build_input "malformed scene JSON" "$DATA/malformed.json"
expect_bad_build_input "NaN in a point cloud" "$DATA/nan.ply"
expect_bad_build_input "empty point cloud" "$DATA/empty.ply"
expect_bad_build_input "missing point cloud" "$WORK/no_such_cloud.ply"

expect_input_error "output in a missing directory" "no_such_dir/y.vmap" \
    build "$SCENE" --points 300 --max-height 3 -o no_such_dir/y.vmap --backend cpu
if [ -e no_such_dir ]; then fail "a failed build created no_such_dir"; else ok "no no_such_dir"; fi

# A failed build leaves an existing output file as it was.
cp x.vmap keep.vmap
expect_input_error "failed build over an existing file" "$DATA/malformed.json" \
    build "$DATA/malformed.json" -o keep.vmap --backend cpu
if cmp -s x.vmap keep.vmap && [ -z "$(temps_of keep.vmap)" ]; then
    ok "a failed build leaves the existing output untouched"
else
    fail "a failed build changed keep.vmap or left keep.vmap.tmp"
fi

head -c 100 x.vmap >truncated.vmap
expect_input_error "info on a truncated .vmap" truncated.vmap info truncated.vmap
if grep -q 'truncated' err.txt; then
    ok "the message says truncated"
else
    fail "the message for a truncated .vmap does not say truncated"
    show info truncated.vmap
fi
expect_input_error "query on a truncated .vmap" truncated.vmap query truncated.vmap --pair 0 1
expect_input_error "info on a missing .vmap" no_such.vmap info no_such.vmap
expect_input_error "info on a scene file" "$SCENE" info "$SCENE"
mkdir a_directory.vmap
expect_input_error "info on a directory" a_directory.vmap info a_directory.vmap

expect_input_error "query --pair id out of range" x.vmap query x.vmap --pair 0 3000
expect_input_error "query --from id out of range" x.vmap query x.vmap --from 4000000000

# ---- render, query by position and rays, bench-query (issue 4) -------------------------------

# png_size FILE: "W H" from the PNG header (IHDR), or nothing when FILE is not a PNG.
png_size() {
    [ "$(head -c 8 "$1" | od -An -tx1 | tr -d ' \n')" = "89504e470d0a1a0a" ] || return
    od -An -tu1 -j16 -N8 "$1" | awk '{print $1*16777216+$2*65536+$3*256+$4, $5*16777216+$6*65536+$7*256+$8}'
}

if expect_ok "render a scene, shaded" render "$SCENE" --points 3000 --mode shaded --size 64x48 \
    -o shaded.png; then
    if [ "$(png_size shaded.png)" = "64 48" ]; then ok "render writes a 64x48 PNG"; else
        fail "shaded.png is not a 64x48 PNG ($(png_size shaded.png))"; fi
fi
if expect_ok "render a .vmap, visible from a point, with a PLY" \
    render x.vmap --mode visible --eye-id 5 --size 80x80 -o vis.png --ply vis.ply; then
    expect_stdout "render says how many points the eye sees" '^eye: +point 5 .*: [0-9]+ of 3000 points visible'
    if [ "$(png_size vis.png)" = "80 80" ]; then ok "visible PNG is 80x80"; else
        fail "vis.png is not an 80x80 PNG"; fi
    if head -c 400 vis.ply | grep -aq 'property uchar red' && head -c 400 vis.ply | grep -aq 'property float nx'; then
        ok "the PLY has uchar colours and normals"
    else
        fail "vis.ply lacks uchar red/green/blue or normals"
    fi
fi
expect_ok "render --mode heights" render "$SCENE" --points 1500 --mode heights --heights 3,4 \
    --eye-pos 0.27,0,0.2 --size 60x60 -o heights.png --backend cpu
if [ "$(png_size heights.png | cut -d' ' -f1)" -gt 120 ] 2>/dev/null; then
    ok "heights puts two panels side by side"
else
    fail "heights.png is not wider than two panels"
fi
if expect_ok "render --mode decided" render "$SCENE" --points 1500 --mode decided --size 40x40 \
    -o decided.png --backend cpu; then
    expect_stdout "decided says how many leaf pairs were walked" '^decided: +[0-9]+ of [0-9]+ leaf pairs walked'
fi
expect_ok "build --construction leaf-pairs" build "$SCENE" --points 1500 --construction leaf-pairs \
    -o pairs.vmap --backend cpu
expect_ok "build --construction nodes" build "$SCENE" --points 1500 -o nodes.vmap --backend cpu
expect_stdout "build reports the leaf pairs walked" '^construction: nodes: [0-9]+ of [0-9]+ leaf pairs walked'
if cmp -s pairs.vmap nodes.vmap; then ok "both constructions write the same file"; else
    fail "pairs.vmap and nodes.vmap differ"; fi
expect_usage_error "--construction unknown" build "$SCENE" --construction magic -o never.vmap
# A degenerate camera fails before any V-map is built (stdout stays empty: no "built:" line).
expect_input_error "render heights with eye == target" "eye and target coincide" render "$SCENE" \
    --points 1500 --mode heights --heights 3,4 --eye-pos 0.27,0,0.2 --eye 1,1,1 --target 1,1,1 \
    --size 60x60 -o never.png --backend cpu
expect_no_file "render with a degenerate camera" never.png
# Output folders are checked before any work: no PLY is left without its PNG.
expect_input_error "render -o into a missing folder" no_such_dir/r.png render x.vmap \
    --size 40x40 -o no_such_dir/r.png --ply lone.ply
expect_no_file "render with a bad -o" lone.ply
expect_ok "render --fov 179 (the end of the documented range)" render x.vmap --fov 179 \
    --size 40x40 -o fov179.png
expect_usage_error "render visible without an eye" render x.vmap --mode visible -o novis.png
expect_no_file "no PNG after a usage error" novis.png
expect_usage_error "render --size 0x10" render x.vmap --size 0x10 -o bad.png
expect_no_file "no PNG after a bad size" bad.png
expect_input_error "render --eye-id out of range" x.vmap render x.vmap --mode visible \
    --eye-id 3000 -o bad.png --ply bad.ply
expect_no_file "no PNG after a bad eye id" bad.png
expect_no_file "no PLY after a bad eye id" bad.ply
expect_usage_error "render --eye with a NaN" render x.vmap --eye nan,0,0 -o bad.png
expect_no_file "no PNG after a NaN eye" bad.png
expect_input_error "render into a missing folder" no_such_dir/r.png render x.vmap --size 8x8 \
    -o no_such_dir/r.png

if expect_ok "query --pair-pos" query x.vmap --pair-pos 0.1,0,0.2 0.2,0.5488,0.3; then
    if grep -Eq '^--pair-pos .*: nearest point [0-9]+' err.txt; then
        ok "pair-pos names the nearest points on stderr"; else fail "pair-pos: no nearest point on stderr"; fi
    expect_stdout "pair-pos answers" '^[0-9]+ [0-9]+ (visible|hidden|same-leaf)$'
fi
if expect_ok "query --from-pos with --ply" query x.vmap --from-pos 0.27,0,0.2 --ply from.ply; then
    expect_stdout "from-pos counts" '^[0-9]+ points visible from [0-9]+ \(of 3000\)$'
    if [ -s from.ply ]; then ok "from.ply written"; else fail "from.ply missing"; fi
fi
if expect_ok "query --ray" query x.vmap --ray-pos 0.27,0,0.2 --dir 0,1,0; then
    expect_stdout "ray straight up from the floor hits the top" '^ray from [0-9]+: hits point [0-9]+ at distance 0\.5[0-9]*'
fi
expect_usage_error "query --ray without --dir" query x.vmap --ray 3
expect_usage_error "query --ply without --from" query x.vmap --pair 0 1 --ply nofrom.ply
expect_no_file "no PLY without --from" nofrom.ply
expect_usage_error "query --dir 0,0,0" query x.vmap --ray 3 --dir 0,0,0
expect_usage_error "query --from-pos not a position" query x.vmap --from-pos 1,2
expect_usage_error "query --pair with --pair-pos" query x.vmap --pair 0 1 --pair-pos 0,0,0 1,1,1
expect_usage_error "query --from with --from-pos" query x.vmap --from 0 --from-pos 0,0,0
expect_input_error "query --ray id out of range" x.vmap query x.vmap --ray 3000 --dir 0,1,0

if expect_ok "bench-query, tiny" bench-query --scene "$SCENE" --points 800,1600 --max-height 4 \
    --queries 40 --runs 1 --backend cpu; then
    expect_stdout "bench-query fits a growth exponent" '^Growth exponent k'
fi

# ---- validate (issue 5) ----------------------------------------------------------------------

BLOCK="$SRC/tests/data/oracle/room-with-block.json"
run validate "$BLOCK" --pairs 5000 --heights 4,5 --md v.md --json v.json
if [ "$rc" -eq 0 ] && grep -q '| 5 | 5 |' v.md && grep -q '"false_visible_rate"' v.json; then
    ok "validate writes the Markdown and JSON tables"
else
    fail "validate --md/--json"
    show validate "$BLOCK" --pairs 5000 --heights 4,5 --md v.md --json v.json
fi
run validate "$BLOCK" --pairs 3000 --heights 4 --predict direct --occluders grid
if [ "$rc" -eq 0 ] && grep -q 'grid occluders' out.txt; then
    ok "validate --occluders grid prints its table"
else
    fail "validate --occluders grid"
    show validate "$BLOCK" --pairs 3000 --heights 4 --predict direct --occluders grid
fi
run validate "$BLOCK" --time-embree --heights 4 --embree-pairs 20000 --runs 1
if [ "$rc" -eq 0 ] && grep -q 'rtcOccluded1' out.txt; then
    ok "validate --time-embree prints its table"
else
    fail "validate --time-embree"
    show validate "$BLOCK" --time-embree --heights 4 --embree-pairs 20000 --runs 1
fi
run validate "$BLOCK" --pairs 3000 --heights 4 --predict direct --eyes 2 --points 4000 \
    --scan 2 --as-cloud sensors
if [ "$rc" -eq 0 ] && grep -q 'simulated scan from 2 scanners' out.txt &&
    grep -q 'scanner positions' out.txt; then
    ok "validate --scan scores a simulated scan with its scanner positions"
else
    fail "validate --scan"
    show validate "$BLOCK" --pairs 3000 --heights 4 --predict direct --eyes 2 --points 4000 \
        --scan 2 --as-cloud sensors
fi
expect_input_error "validate --as-cloud sensors without --scan" "$BLOCK" \
    validate "$BLOCK" --heights 4 --as-cloud sensors
expect_usage_error "validate --scan 0" validate "$BLOCK" --scan 0
expect_usage_error "validate --scan 65" validate "$BLOCK" --scan 65
expect_usage_error "validate --scan-seed without --scan" validate "$BLOCK" --scan-seed 3
expect_input_error "validate a missing scene" no_such_scene.json validate no_such_scene.json
expect_input_error "validate a point cloud" "$DATA/nan.ply" validate "$DATA/nan.ply"
expect_input_error "validate --splat-floor without --predict direct" "$BLOCK" \
    validate "$BLOCK" --heights 4 --splat-floor 2
expect_usage_error "validate --pairs 0" validate "$BLOCK" --pairs 0
expect_usage_error "validate --heights 0" validate "$BLOCK" --heights 0
expect_usage_error "validate --heights 30" validate "$BLOCK" --heights 5,30
expect_usage_error "validate without a scene" validate
expect_usage_error "build --occluders cones" build "$SCENE" --occluders cones -o never.vmap
expect_input_error "validate --json into a missing folder" no_such_dir/v.json \
    validate "$BLOCK" --pairs 100 --heights 3 --json no_such_dir/v.json
[ -e no_such_dir ] && fail "validate created no_such_dir" || ok "validate left no file behind"

# ---- vmap gi (global illumination) ----------------------------------------------------------

if expect_ok "gi on a .vmap, PLY out" gi x.vmap --bounces 3 --ply lit.ply --backend cpu \
    --size 32x32; then
    if [ -s x-gi.png ]; then ok "gi writes <input>-gi.png by default"; else fail "gi wrote no x-gi.png"; fi
    expect_stdout "gi reports each bounce" '^bounce +2: '
    expect_stdout "gi ends with the final gather" '^gather: +final gather \(bounce 3\)'
    expect_stdout "gi reports the refinement" '^refinement: blocks, theta 1: [0-9]+ interactions'
    expect_stdout "gi prints the exposure" '^tone map: +exposure [0-9.e+-]+ '
    if [ "$(head -c 3 lit.ply)" = "ply" ] && grep -aq 'property uchar red' lit.ply &&
        grep -aq 'property float radiosity_r' lit.ply; then
        ok "lit.ply holds display colours and linear radiosity"
    else
        fail "lit.ply lacks display colours or linear radiosity"
    fi
fi
if expect_ok "gi converges by default" gi x.vmap --backend cpu --tolerance 0.01; then
    expect_stdout "gi says it converged" '^converged: '
    # x.vmap has vmap build's predicate (no end window): gi says its own maps differ.
    if grep -q 'note: x.vmap was built with -K 2 --eps 0.01 --end-window 0; the V-map vmap gi builds itself has -K 2 --eps 0.01 --end-window 2' err.txt; then
        ok "gi notes a loaded map without the GI's end window"
    else
        fail "gi said nothing of the loaded map's end window"
        sed 's/^/  stderr: /' err.txt | head -5
    fi
fi
if expect_ok "gi renders a PNG and a PFM" gi x.vmap --bounces 1 --backend cpu -o lit.png \
    --pfm lit.pfm --size 64x48; then
    if [ "$(head -c 4 lit.png | tail -c 3)" = "PNG" ]; then ok "lit.png is a PNG"; else fail "lit.png is not a PNG"; fi
    if [ "$(head -c 2 lit.pfm)" = "PF" ] && [ "$(stat -c %s lit.pfm)" -gt $((64 * 48 * 12)) ]; then
        ok "lit.pfm is a float RGB image"
    else
        fail "lit.pfm is not a 64x48 PFM"
    fi
fi
if expect_ok "gi --reference prints the error table" gi "$SCENE" --reference --points 1500 \
    --max-height 5 --backend cpu --ref-points 20 --ref-samples 16 --ref-out ref.csv; then
    expect_stdout "the table has the default GI" '^\| vmap gi \(default\) \| converged'
    expect_stdout "the table has the brute force" '^\| brute-force gather \| 1 \|'
    if [ "$(head -c 4 ref.csv)" = "set," ] && [ "$(wc -l <ref.csv)" -eq 21 ]; then
        ok "ref.csv has a header and 20 points (an empty room has no model points)"
    else
        fail "ref.csv is not the 20 points' table"
    fi
fi
expect_input_error "gi --reference on a .vmap" x.vmap gi x.vmap --reference
expect_usage_error "gi --size nonsense" gi x.vmap --size nonsense -o y.png
if [ -e y.png ]; then fail "gi --size nonsense wrote y.png"; else ok "no y.png"; fi
if expect_ok "gi on a scene against the brute force" gi "$SCENE" --points 1500 --max-height 5 \
    --bounces 1 --backend cpu --compare-brute; then
    expect_stdout "gi --compare-brute prints the difference" 'relative RMS vs brute force 0\.0[0-4]'
fi
# bench: a row the CPU only estimated built nothing, so it shows no counts (it showed 0.0%
# walked, 0 node pairs and 0 links).
if expect_ok "bench with the CPU's time estimated" bench --scene "$SCENE" --points 3000 \
    --heights 5 --runs 1 --cpu-budget 0 --backends cpu; then
    expect_stdout "an estimated row shows no counts" '^\| cornell-empty \| 3000 \| 5 \| [0-9]+ \| [0-9.e+]+ \| - \| - \| - \| [0-9.e+-]+ \(est\.\) \|'
fi
# bench-gi at its default backends (cpu, and cuda where there is a GPU): without one the table
# leaves the GPU column out (the solver's refusal used to end the command with exit status 1).
if expect_ok "bench-gi at its default backends" bench-gi --points 300 --runs 1 --bounces 1 \
    --brute-max 0; then
    expect_stdout "bench-gi prints a row of 300 points" '^\| 300 \| [0-9]+ \|'
fi
expect_usage_error "gi --theta 0" gi x.vmap --theta 0
expect_usage_error "gi --theta -1" gi x.vmap --theta -1
expect_usage_error "gi --bounces -1" gi x.vmap --bounces -1
expect_usage_error "gi --backend gpu" gi x.vmap --backend gpu
expect_usage_error "gi --refine nope" gi x.vmap --refine nope
expect_input_error "gi on a missing file" no_such.vmap gi no_such.vmap
expect_input_error "gi --points on a .vmap" x.vmap gi x.vmap --points 10
if [ -s sphere.vmap ]; then
    expect_input_error "gi on a V-map without emitters" sphere.vmap gi sphere.vmap
fi
expect_input_error "gi --ply into a missing folder" no_dir/lit.ply gi x.vmap --bounces 1 \
    --backend cpu --ply no_dir/lit.ply
bad=$(ls no_dir 2>/dev/null)
if [ -n "$bad" ]; then fail "gi left files in no_dir: $bad"; else ok "gi wrote nothing half"; fi

# ---- formats: meshes are sampled, point lists and PCD read, any emitter lights -----------------

# Two unit boxes side by side as OBJ quads (a convex mesh alone sees nothing of itself).
awk 'BEGIN {
    for (b = 0; b < 2; b++) {
        for (i = 0; i < 8; i++)
            printf "v %d %d %d\n", (i % 2) + 2 * b, int(i / 2) % 2, int(i / 4);
    }
    split("1 3 4 2|5 6 8 7|1 2 6 5|3 7 8 4|1 5 7 3|2 4 8 6", q, "|");
    for (b = 0; b < 2; b++)
        for (f = 1; f <= 6; f++) {
            split(q[f], c, " ");
            printf "f %d %d %d %d\n", c[1] + 8 * b, c[2] + 8 * b, c[3] + 8 * b, c[4] + 8 * b;
        }
}' >boxes.obj
if expect_ok "build an OBJ mesh" build boxes.obj --points 3000 --max-height 5 --backend cpu \
    -o boxes.vmap; then
    expect_stdout "a mesh is area-sampled" '^input: +mesh .*area-sampled'
    expect_stdout "--points applies to a mesh" '^points: +3000$'
fi
if expect_ok "build a mesh's vertices" build boxes.obj --as-points --max-height 3 \
    --backend cpu -o boxes-v.vmap; then
    expect_stdout "--as-points keeps the vertices" '^points: +16$'
fi
awk 'BEGIN { for (i = 0; i < 300; i++) printf "%.5f %.5f 0 0 0 1\n", (i % 20) / 20, int(i / 20) / 15 }' \
    >plate.xyzn
if expect_ok "build an xyzn cloud" build plate.xyzn --max-height 4 --backend cpu -o plate.vmap; then
    expect_stdout "an xyzn cloud keeps its points" '^points: +300$'
fi
expect_usage_error "build --points on a point list" build plate.xyzn --points 10
printf 'FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 2\nDATA ascii\n0 0 0\n1 0 nope\n' >bad.pcd
expect_input_error "a bad PCD names the point and field" "bad.pcd" build bad.pcd
if grep -q 'point 1 (line 7): field z' err.txt; then ok "PCD error names point 1, field z"
else fail "PCD error lacks the point and field"; show build bad.pcd; fi
expect_input_error "gi on a cloud with no emitters names the field" plate.xyzn \
    gi plate.xyzn --bounces 1 --backend cpu
if grep -q '"emission"' err.txt; then ok "the no-emitter message names \"emission\""
else fail "the no-emitter message lacks \"emission\""; show gi plate.xyzn; fi
cat >lit.json <<'JSON'
{ "room": null,
  "meshes": [ { "file": "boxes.obj", "emission": [5, 5, 5] } ],
  "sampling": { "points": 2000, "seed": 2 } }
JSON
if expect_ok "gi on meshes without the room" gi lit.json --bounces 1 --backend cpu \
    --max-height 5 -o lit.png --size 64x64; then
    expect_stdout "every point of an emitting mesh emits" '^points: +2000 \(2000 emitting\)'
fi
# A PLY cloud whose emission is per point: a lit plate facing a plate.
awk 'BEGIN {
    printf "ply\nformat ascii 1.0\nelement vertex 800\nproperty float x\nproperty float y\n";
    printf "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n";
    printf "property float emission_r\nproperty float emission_g\nproperty float emission_b\n";
    printf "end_header\n";
    for (i = 0; i < 400; i++) printf "%.4f 0 %.4f 0 1 0 0 0 0\n", (i % 20) / 20, int(i / 20) / 20;
    for (i = 0; i < 400; i++) printf "%.4f 0.5 %.4f 0 -1 0 3 3 3\n", (i % 20) / 20, int(i / 20) / 20;
}' >plates.ply
if expect_ok "gi on a PLY cloud with per-point emission" gi plates.ply --bounces 1 \
    --backend cpu --max-height 4 --ply plates-lit.ply; then
    expect_stdout "the cloud's emission is used" '^points: +800 \(400 emitting\)'
fi
run validate boxes.obj --points 2000 --pairs 2000 --heights 4
if [ "$rc" -eq 0 ] && grep -q 'boxes' out.txt; then ok "validate takes a mesh as its own truth"
else fail "validate on a mesh file"; show validate boxes.obj --points 2000 --pairs 2000 --heights 4; fi

# ---- done ------------------------------------------------------------------------------------

leftovers=$(ls -A | grep '\.tmp$')
if [ -n "$leftovers" ]; then fail "temporary files left behind: $leftovers"; else ok "no *.tmp"; fi

if [ "$failures" -ne 0 ]; then
    echo "$failures check(s) failed (search for FAIL above)"
    exit 1
fi
echo "all checks passed"
