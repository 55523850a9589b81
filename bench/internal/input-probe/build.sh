#!/usr/bin/env bash
# Builds input_probe (input_probe.cpp): where `vmap build SCENE`'s input goes at a thread count,
# with sampling.cpp and elimination.cpp timed by timing.patch (applied to copies, not to the
# tree). Needs build-cpu (libvmap_core.a). Writes OUT (default .device/bin/input_probe, for
# the GPU machine: it loads only libtbb and libfmt, which the bundle carries).
# Run: input_probe scenes/cornell-dragon.json 16   (then 4, 1: the part that does not scale)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
out="${1:-$root/.device/bin/input_probe}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/src/scene"
cp "$root/src/scene/sampling.cpp" "$root/src/scene/elimination.cpp" "$work/src/scene/"
(cd "$work" && patch -s -p1 < "$root/bench/internal/input-probe/timing.patch")
flags=(-O3 -DNDEBUG -std=c++20 -mpopcnt -ffp-contract=off -I"$root/src" -I"$root/include"
       -include vmap/version.h)
g++ "${flags[@]}" -c "$work/src/scene/sampling.cpp" -o "$work/s.o"
g++ "${flags[@]}" -c "$work/src/scene/elimination.cpp" -o "$work/e.o"
# The timed objects first: their definitions win over the archive's (a probe, not a build).
g++ "${flags[@]}" "$root/bench/internal/input-probe/input_probe.cpp" "$work/s.o" "$work/e.o" \
    -o "$out" -Wl,--allow-multiple-definition "$root/build-cpu/libvmap_core.a" -ltbb -lfmt \
    -lembree3 /usr/lib/x86_64-linux-gnu/libstreamvbyte.a
echo "input_probe: $out"
