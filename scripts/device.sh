#!/usr/bin/env bash
# GPU runs on the lent H100/H200 machine, in two halves:
#   scripts/device.sh bundle   (here)   build for sm_90 with a static CUDA runtime and gather into
#                                       .device/ (git-ignored) the binaries, the shared libraries
#                                       they load (TBB, fmt, ...) and the compressed models.
#   scripts/device.sh run [STEP...]     (there; carry .device) unpack, then run the steps:
#        gpu       the gpu-labelled tests          sanitize  compute-sanitizer memcheck+racecheck
#                  (each run stopped after SAN_TIMEOUT s, default 150, and said "cut")
#        cpu       the CPU test executables        bench     vmap bench (Fig. 10 table)
#        dragon    cornell-dragon at height 10, end to end, GPU (LEAF_POINTS, default 4 8)
#        ab        kernel variants (VARIANTS) on the dragon, height 9 (AB_LEAF_POINTS, default 8)
#        embree    vmap validate --time-embree (Embree rays vs the leaf-pair kernel, all cores)
#        construction  issue 15's targets: cornell-dragon h10 at CONS_LEAF_POINTS (default 8 4 1),
#                  CONS_RUNS runs each (default 3), end to end with the saved file, with
#                  --construction CONS_METHOD (default: the build's own, auto) and
#                  --walk-pairs CONS_WALK_PAIRS (default: the backend's) and --lanes
#                  CONS_LANES (default: the backend's), by each of CONS_BINS (default vmap;
#                  "vmap vmap-before" interleaves the two runs and compares files); for the
#                  leaf_points in CONS_ORACLE also once with --construction leaf-pairs, and the
#                  two files compared; growth over CONS_POINTS (lp 1, h 12, --count-links);
#                  the 1.1M-point --count-links run when CONS_BIG=1 (stopped after
#                  CONS_BIG_TIMEOUT s, default 300); a one-line-a-run summary in
#                  $OUT/construction.txt
#        mpi       the MPI build (bundled Open MPI, OPAL_PREFIX): CPU backend at 1, 2, 4, 8 ranks x
#                  MPI_THREADS threads (default 2: strong scaling), the 16 cores as 1x16, 2x8,
#                  4x4, 8x2, static against dynamic, shards, and 2 ranks sharing the GPU; every
#                  .vmap compared with the single-process build; one table in mpi-summary.md
#                  (MPI_SCENE, default cornell-bunny at 30000 points; MPI_REPEAT=R runs the
#                  1/2/4/8-rank sweep R times and takes medians; MPI_EXTRA=0 skips the 8-rank
#                  variants and the 1x16..4x4 runs; MPI_BOUND=0 the bound runs)
#        host      what the host gives when all its cores are busy (the ceiling of any strong
#                  scaling on it): a compute-only loop (Python, no memory traffic) alone, then 8
#                  and 16 copies at once; and `vmap --threads 2 build` (MPI_SCENE, --count-links)
#                  alone and 8 copies at once; the seconds of each in $OUT/host.txt
#        profile   Nsight Compute (ncu --set full) on one batch of the kernel (VARIANTS, PROFILE_SCENE)
#        gi-throughput  vmap bench-gi on the GPU for .device/bin/vmap-before (bundled with
#                  BEFORE=/path/to/vmap) and vmap, interleaved; the side-by-side table of setup
#                  and per-bounce medians in $OUT/gi-throughput/gi-throughput.md
#                  (bench/gi-throughput.sh: BACKEND, GT_POINTS, GT_RUNS, ... pass through)
#        links     the per-node link arrays (bench/internal/links_bench.cpp) from the cornell-dragon h10 V-map
#                  at LINKS_LEAF_POINTS (default 1: 4.6e8 links), at LINKS_THREADS (default 16),
#                  LINKS_RUNS runs (default 3); tables in $OUT/links.md
#   bundle takes BEFORE=/path/to/vmap: another vmap binary (e.g. a device build of an older
#   commit), bundled as .device/bin/vmap-before for gi-throughput; and BUNDLE_TESTS="gpu_test
#   construction_test ...": only these test programs (default: every one; a full bundle with
#   BEFORE can pass what a call may carry, which the run tool counts less kindly than this
#   script's sum of file sizes: it refused one this script put at 63 MiB).
#      Logs and tables go to $OUT. At the end every file in $OUT goes into $OUT/logs.tgz (or
#      logs-2.tgz, logs-3.tgz, ... when an earlier run in the same call left one: a second run
#      does not overwrite the first's logs) and the *.log files are deleted (few files come back
#      from the device): redirect a caller's own output to a name not ending in .log and not
#      device-gpu.txt (e.g. $OUT/run.txt), and do not write logs*.tgz.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
cmd="${1:-}"
shift || true

