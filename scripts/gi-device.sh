#!/usr/bin/env bash
# GI runs on the lent GPU machine (see scripts/device.sh for the V-map ones):
#   scripts/gi-device.sh bundle   (here) gather build/ (default preset, sm_90) binaries, the
#                                 shared libraries they load and the models into .device/
#   scripts/gi-device.sh run STEP...   (there; carry .device) steps:
#       gpu     tests/gi_gpu_test (CPU vs CUDA radiosity, bit for bit)
#       two     vmap gi on cornell-two-models (Fig. 12), GPU V-map and bounces, PNG + log
#       bunny   vmap gi on the default scene, PNG + log
#       bench   vmap bench-gi (POINTS, default 5000..80000; BRUTE_MAX, default 40000)
#   Outputs go to $OUT.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
cmd="${1:-}"
shift || true
if [[ "$cmd" == bundle ]]; then
    cmake --build build -j2 --target vmap gi_gpu_test
    rm -rf .device
    mkdir -p .device/bin .device/lib .device/models
    cp build/vmap build/tests/gi_gpu_test .device/bin/
    for b in .device/bin/*; do ldd "$b" | awk '/=>/ {print $3}'; done | sort -u |
        grep -E 'lib(tbb|fmt|gtest|gmock)' | while read -r so; do cp -L "$so" .device/lib/; done
    cp -L models/bunny.off models/armadillo.off .device/models/
    echo "$root" > .device/source_dir
    git rev-parse --short HEAD > .device/commit
    du -sh .device
    exit 0
fi
if [[ "$cmd" == run ]]; then
    : "${OUT:=$root/out/device}"
    mkdir -p "$OUT"
    src="$(cat .device/source_dir)"
    if [[ "$src" != "$root" && ! -e "$src" ]]; then mkdir -p "$(dirname "$src")"; ln -s "$root" "$src"; fi
    [[ -d models && ! -L models ]] || { rm -f models; mkdir -p models; }
    cp -n .device/models/* models/
    export LD_LIBRARY_PATH="$root/.device/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    nvidia-smi --query-gpu=name,memory.total --format=csv,noheader > "$OUT/gpu.txt" 2>&1 || true
    cat "$OUT/gpu.txt"
    bin=.device/bin
    rc=0
    for step in "$@"; do
        echo "=== $step" >&2
        case "$step" in
            gpu) "$bin/gi_gpu_test" > "$OUT/gi_gpu_test.log" 2>&1 || rc=1
                 tail -4 "$OUT/gi_gpu_test.log" ;;
            two) "$bin/vmap" gi scenes/cornell-two-models.json -o "$OUT/cornell-two-models-gi.png" \
                     --backend cuda 2>&1 | tee "$OUT/two-models.log" || rc=1 ;;
            bunny) "$bin/vmap" gi scenes/cornell-bunny.json -o "$OUT/cornell-bunny-gi.png" \
                     --backend cuda 2>&1 | tee "$OUT/bunny.log" || rc=1 ;;
            bench) "$bin/vmap" bench-gi --points "${POINTS:-5000,10000,20000,40000,80000}" \
                     --brute-max "${BRUTE_MAX:-40000}" --runs 3 --out "$OUT" 2>&1 |
                     tail -15 || rc=1 ;;
            *) echo "unknown step $step" >&2; rc=2 ;;
        esac
    done
    exit $rc
fi
echo "usage: $0 bundle | run STEP..." >&2
exit 2
