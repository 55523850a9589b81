# One device call (carry .device, bundled with BEFORE=<device build of 782f359>, and
# bench/internal/input-probe/build.sh for .device/bin/input_probe): the save A/B of issue 15 at
# lp4 and lp1, the input probe at 16, 4 and 1 threads, and the lp4 build with each stdout line
# timestamped (stdbuf) to time what follows "wrote:" (the exit). Run: bash bench/internal/save-ab/device-call.sh
# Without a vmap-before in the bundle (no BEFORE=), the tree's binary alone (CONS_BINS=vmap).
bins="vmap"; [[ -e .device/bin/vmap-before || -e .device/bin/vmap-before.xz ]] && bins="vmap vmap-before"
export OUT; CONS_BINS="${CONS_BINS:-$bins}" CONS_LEAF_POINTS="${CONS_LEAF_POINTS:-4 1}" CONS_RUNS=${CONS_RUNS:-2} bash scripts/device.sh run construction > $OUT/run.txt 2>&1; echo "rc $?" >> $OUT/run.txt
export LD_LIBRARY_PATH=$PWD/.device/lib
for t in 16 4 1; do .device/bin/input_probe scenes/cornell-dragon.json $t; done > $OUT/input.txt 2>&1
for r in 1 2; do s=$(date +%s.%N); stdbuf -oL .device/bin/vmap -v build scenes/cornell-dragon.json --backend cuda --max-height 10 --leaf-points 4 -o /tmp/x.vmap | while IFS= read -r l; do echo "$(date +%s.%N) $l"; done > $OUT/exit-$r.txt; e=$(date +%s.%N); echo "start $s end $e" >> $OUT/exit-$r.txt; done
rm -f /tmp/x.vmap
grep -oE "saving [0-9.]+ s|saving: .*disk [0-9.]+ s|wall [0-9.]+ .*\]|byte-identical.*|DIFFERS.*" $OUT/construction.txt
grep -E "^threads [0-9]+:|^  " $OUT/input.txt | tail -40
for r in 1 2; do head -1 $OUT/exit-$r.txt | cut -c1-40; grep -E "wrote|time:  |start" $OUT/exit-$r.txt; done