# Debian's Open MPI runtime for `run mpi` (the GPU machine has no MPI): mpirun (orterun), orted,
# the components a one-host run loads (no InfiniBand, UCX, OFI, PSM, Slurm, MPI-IO or Java), their
# libraries and the help texts, laid out as under /usr so that OPAL_PREFIX relocates it (and
# PMIX_PREFIX, PMIx's). Into DEST (a prefix) and DEST/../lib (the libraries).
bundle_mpi() {
    local dest=$1 ompi=/usr/lib/x86_64-linux-gnu/openmpi pmix=/usr/lib/x86_64-linux-gnu/pmix2
    local mca=$dest/lib/x86_64-linux-gnu/openmpi/lib/openmpi3
    mkdir -p "$dest/bin" "$mca" "$dest/share/openmpi" "$dest/lib/x86_64-linux-gnu/pmix2/lib/pmix" \
        "$dest/lib/x86_64-linux-gnu/pmix2/share/pmix" "$dest/../lib"
    cp -L /usr/bin/orterun "$dest/bin/mpirun"
    cp -L /usr/bin/orted "$dest/bin/orted"
    for f in "$ompi"/lib/openmpi3/mca_*.so; do
        case $(basename "$f") in
            *ucx*|*ofi*|*psm*|*openib*|*verbs*|*slurm*|*flux*|*jsm*|*gridengine*|*monitoring*|\
            *romio*|*fcoll*|*fbtl*|*fs_ufs*|*sharedfp*|*io_ompio*|*memheap*|*scoll*|*spml*|\
            *sshmem*|*atomic_*|*vprotocol*|*treematch*|*bzip*|*crs_*|*simulator*|*netlink*) ;;
            *) cp "$f" "$mca/" ;;
        esac
    done
    cp "$pmix"/lib/pmix/*.so "$dest/lib/x86_64-linux-gnu/pmix2/lib/pmix/"
    cp /usr/share/openmpi/help-*.txt "$dest/share/openmpi/"
    cp "$pmix"/share/pmix/help-*.txt "$dest/lib/x86_64-linux-gnu/pmix2/share/pmix/"
    for so in libmpi.so.40 libopen-rte.so.40 libopen-pal.so.40 libhwloc.so.15 libpmix.so.2 \
              libevent_core-2.1.so.7 libevent_pthreads-2.1.so.7 libudev.so.1 libmunge.so.2 \
              libmca_common_sm.so.40; do
        cp -L "$(ldconfig -p | awk -v n="$so" '$1 == n {print $NF; exit}')" "$dest/../lib/$so"
    done
}
# The environment that runs the bundled Open MPI from PREFIX, as root, on this host only.
mpi_env() {
    export OPAL_PREFIX=$1 PMIX_PREFIX=$1/lib/x86_64-linux-gnu/pmix2 PATH=$1/bin:$PATH
    export PMIX_MCA_mca_base_component_path=$1/lib/x86_64-linux-gnu/pmix2/lib/pmix
    # PMIx of mpirun itself still looks in /usr for its three plugins: none of them is needed
    # on one host (compression, Slurm), so none is used here or there.
    export PMIX_MCA_pcompress=^zlib PMIX_MCA_prm=^default,slurm PMIX_MCA_pcompress_base_silence_warning=1
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
    export OMPI_MCA_btl=self,vader,tcp OMPI_MCA_pml=ob1 OMPI_MCA_btl_vader_single_copy_mechanism=none
}

if [[ "$cmd" == mpi-selftest ]]; then
    # The relocated runtime here, before it travels: copied to a fresh prefix, run with a clean
    # environment, and every file Open MPI opens must come from that prefix, not from /usr.
    t=$(mktemp -d)
    bundle_mpi "$t/mpi"
    cp "${1:-build-cpu/vmap}" "$t/vmap"
    env -i HOME="$t" bash -c "set -e; cd '$t'; $(declare -f mpi_env); mpi_env '$t/mpi'
        export LD_LIBRARY_PATH='$t/lib'
        strace -f -e trace=openat -o '$t/trace' mpirun -np 2 --oversubscribe ./vmap build \
            '$root/scenes/cornell-bunny.json' --points 2000 --max-height 5 --backend cpu -q -o a.vmap
        ./vmap build '$root/scenes/cornell-bunny.json' --points 2000 --max-height 5 --backend cpu \
            -q -o b.vmap
        cmp a.vmap b.vmap && echo 'relocated mpirun -np 2: byte-identical'"
    rc=$?
    echo "files under /usr/lib/x86_64-linux-gnu/{openmpi,pmix2} or /usr/share/openmpi opened:"
    grep -v ENOENT "$t/trace" | grep -E '"/usr/(lib/x86_64-linux-gnu/(openmpi|pmix2)|share/openmpi)' |
        grep -oE '"[^"]*"' | sort | uniq -c | head -20
    grep -v ENOENT "$t/trace" | grep -oE '"/[^"]*(libmpi|libopen-|libpmix|libhwloc|libevent|mca_)[^"]*"' |
        sed 's|^"'"$t"'|"PREFIX|' | sort | uniq -c | sort -rn | head -5
    du -sh "$t/mpi" "$t/lib"
    rm -rf "$t"
    exit $rc
fi

if [[ "$cmd" == bundle ]]; then
    cmake --preset device >/dev/null
    cmake --build build-device -j"$(nproc)"
    rm -rf .device
    mkdir -p .device/bin .device/lib .device/models
    cp build-device/vmap .device/bin/
    if [[ -n "${BEFORE:-}" ]]; then cp "$BEFORE" .device/bin/vmap-before; fi
    if [[ -n "${BUNDLE_TESTS:-}" ]]; then
        for t in $BUNDLE_TESTS; do cp "build-device/tests/$t" .device/bin/; done
    else
        cp build-device/tests/*_test .device/bin/
    fi
    # Benchmark drivers built as programs of their own, where the build has any.
    if [[ -d build-device/bench ]]; then
        find build-device/bench -maxdepth 1 -type f -executable -exec cp {} .device/bin/ \;
    fi
    for b in .device/bin/*; do ldd "$b" | awk '/=>/ {print $3}'; done | sort -u |
        grep -E 'lib(tbb|fmt|gtest|gmock|benchmark|embree|nlohmann|cpp-httplib|brotli|ssl|crypto)' |
        while read -r so; do cp -L "$so" .device/lib/; done
    strip --strip-unneeded .device/bin/* 2>/dev/null || true
    # Every model a scene or a test names (the test scenes' libcgal-demo meshes too), fetched
    # first where this checkout has none yet (a fresh clone: cached, idempotent).
    "$root/scripts/fetch-models.sh"
    # xz: the dragon's 34 MB PLY is 5.4 MB (gzip -1 made 10 MB, which with MPI and the tree
    # passed the 64 MiB a carry holds).
    for f in models/dragon.ply models/*.off; do
        xz -T0 -6 -c "$f" > ".device/models/$(basename "$f").xz"
    done
    cp build-device/tests/vmap_equal .device/bin/ 2>/dev/null || true
    # (grep -q would close the pipe early: ldd's SIGPIPE fails the test under pipefail)
    if ldd build-device/vmap | grep libmpi.so >/dev/null; then bundle_mpi .device/mpi; fi
    # Everything over 1 MB travels compressed (Embree alone is 43 MB; together the binaries and
    # libraries pass the 64 MiB a carry may hold); `run` unpacks them.
    find .device/lib .device/bin -type f -size +1M -exec xz -T0 -6 {} \;
    git rev-parse --short HEAD > .device/commit
    du -sh .device
    # What `run` carries: the tracked tree and .device, at most 64 MiB.
    total=$(( $(git ls-files -z | xargs -0 stat -c %s | awk '{s += $1} END {print s}') +
              $(du -sb .device | cut -f1) ))
    echo "carry: $((total / 1048576)) MiB of 64 (tree + .device)"
    (( total <= 64 * 1048576 )) || { echo "device.sh: the carry is over 64 MiB" >&2; exit 1; }
    (( total <= 60 * 1048576 )) ||
        echo "device.sh: over 60 MiB: the run tool may refuse it; bundle fewer tests (BUNDLE_TESTS)" >&2
    exit 0
fi

if [[ "$cmd" == run ]]; then
    [[ -d .device/bin ]] || {
        echo "device.sh run: no .device/bin here: run scripts/device.sh bundle on the build machine first, and carry .device" >&2
        exit 1
    }
    : "${OUT:=$root/out/device}"
    mkdir -p "$OUT"
    # The binaries find scenes, models and tests/data from their own folder up (vmap::data_dir()).
    export LD_LIBRARY_PATH="$root/.device/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    for f in .device/lib/*.xz .device/bin/*.xz; do [[ -e "$f" ]] && xz -d -k -f "$f"; done
    mkdir -p models
    for f in .device/models/*.xz; do
        n="models/$(basename "$f" .xz)"
        [[ -s "$n" ]] || xz -d -c "$f" > "$n"
    done
    nvidia-smi --query-gpu=name,memory.total,clocks.max.sm --format=csv > "$OUT/device-gpu.txt" 2>&1 || true
    cat "$OUT/device-gpu.txt"
    bin=.device/bin
    VMAP_COMMIT="$(cat .device/commit 2>/dev/null || echo unknown)"
    export VMAP_COMMIT
    san=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
    rc=0
    for step in "${@:-gpu}"; do
        echo "=== $step" >&2
        case "$step" in
            gpu)
                for t in gpu_test gi_gpu_test; do
                    [[ -x "$bin/$t" ]] || continue
                    "$bin/$t" > "$OUT/$t.log" 2>&1 || { rc=1; echo "FAILED $t"; }
                    grep -E "PASSED|FAILED|SKIPPED \]" "$OUT/$t.log" | tail -6
                done
                # Every OnEachBackend case's GPU instance (tests/backend_fixture.h), each against
                # its own oracle; on the device none may skip.
                for t in visibility_test vmap_build_test construction_test gi_test gi_reference_test; do
                    [[ -x "$bin/$t" ]] || continue
                    "$bin/$t" --gtest_filter='Cuda/*' > "$OUT/$t-cuda.log" 2>&1 || { rc=1; echo "FAILED $t (Cuda/*)"; }
                    if grep -q "SKIPPED \]" "$OUT/$t-cuda.log"; then rc=1; echo "SKIPPED $t (Cuda/*) on the device"; fi
                    echo "$t Cuda/*: $(grep -E "^\[  (PASSED|FAILED) " "$OUT/$t-cuda.log" | tr '\n' ' ')"
                done
                # The other kernel variants claim the same answers: check them too.
                for v in ${GPU_VARIANTS:-lane}; do
                    VMAP_CUDA_VARIANT=$v "$bin/gpu_test" --gtest_filter='*GpuMatchesCpu*:*Rect*' \
                        > "$OUT/gpu_test-$v.log" 2>&1 || { rc=1; echo "FAILED gpu_test ($v)"; }
                    echo "variant $v: $(grep -E "PASSED|FAILED" "$OUT/gpu_test-$v.log" | tail -1)"
                done ;;
            sanitize)
                # Each run stopped after SAN_TIMEOUT s (default 150: racecheck of the larger
                # cases has run past a call's 600 s), said as "cut", and counted as a failure.
                sanitized() {  # log name, tool, test binary, gtest filter
                    local log=$1 tool=$2 exe=$3 filter=$4 t0 code=0
                    [[ -x "$bin/$exe" ]] || return 0
                    t0=$(date +%s)
                    timeout "${SAN_TIMEOUT:-150}" "$san" --tool "$tool" --error-exitcode 9 "$bin/$exe" \
                        --gtest_filter="$filter" > "$OUT/$log.log" 2>&1 || code=$?
                    if [[ $code == 124 ]]; then
                        rc=1; echo "$log: cut after ${SAN_TIMEOUT:-150} s"
                    else
                        [[ $code == 0 ]] || rc=1
                        echo "$log ($(( $(date +%s) - t0 )) s, exit $code): $(grep -E "ERROR SUMMARY|RACECHECK SUMMARY" "$OUT/$log.log" | tail -1)"
                    fi
                }
                sanitized memcheck memcheck gpu_test 'GpuBackend.*:*cornell_bunny_h7*:*room_with_block*'
                sanitized racecheck racecheck gpu_test 'GpuBackend.Rect*:GpuBackend.Small*:*cornell_empty*'
                # parallel_for_device's kernels in a test of their own: the predicate cases.
                sanitized predicate-memcheck memcheck visibility_test 'Cuda/Fig7.*:Cuda/Facing.*:Cuda/EndPlanes.*'
                sanitized gi-memcheck memcheck gi_gpu_test '*cornell_empty*'
                sanitized gi-racecheck racecheck gi_gpu_test '*cornell_empty*' ;;
            embree)
                # Embree occlusion rays against the leaf-pair kernel on this machine's cores.
                "$bin/vmap" validate scenes/cornell-bunny.json scenes/cornell-two-models.json \
                    scenes/cornell-dragon.json --time-embree --heights 8 --runs 5 \
                    --embree-pairs 2000000 > "$OUT/embree.md" 2> "$OUT/embree.err" || rc=1
                tail -20 "$OUT/embree.md" ;;
            construction-test)
                "$bin/construction_test" > "$OUT/construction_test.log" 2>&1 || { rc=1; echo "FAILED construction_test"; }
                tail -3 "$OUT/construction_test.log" ;;
            cpu)
                for t in "$bin"/*_test; do
                    [[ "$(basename "$t")" == gpu_test ]] && continue
                    "$t" > "$OUT/$(basename "$t").log" 2>&1 || { rc=1; echo "FAILED $t"; }
                done ;;
            dragon)
                for lp in ${LEAF_POINTS:-4 8}; do
                    "$bin/vmap" build scenes/cornell-dragon.json -o /tmp/dragon.vmap --backend cuda \
                        --max-height 10 --leaf-points "$lp" 2>&1 | tee "$OUT/dragon-lp$lp.log" | head -13
                    rm -f /tmp/dragon.vmap
                done ;;
            construction)
                meth=(${CONS_METHOD:+--construction "$CONS_METHOD"} ${CONS_WALK_PAIRS:+--walk-pairs "$CONS_WALK_PAIRS"}
                      ${CONS_LANES:+--lanes "$CONS_LANES"})
                cons() {  # name, then vmap build arguments: one log per run, wall seconds too
                    # CONS_BINS: the binaries of .device/bin to run, interleaved run by run
                    # (default vmap; e.g. "vmap vmap-before", bundled with BEFORE=); with more
                    # than one, each run's -o file is compared with the first binary's.
                    local name=$1; shift
                    local bins=(${CONS_BINS:-vmap})
                    for r in $(seq "${CONS_RUNS:-3}"); do
                        for vb in "${bins[@]}"; do
                            local tag=$name t0
                            [[ ${#bins[@]} -gt 1 ]] && tag=$name-$vb
                            t0=$(date +%s.%N)
                            timeout "${CONS_TIMEOUT:-590}" "$bin/$vb" -v build "$@" > "$OUT/cons-$tag-$r.log" 2>&1 ||
                                { rc=1; echo "FAILED $tag (rc $?)"; }
                            echo "wall $(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN{print b - a}')" >> "$OUT/cons-$tag-$r.log"
                            { grep -E "^construction|^time:|^ +plan|^saving:|^wall|^device|^throughput|^leaf pairs:" "$OUT/cons-$tag-$r.log" |
                                tr '\n' ' '; echo " [$tag $r]"; } | tee -a "$OUT/construction.txt"
                            if [[ ${#bins[@]} -gt 1 && -f /tmp/cons.vmap ]]; then
                                if [[ $vb == "${bins[0]}" ]]; then mv /tmp/cons.vmap /tmp/cons-first.vmap
                                else { cmp /tmp/cons.vmap /tmp/cons-first.vmap && echo "$tag $r: byte-identical to ${bins[0]}" ||
                                       { rc=1; echo "$tag $r: DIFFERS from ${bins[0]}"; }; } | tee -a "$OUT/construction.txt"
                                fi
                            fi
                        done
                    done
                    rm -f /tmp/cons-first.vmap
                }
                for lp in ${CONS_LEAF_POINTS:-8 4 1}; do
                    cons "lp$lp" scenes/cornell-dragon.json --backend cuda --max-height 10 \
                        --leaf-points "$lp" -o /tmp/cons.vmap "${meth[@]}"
                    if [[ " ${CONS_ORACLE:-} " == *" $lp "* ]]; then
                        CONS_RUNS=1 cons "lp$lp-oracle" scenes/cornell-dragon.json --backend cuda --max-height 10 \
                            --leaf-points "$lp" -o /tmp/cons-o.vmap --construction leaf-pairs
                        { cmp /tmp/cons.vmap /tmp/cons-o.vmap && echo "lp$lp: byte-identical" ||
                            { rc=1; echo "lp$lp: FILES DIFFER"; }; } | tee -a "$OUT/construction.txt"
                        rm -f /tmp/cons-o.vmap
                    fi
                    rm -f /tmp/cons.vmap
                done
                for n in ${CONS_POINTS:-}; do
                    cons "n$n" scenes/cornell-dragon.json --backend cuda --max-height 12 \
                        --leaf-points 1 --points "$n" --count-links "${meth[@]}"
                done
                if [[ "${CONS_BIG:-0}" == 1 ]]; then
                    CONS_RUNS=1 CONS_TIMEOUT=${CONS_BIG_TIMEOUT:-300} cons big scenes/cornell-dragon.json \
                        --backend cuda --max-height 12 --leaf-points 1 --points 1100000 --count-links "${meth[@]}"
                fi ;;
            ab)
                for v in ${VARIANTS:-packet lane}; do
                    echo "variant $v"
                    VMAP_CUDA_VARIANT=$v "$bin/vmap" build scenes/cornell-dragon.json -o /tmp/ab.vmap \
                        --backend cuda --max-height 9 --leaf-points "${AB_LEAF_POINTS:-8}" 2>&1 |
                        tee "$OUT/ab-$v.log" | grep -E "throughput|time:"
                    rm -f /tmp/ab.vmap
                done ;;
            bench)
                for lp in ${BENCH_LEAF_POINTS:-4}; do
                    "$bin/vmap" bench ${BENCH_ARGS:-} --leaf-points "$lp" --out "$OUT/lp$lp" 2>&1 |
                        tee "$OUT/bench-lp$lp.log" | tail -12
                done ;;
            mpi)
                mpi_env "$root/.device/mpi"
                read -r -a scene <<< "${MPI_SCENE:-scenes/cornell-bunny.json --points 30000}"
                sum="$OUT/mpi-summary.md"
                ref=/tmp/mpi-ref.vmap
                "$bin/vmap" build "${scene[@]}" --backend cpu -o "$ref" > "$OUT/mpi-ref.log" 2>&1 || rc=1
                { echo "# mpirun -np P vmap --threads T build ${scene[*]}, $(nproc) cores, $(date -u +%F)"
                  grep -E "^(points|octree|links):" "$OUT/mpi-ref.log"
                  echo
                  echo "| run | P | T | backend | schedule | wall s | slowest rank s | slowest/mean | identical |"
                  echo "|---|---:|---:|---|---|---:|---:|---:|---|"; } > "$sum"
                mrun() {  # label P T backend schedule [more build args]
                    local label=$1 np=$2 th=$3 be=$4 sc=$5; shift 5
                    local out=/tmp/mpi-$label.vmap t0; t0=$(date +%s.%N)
                    # shellcheck disable=SC2086  # MAP: mpirun's placement options, split on purpose
                    mpirun -np "$np" --oversubscribe ${MAP:---bind-to none} "$bin/vmap" --threads "$th" build "${scene[@]}" \
                        --backend "$be" --schedule "$sc" -o "$out" "$@" > "$OUT/mpi-$label.log" 2>&1 ||
                        { rc=1; echo "FAILED $label"; tail -5 "$OUT/mpi-$label.log"; }
                    local wall; wall=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN{printf "%.2f", b - a}')
                    local cons imb same=NO
                    cons=$(grep -oE 'per rank [0-9.]+-[0-9.]+' "$OUT/mpi-$label.log" | sed 's/.*-//' || true)
                    imb=$(grep -oE 'slowest / mean [0-9.]+' "$OUT/mpi-$label.log" | awk '{print $4}' || true)
                    if [[ " $* " == *" --shards "* ]]; then
                        "$bin/vmap_equal" "$ref" "$out" && same="yes (shards)"
                        rm -f "$out".*
                    else cmp -s "$ref" "$out" && same=yes; fi
                    [[ "$same" == NO ]] && rc=1
                    echo "| $label | $np | $th | $be | $sc | $wall | $cons | $imb | $same |" >> "$sum"
                    sed -n "s/^phases: *slowest rank's s: /$label (wall $wall): /p" "$OUT/mpi-$label.log" >> "$sum.phases"
                    rm -f "$out"
                }
                th=${MPI_THREADS:-2}
                # MPI_REPEAT=R: the strong-scaling sweep R times, alternating (the table below
                # takes each P's median).
                for _ in $(seq "${MPI_REPEAT:-1}"); do
                    for np in 1 2 4 8; do mrun "cpu-$np" "$np" "$th" cpu dynamic; done
                done
                # The same with each rank bound to T cores of its own (MPI_BOUND=0: skipped).
                if [[ "${MPI_BOUND:-1}" != 0 ]]; then
                    for np in 1 2 4 8; do
                        MAP="--map-by slot:PE=$th --bind-to core" mrun "bound-$np" "$np" "$th" cpu dynamic
                    done
                fi
                if [[ "${MPI_EXTRA:-1}" != 0 ]]; then  # MPI_EXTRA=0: the scaling runs only
                    for per in 32 64; do mrun "cpu-8-c$per" 8 "$th" cpu dynamic --chunks-per-rank "$per"; done
                    mrun cpu-8-static 8 "$th" cpu static
                    mrun cpu-4-static 4 "$th" cpu static
                    for np in 1 2 4; do mrun "cores-$np" "$np" $((16 / np)) cpu dynamic; done
                fi
                mrun shards-4 4 4 cpu dynamic --shards
                mrun gpu-1 1 16 cuda dynamic
                mrun gpu-2-shared 2 8 cuda dynamic
                "$bin/gpu_test" --gtest_filter='GpuDevice.*' > "$OUT/mpi-gpu-device.log" 2>&1 || rc=1
                echo "--device test: $(grep -E 'PASSED|FAILED|SKIPPED \]' "$OUT/mpi-gpu-device.log" | tail -1)" >> "$sum"
                # Strong scaling at T threads a rank: speedup and efficiency against P = 1.
                # With repeats, each P's median wall and median slowest rank (and their ranges).
                awk -F'|' 'function med(a, n,   i, j, t) {for (i = 2; i <= n; i++) for (j = i; j > 1 && a[j - 1] > a[j]; j--) {t = a[j]; a[j] = a[j - 1]; a[j - 1] = t}
                                                    return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2}
                    $2 ~ /(cpu|bound)-[1248] / {split($2, l, "-"); k = l[1]; gsub(/ /, "", k); p = $3 + 0;
                                                n[k, p]++; W[k, p, n[k, p]] = $7 + 0; C[k, p, n[k, p]] = $8 + 0; ks[k] = 1}
                    END {for (k in ks) for (p = 1; p <= 8; p *= 2) if (n[k, p] > 0) {
                             m = n[k, p]; split("", a); split("", b)
                             for (i = 1; i <= m; i++) {a[i] = W[k, p, i]; b[i] = C[k, p, i]}
                             w[k, p] = med(a, m); c[k, p] = med(b, m); runs[k, p] = m
                             range[k, p] = m > 1 ? sprintf(" (%.2f-%.2f)", a[1], a[m]) : ""}
                         print "\n| runs | P | runs of each | wall s, median (range) | speedup (wall) | efficiency (wall) | speedup (slowest rank) | efficiency (slowest rank) |";
                         print "|---|---:|---:|---|---:|---:|---:|---:|";
                         for (k in ks) for (p = 1; p <= 8; p *= 2) if (w[k, p] > 0)
                             printf "| %s | %d | %d | %.2f%s | %.2f | %.2f | %.2f | %.2f |\n", k, p, runs[k, p], w[k, p], range[k, p],
                                    w[k, 1] / w[k, p], w[k, 1] / w[k, p] / p, c[k, 1] / c[k, p], c[k, 1] / c[k, p] / p}' \
                    "$sum" >> "$sum.tail" && cat "$sum.tail" >> "$sum" && rm -f "$sum.tail"
                { echo; echo "Phases, the slowest rank's seconds (src/mpi/mpi_build.cpp):"
                  cat "$sum.phases"; } >> "$sum" && rm -f "$sum.phases"
                grep -h "^mpi:\|^note:" "$OUT"/mpi-cpu-8.log "$OUT"/mpi-gpu-2-shared.log >> "$sum" || true
                rm -f "$ref"
                cat "$sum" ;;
            host)
                read -r -a scene <<< "${MPI_SCENE:-scenes/cornell-bunny.json --points 60000}"
                h="$OUT/host.txt"
                spin='import time
t = time.time(); x = 0
for i in range(30_000_000): x += i * i % 7
print("%.2f" % (time.time() - t))'
                at_once() {  # N, then a command: N copies at once, their seconds sorted
                    local n=$1; shift
                    for i in $(seq "$n"); do "$@" > "$OUT/host-$i.out" 2>&1 & done
                    wait
                    for i in $(seq "$n"); do tail -1 "$OUT/host-$i.out"; done | sort -n | tr '\n' ' '
                    rm -f "$OUT"/host-*.out
                }
                build_s() {  # the build's own total (s), from -v
                    "$bin/vmap" --threads 2 build "${scene[@]}" --backend cpu --count-links -v 2>&1 |
                        sed -n 's/^time: *\([0-9.]*\) s total.*/\1/p'
                }
                { echo "# the host with its cores busy, $(nproc) cores, $(date -u +%F), commit $VMAP_COMMIT"
                  echo "compute loop, alone: $(at_once 1 python3 -c "$spin")"
                  echo "compute loop, 8 at once: $(at_once 8 python3 -c "$spin")"
                  echo "compute loop, 16 at once: $(at_once 16 python3 -c "$spin")"
                  echo "vmap --threads 2 build ${scene[*]} --count-links, alone: $(at_once 1 build_s)"
                  echo "the same, 8 at once: $(at_once 8 build_s)"; } > "$h"
                cat "$h" ;;
            links)
                lp=${LINKS_LEAF_POINTS:-1}
                "$bin/vmap" -v build scenes/cornell-dragon.json --backend cuda --max-height 10 \
                    --leaf-points "$lp" -o /tmp/links.vmap > "$OUT/links-build.log" 2>&1 || rc=1
                grep -E "^links:|link arrays" "$OUT/links-build.log" | tee -a "$OUT/links.md"
                for th in ${LINKS_THREADS:-16}; do
                    "$bin/links_bench" /tmp/links.vmap --threads "$th" --runs "${LINKS_RUNS:-3}" 2>&1 |
                        tee -a "$OUT/links.md" || rc=1
                done
                rm -f /tmp/links.vmap ;;
            profile)
                # Nsight Compute on one batch of the leaf-pair kernel (VARIANTS, default scene).
                ncu=$(command -v ncu || ls /usr/local/cuda*/bin/ncu /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1 || true)
                if [[ -z "$ncu" ]]; then echo "no ncu"; continue; fi
                for v in ${VARIANTS:-packet}; do
                    VMAP_CUDA_VARIANT=$v "$ncu" --kernel-name regex:leaf_pairs --launch-skip 1 \
                        --launch-count 1 --set full "$bin/vmap" build ${PROFILE_SCENE:-scenes/cornell-bunny.json} \
                        -o /tmp/prof.vmap --backend cuda > "$OUT/profile-$v.txt" 2>&1 || true
                    grep -E "Duration|Throughput|Achieved Occupancy|Registers Per|Warp Cycles Per Issued|Avg. Active Threads|Hit Rate|Stall|Issued Ipc|No Eligible" "$OUT/profile-$v.txt" | head -40
                done ;;
            gi-throughput)
                if [[ ! -x "$bin/vmap-before" ]]; then
                    echo "gi-throughput: no $bin/vmap-before (bundle with BEFORE=/path/to/vmap)"; rc=1; continue
                fi
                bench/gi-throughput.sh "$OUT/gi-throughput" "$bin/vmap-before" "$bin/vmap" || rc=1 ;;
            *) echo "unknown step $step" >&2; rc=2 ;;
        esac
    done
    # Only a few files come back from the device: every log travels in one archive, and the
    # summaries beside it.
    archive=logs.tgz
    for k in $(seq 2 99); do [[ -e "$OUT/$archive" ]] && archive=logs-$k.tgz; done
    (cd "$OUT" && find . -maxdepth 1 -type f ! -name 'logs*.tgz' -printf '%P\n' |
        tar czf "$archive" -T - && find . -maxdepth 1 -type f \( -name '*.log' \) -delete)
    exit $rc
fi
echo "usage: scripts/device.sh bundle | run [gpu|sanitize|cpu|dragon|bench|links|...]..." >&2
exit 2
