#!/usr/bin/env bash
# The MPI build end to end (ctest label mpi): mpirun -np 2 and 3 --oversubscribe over TCP on
# loopback, CPU backend. Each scene's .vmap is byte-identical to the single-process build's
# (2 ranks dynamic, 3 static), the sharded output reads back as the same map, and a rank
# with bad input, a rank whose input differs and a killed rank each end the whole job with a
# clear error and leave no output (rank 0 alone reads the input and sends the points). Exit 77 (ctest: skipped) when mpirun or MPI support is absent.
# Usage: run.sh VMAP SOURCE_DIR VMAP_EQUAL HAVE_MPI(ON|OFF) [BUILD_TYPE]
# A Debug build (the ASan preset, 10-30x slower) runs the first scene only: the MPI glue under
# the sanitizers; mpi_split_test covers the cutting and merging there on three scenes.
set -uo pipefail
vmap=$1 src=$2 equal=$3 have=$4 build_type=${5:-Release}
if [[ "$have" != ON ]]; then
    echo "SKIPPED: this vmap was built without MPI (install libopenmpi-dev and reconfigure)"
    exit 77
fi
if ! command -v mpirun >/dev/null; then
    echo "SKIPPED: mpirun not found (install openmpi-bin)"
    exit 77
fi
# As root (CI, containers) Open MPI refuses to start without these.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# Open MPI's own allocations at exit are not ours to report (the debug preset's LeakSanitizer);
# address and UB checks stay on.
export ASAN_OPTIONS="${ASAN_OPTIONS:-}${ASAN_OPTIONS:+:}detect_leaks=0"
mpi=(mpirun --oversubscribe --bind-to none --mca btl self,tcp --mca btl_tcp_if_include lo
     --mca oob_tcp_if_include lo)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0 pass=0
check() {  # name, then a command that must succeed
    local name=$1; shift
    if "$@" > "$tmp/log" 2>&1; then pass=$((pass + 1)); else
        fail=$((fail + 1)); echo "FAILED: $name"; tail -20 "$tmp/log"; fi
}
no_output() {  # the output and no temporary of it
    [[ ! -e "$1" ]] && ! ls -a "$(dirname "$1")" | grep -q "^\.$(basename "$1")\..*\.tmp$"
}

# Without mpirun, --shards is a usage error (exit 2) and nothing is written.
check "--shards without mpirun" bash -c "'$vmap' build '$src/scenes/cornell-bunny.json' --points 500 \
    --max-height 4 --shards -o '$tmp/s.vmap' 2> '$tmp/err'; [[ \$? -eq 2 ]] &&
    grep -q 'under mpirun only' '$tmp/err' && [[ ! -e '$tmp/s.vmap' ]]"

scenes=("$src/scenes/cornell-bunny.json --points 3000 --max-height 6"
        "$src/scenes/test/test-many.json --max-height 5"
        "$src/scenes/test/test-plates.json --points 4000 --max-height 6"
        "$src/scenes/test/test-tight.json --points 4000 --max-height 6 --leaf-points 2")
[[ "$build_type" == Debug ]] && scenes=("${scenes[0]}")
for k in "${!scenes[@]}"; do
    read -r -a args <<< "${scenes[$k]}"
    one="$tmp/one-$k.vmap"
    check "scene $k: single-process build" "$vmap" -q build "${args[@]}" --backend cpu -o "$one"
    for run in "2 dynamic" "3 static"; do
        read -r np sched <<< "$run"
        out="$tmp/np$np-$sched-$k.vmap"
        check "scene $k: np $np $sched" "${mpi[@]}" -np $np "$vmap" -q build "${args[@]}" \
            --backend cpu --schedule $sched -o "$out"
        check "scene $k: np $np $sched byte-identical" cmp "$one" "$out"
        rm -f "$out"
    done
    if [[ $k -eq 0 ]]; then  # the dynamic schedule's chunks, few or many: the same file
        for per in 1 40; do
            check "scene 0: np 2, $per chunks a rank, byte-identical" bash -c "${mpi[*]} -np 2 \
                '$vmap' -q build ${args[*]} --backend cpu --chunks-per-rank $per -o '$tmp/c.vmap' &&
                cmp '$one' '$tmp/c.vmap'"
            rm -f "$tmp/c.vmap"
        done
    fi
    check "scene $k: np 3 shards" "${mpi[@]}" -np 3 "$vmap" -q build "${args[@]}" --backend cpu \
        --shards -o "$tmp/sh-$k.vmap"
    check "scene $k: shards read back equal" "$equal" "$one" "$tmp/sh-$k.vmap"
    check "scene $k: shards queried" bash -c "cmp <('$vmap' query '$one' --pair 0 100) \
        <('$vmap' query '$tmp/sh-$k.vmap' --pair 0 100)"
done

# A noisy scan: rank 0 alone reads it and measures its roughness, which the other ranks take
# (a roughness left at 0 on rank 1 would differ: the check of the inputs fails the job).
awk -v n=1500 -v seed=5 -v s=0.002 -f "$src/tests/data/noisy_sphere.awk" > "$tmp/noisy.ply"
check "noisy cloud: single-process build" "$vmap" -q build "$tmp/noisy.ply" --max-height 6 \
    --backend cpu -o "$tmp/noisy-1.vmap"
check "noisy cloud: np 2 byte-identical, its roughness shared" bash -c "${mpi[*]} -np 2 '$vmap' -q \
    build '$tmp/noisy.ply' --max-height 6 --backend cpu -o '$tmp/noisy-2.vmap' &&
    cmp '$tmp/noisy-1.vmap' '$tmp/noisy-2.vmap' &&
    '$vmap' info '$tmp/noisy-2.vmap' | grep -qE '^predicate: .*roughness 0\.0'"

