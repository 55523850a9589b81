#!/usr/bin/env bash
# The main job: set up (Debian packages, models), build, and compute the V-map of the default
# scene (scenes/cornell-bunny.json) into out/cornell-bunny.vmap, printing its summary.
# Extra arguments go to `vmap build` (e.g. --backend cpu, --points 20000). Then global
# illumination over that V-map (vmap gi): out/cornell-bunny-gi.png and the lit points as a PLY.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
cmake --preset default >/dev/null
cmake --build build -j"$(nproc)" --target vmap
mkdir -p out
build/vmap build scenes/cornell-bunny.json -o out/cornell-bunny.vmap "$@"
build/vmap gi out/cornell-bunny.vmap --scene scenes/cornell-bunny.json \
    --theta 8 -o out/cornell-bunny-gi.png --ply out/cornell-bunny-gi.ply
