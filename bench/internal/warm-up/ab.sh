#!/bin/bash
# On the device (carry .device and bench/internal/warm-up/ctx, built here with
#   nvcc -O2 -arch=sm_90 -cudart static -o bench/internal/warm-up/ctx bench/internal/warm-up/ctx.cu):
#   scripts/device.sh run none; bash bench/internal/warm-up/ab.sh   (at ccc0691, whose vmap had the switch)
# A/B of the CUDA warm-up during input (VMAP_NO_WARM=1 switched it off at ccc0691 only), interleaved.
set -u
OUT=${OUT:-/tmp/out}; mkdir -p $OUT
export LD_LIBRARY_PATH=$PWD/.device/lib
B=.device/bin/vmap
for i in 1 2 3; do bench/internal/warm-up/ctx; done | tee $OUT/ctx.txt
run() {  # tag, warm(0/1), args...
    local tag=$1 w=$2; shift 2
    local t0=$(date +%s.%N)
    if [ $w = 0 ]; then VMAP_NO_WARM=1 $B -v build "$@" > $OUT/$tag.txt 2>&1; else $B -v build "$@" > $OUT/$tag.txt 2>&1; fi
    local t1=$(date +%s.%N)
    echo "$tag warm=$w wall $(awk "BEGIN{printf \"%.3f\", $t1 - $t0}") | $(grep -h '^time:' $OUT/$tag.txt | tr '\n' ' ' | cut -c1-200)"
}
run prime 1 scenes/cornell-dragon.json -o /tmp/d.vmap --backend cuda --max-height 10 --leaf-points 4
for i in 1 2 3 4; do for w in 0 1; do
    run bunny-$w-$i $w -o /tmp/b.vmap --backend cuda
done; done
for i in 1 2 3 4; do for w in 0 1; do
    run lp4-$w-$i $w scenes/cornell-dragon.json -o /tmp/d.vmap --backend cuda --max-height 10 --leaf-points 4
done; done
for i in 1 2; do for w in 0 1; do
    run lp1-$w-$i $w scenes/cornell-dragon.json -o /tmp/d.vmap --backend cuda --max-height 10 --leaf-points 1
done; done
cmp /tmp/d.vmap /tmp/d.vmap && echo done
