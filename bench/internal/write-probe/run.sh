#!/usr/bin/env bash
# On the GPU machine: write_probe at 2000 MiB (the lp1 save's size) and 700 MiB (lp4's) with 16
# threads into /tmp (where `scripts/device.sh run construction` saves), three rounds, every mode.
set -u
exe="${1:-.device/bin/write_probe}"
df -hT /tmp | tail -1
for r in 1 2 3; do
    $exe 2000 /tmp/wp.bin 16 pwrite pwsfr mmap mmapsfr
    $exe 700 /tmp/wp.bin 16 pwsfr mmap mmapsfr
done
# The first touch of fresh memory (bench/internal/touch-probe): huge pages (allocate_huge's
# MADV_HUGEPAGE) against 4 KiB pages, 4000 MiB (the lp1 link targets' size) with 16 threads.
tp="${2:-bench/internal/touch-probe/touch_probe}"
cat /sys/kernel/mm/transparent_hugepage/enabled /sys/kernel/mm/transparent_hugepage/defrag
for r in 1 2 3; do $tp 4000 16; $tp 4000 16 small; $tp 700 16; $tp 700 16 small; done