# Rank 0 speaks for the whole job: its first report names the ranks and the whole job's size.
check "progress names the ranks" bash -c "${mpi[*]} -np 2 '$vmap' build \
    '$src/scenes/cornell-bunny.json' --points 3000 --max-height 6 --backend cpu \
    -o '$tmp/p.vmap' 2> '$tmp/err' && grep -q '^leaf pairs: [0-9]* to do on 2 ranks, cpu' '$tmp/err'"

# Rank 0's summary counts the whole job's leaf pairs, as one process does (it said "of 0").
check "summary: all leaf pairs" bash -c "'$vmap' build '$src/scenes/cornell-bunny.json' \
    --points 3000 --max-height 6 --backend cpu -o '$tmp/p1.vmap' > '$tmp/out1' &&
    ${mpi[*]} -np 2 '$vmap' build '$src/scenes/cornell-bunny.json' --points 3000 --max-height 6 \
    --backend cpu -o '$tmp/p.vmap' > '$tmp/out' &&
    n=\$(grep -oE 'of [1-9][0-9]* leaf pairs walked' '$tmp/out1') && grep -qF \"\$n\" '$tmp/out'"

# Rank 0's summary: the backend the ranks ran and the slowest rank's seconds per phase.
check "summary: backend and phases" bash -c "${mpi[*]} -np 2 '$vmap' build \
    '$src/scenes/cornell-bunny.json' --points 3000 --max-height 6 --backend cpu \
    -o '$tmp/p.vmap' > '$tmp/out' && grep -q '^backend: *cpu (' '$tmp/out' &&
    grep -qE '^phases: .*start [0-9.]+ \\(.*input [0-9.]+, octree [0-9.]+\\), probe .*construction [0-9.]+, .*save [0-9.]+$' '$tmp/out'"

# A shard missing or corrupt: one clear error naming it.
rm -f "$tmp/sh-0.vmap.shard-1-of-3"
check "missing shard named" bash -c "! '$vmap' info '$tmp/sh-0.vmap' 2> '$tmp/err' &&
    grep -q 'sh-0.vmap.shard-1-of-3' '$tmp/err'"

bunny=("$src/scenes/cornell-bunny.json" --points 3000 --max-height 6 --backend cpu -q)
# Bad input: rank 0 alone reads it (and sends the points); the job ends, the file and field named.
printf '{"name": "bad", "meshes": [{"file": 3}]}' > "$tmp/bad.json"
out="$tmp/bad.vmap"
check "bad input fails the job" bash -c "! ${mpi[*]} -np 2 '$vmap' build '$tmp/bad.json' -q \
    -o '$out' 2> '$tmp/err' && grep -q 'rank 0 of 2: .*bad.json: meshes\[0\].file' '$tmp/err'"
check "bad input: no output" no_output "$out"
# A rank that names another input (MPMD: rank 1 reads another file) ends the job, naming it.
check "another input on rank 1 fails the job" bash -c "! ${mpi[*]} -np 1 '$vmap' build \
    ${bunny[*]} -o '$out' : -np 1 '$vmap' build '$tmp/bad.json' -q -o '$out' 2> '$tmp/err' &&
    grep -q 'rank 1 of 2: its input (.*bad.json.*) differs from rank 0' '$tmp/err'"
check "bad input: no output" no_output "$out"
check "differing input on rank 1 fails the job" bash -c "! ${mpi[*]} -np 1 '$vmap' build \
    ${bunny[*]} -o '$out' : -np 1 '$vmap' build ${bunny[*]} --seed 7 -o '$out' 2> '$tmp/err' &&
    grep -q 'rank 1 of 2: its input .* differs from rank 0' '$tmp/err'"
check "differing input: no output" no_output "$out"
check "differing parameters on rank 1 fail the job" bash -c "! ${mpi[*]} -np 1 '$vmap' build \
    ${bunny[*]} -o '$out' : -np 1 '$vmap' build ${bunny[*]} --eps 0.02 -o '$out' 2> '$tmp/err' &&
    grep -q 'rank 1 of 2: its input (points, octree or parameters) differs from rank 0' '$tmp/err'"
check "differing parameters: no output" no_output "$out"
# The same file named from another folder is the same input.
check "the same file by another path" bash -c "cd '$tmp' && ${mpi[*]} -np 1 '$vmap' build \
    ${bunny[*]} -o '$tmp/path.vmap' : -np 1 '$vmap' build \
    \$(realpath --relative-to='$tmp' '$src/scenes/cornell-bunny.json') ${bunny[*]:1} -o '$tmp/path.vmap'"
rm -f "$tmp/path.vmap"

# A rank killed during the construction: mpirun ends the job, nothing is written.
"${mpi[@]}" -np 2 "$vmap" build "$src/scenes/cornell-bunny.json" --points 20000 --max-height 8 \
    --backend cpu -q -o "$out" > "$tmp/kill.log" 2>&1 &
runner=$!
victim=""
for _ in $(seq 100); do  # rank 1, found among mpirun's children by its environment
    for p in $(ps -o pid= --ppid "$runner" 2>/dev/null); do
        tr '\0' '\n' < "/proc/$p/environ" 2>/dev/null | grep -qx OMPI_COMM_WORLD_RANK=1 && victim=$p
    done
    [[ -n "$victim" ]] && break
    sleep 0.1
done
sleep 2  # into the construction
[[ -n "$victim" ]] && kill -9 "$victim"
wait "$runner"
rc=$?
check "killed rank fails the job (rc $rc)" bash -c "[[ -n '$victim' && $rc -ne 0 ]] &&
    grep -q 'signal 9' '$tmp/kill.log'"
check "killed rank: no output" no_output "$out"

echo "$pass passed, $fail failed"
[[ $fail -eq 0 ]]
