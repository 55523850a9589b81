#!/usr/bin/env bash
# GI runs on the lent GPU machine. Here: `scripts/device.sh bundle` (builds build-device for
# sm_90 and gathers binaries, libraries and models into .device/). There (carry .device):
#   scripts/gi-device.sh STEP...
#       gpu     tests/gi_gpu_test (CPU vs CUDA radiosity, bit for bit)
#       check   gi_gpu_test (refinement, bounces, final gather: CPU vs CUDA bit for bit), then
#               compute-sanitizer memcheck and racecheck on it (small cases), then vmap gi on
#               cornell-two-models twice (timing); one summary in $OUT/gi-check.txt
#       full    vmap gi --reference on cornell-two-models and cornell-dragon (SCENES) at their
#               full point counts, the V-map at each of KS (default 2), EPS (default 0.01),
#               WINDOWS (--end-window, default 2) and FLOORS (--delta-floor, default 2),
#               REF_POINTS (default 1000) + as many model points; the summary lines appended to
#               $OUT/gi-check.txt
#       two     vmap gi on cornell-two-models (Fig. 12, 150,000 points; GI_ARGS: more options),
#               PNG + log
#       bunny   vmap gi on the default scene, PNG + log
#       bench   vmap bench-gi (POINTS, default 5000..80000; BRUTE_MAX, default 40000)
#       ref     vmap gi --reference on every shipped scene (the error table, docs/gi.md), CSVs,
#               and the side-by-side picture of cornell-two-models (REF_PICTURE_SAMPLES, 512)
#   Outputs go to $OUT.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
[[ -d .device/bin ]] || {
    echo "gi-device.sh: no .device/bin here: run scripts/device.sh bundle on the build machine first, and carry .device" >&2
    exit 1
}
: "${OUT:=$root/out/device}"
mkdir -p "$OUT"
# The binaries find scenes and models from their own folder up (vmap::data_dir()).
export LD_LIBRARY_PATH="$root/.device/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# The bundle compresses the large libraries and the test binaries.
for f in .device/lib/*.xz .device/bin/*.xz; do [[ -e "$f" ]] && xz -d -k -f "$f"; done
mkdir -p models
# The bundle's models are xz-compressed (scripts/device.sh bundle).
for f in .device/models/*.xz; do
    [[ -e "$f" ]] || continue
    n="models/$(basename "$f" .xz)"
    [[ -s "$n" ]] || xz -d -c "$f" >"$n"
done
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader >"$OUT/gpu.txt" 2>&1 || true
cat "$OUT/gpu.txt"
bin=.device/bin
rc=0
for step in "$@"; do
    echo "=== $step" >&2
    case "$step" in
        gpu)
            "$bin/gi_gpu_test" >"$OUT/gi_gpu_test.log" 2>&1 || rc=1
            tail -4 "$OUT/gi_gpu_test.log" ;;
        check)
            {
                "$bin/gi_gpu_test" >"$OUT/gi_gpu_test.log" 2>&1 || rc=1
                grep -E "^\[  (PASSED|FAILED) |FAILED|SKIPPED \]" "$OUT/gi_gpu_test.log" | head -20 || true
                san=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
                for tool in memcheck racecheck; do
                    "$san" --tool "$tool" --error-exitcode 9 "$bin/gi_gpu_test" \
                        --gtest_filter='GiGpu.*:*cornell_empty*' >"$OUT/gi-$tool.log" 2>&1 || rc=1
                    echo "$tool: $(grep -E "ERROR SUMMARY|PASSED|FAILED" "$OUT/gi-$tool.log" | tr '\n' ' ')"
                done
                for r in 1 2; do
                    TIMEFORMAT="wall %R s, user %U s, sys %S s"
                    { time "$bin/vmap" gi scenes/cornell-two-models.json --backend cuda \
                        -o "$OUT/two-$r.png" >"$OUT/two-$r.log" 2>&1 || rc=1; } 2>>"$OUT/two-$r.log"
                    echo "two-models run $r:"
                    grep -E "^(input|scene|mesh|backend|refinement|converged|gather|wall|note)" "$OUT/two-$r.log" |
                        cut -c1-220 || true
                done
            } > >(tee "$OUT/gi-check.txt") 2>&1 ;;
        full)
            for sc in ${SCENES:-cornell-two-models cornell-dragon}; do
              for k in ${KS:-2}; do
                for e in ${EPS:-0.01}; do
                  for w in ${WINDOWS:-2}; do
                    for f in ${FLOORS:-2}; do
                        log="$OUT/full-$sc-K$k-eps$e-w$w-f$f.log"
                        "$bin/vmap" gi "scenes/$sc.json" --reference \
                            --ref-points "${REF_POINTS:-1000}" --ref-samples 1024 --backend cuda \
                            --no-brute -K "$k" --eps "$e" --end-window "$w" --delta-floor "$f" \
                            --ref-out "$OUT/full-$sc-K$k-eps$e-w$w-f$f.csv" >"$log" 2>&1 || rc=1
                        echo "$sc, K $k, eps $e, end window $w, delta floor $f:"
                        grep -E "^(scene|vmap gi:)|converged \(|\| 1 \||V-map visibility vs|exact visibility between" \
                            "$log" | grep -v "reference noise" | cut -c1-200 || true
                    done
                  done
                done
              done
            done > >(tee -a "$OUT/gi-check.txt") 2>&1 ;;
        two)
            # shellcheck disable=SC2086 # GI_ARGS: extra options, word-split on purpose
            "$bin/vmap" gi scenes/cornell-two-models.json -o "$OUT/gi-cornell-two-models.png" \
                --size 640x640 --backend cuda ${GI_ARGS:-} 2>&1 | tee "$OUT/two-models.log" |
                grep -vE "^bounce" || rc=1 ;;
        bunny)
            "$bin/vmap" gi scenes/cornell-bunny.json -o "$OUT/gi-cornell-bunny.png" \
                --size 640x640 --backend cuda 2>&1 | tee "$OUT/bunny.log" || rc=1 ;;
        bench)
            "$bin/vmap" bench-gi --points "${POINTS:-5000,10000,20000,40000,80000}" \
                --brute-max "${BRUTE_MAX:-40000}" --runs 3 --out "$OUT" 2>&1 | tail -15 || rc=1 ;;
        ref)
            for sc in cornell-empty cornell-bunny cornell-two-models cornell-dragon; do
                extra=()
                [[ $sc == cornell-empty || $sc == cornell-bunny ]] || extra=(--no-brute)
                [[ $sc == cornell-two-models ]] && extra+=(-o "$OUT/gi-reference-$sc.png" \
                    --size 480x480 --ref-picture-samples "${REF_PICTURE_SAMPLES:-512}")
                "$bin/vmap" gi "scenes/$sc.json" --reference --ref-points 2000 --ref-samples 1024 \
                    --backend cuda --ref-out "$OUT/ref-$sc.csv" "${extra[@]}" 2>&1 |
                    tee "$OUT/ref-$sc.log" | grep -E "^(scene|reference|vmap gi|brute)|default" || rc=1
            done ;;
        *)
            echo "unknown step $step (gpu, two, bunny, bench, ref)" >&2
            rc=2 ;;
    esac
done
exit $rc
