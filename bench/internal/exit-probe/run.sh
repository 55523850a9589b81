#!/usr/bin/env bash
# On the GPU machine (carry .device, after build.sh): each exit mode 3 times, interleaved;
# prints "MODE MB pinned?: seconds from the program's last line to the shell seeing it end".
set -u
exe="${1:-.device/bin/exit_probe}"
for r in 1 2 3; do
    for args in "200 return" "200 quick" "200 free" "2000 return" "2000 quick" "200 return p" "200 quick p"; do
        line=$($exe $args | tail -1); e=$(date +%s.%N)
        awk -v a="$e" -v b="${line%% *}" -v w="$args" 'BEGIN { printf "%s: %.3f s\n", w, a - b }'
    done
done
