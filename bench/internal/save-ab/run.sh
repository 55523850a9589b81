#!/usr/bin/env bash
# The save alone, before and after: one V-map loaded, then saved 7 times by the save of commit
# BEFORE (default c1a5376: links coded into a fresh buffer a chunk; hash, then write, then
# fsync) and by this tree's (chunks counted, then coded into one array; each 8 MiB chunk of the
# file hashed as it is written, its writeback started at once, the header last). Medians [min-max]
# per call; the two files compared. Needs build-cpu (libvmap_core.a) built from this tree.
# Usage: bench/internal/save-ab/run.sh MAP.vmap [OUT_FOLDER]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
map="${1:?usage: run.sh MAP.vmap [OUT_FOLDER]}"
out="${2:-/tmp}"
before="${BEFORE:-c1a5376}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/inc/vmap" "$work/inc/io"
git -C "$root" show "$before:src/io/vmap_file.cpp" > "$work/vmap_file.cpp"
git -C "$root" show "$before:src/io/link_codec.cpp" > "$work/link_codec.cpp"
git -C "$root" show "$before:src/io/link_codec.h" > "$work/inc/io/link_codec.h"
git -C "$root" show "$before:src/io/atomic_file.cpp" > "$work/atomic_file.cpp"
git -C "$root" show "$before:include/vmap/files.h" > "$work/inc/vmap/files.h"
flags=(-O3 -DNDEBUG -std=c++20 -mpopcnt -ffp-contract=off -I"$root/src" -I"$root/include"
       -include vmap/version.h)
libs=("$root/build-cpu/libvmap_core.a" -ltbb -lfmt -lembree3 -lstreamvbyte)
src="$root/bench/internal/save-ab/save_ab.cpp"
g++ "${flags[@]}" "$src" -o "$work/new" "${libs[@]}"
g++ "${flags[@]}" -I"$work/inc" -c "$work/atomic_file.cpp" -o "$work/af.o"
g++ -I"$work/inc" "${flags[@]}" -c "$work/vmap_file.cpp" -o "$work/vf.o"
g++ -I"$work/inc" "${flags[@]}" -c "$work/link_codec.cpp" -o "$work/lc.o"
# The old objects first: their definitions win over the archive's (a probe, not a build).
g++ "${flags[@]}" -DOLD "$src" "$work/vf.o" "$work/lc.o" "$work/af.o" -o "$work/old" \
    -Wl,--allow-multiple-definition "${libs[@]}"
for r in 1 2 3; do
    "$work/old" "$map" "$out/save-ab-old.vmap" "before ($before)"
    "$work/new" "$map" "$out/save-ab-new.vmap" "after"
done
cmp "$out/save-ab-old.vmap" "$out/save-ab-new.vmap" && echo "files byte-identical"
rm -f "$out/save-ab-old.vmap" "$out/save-ab-new.vmap"
