#!/usr/bin/env bash
# The main job: set up (Debian packages, models), build, and compute the V-map of the default
# scene (scenes/cornell-bunny.json) into out/cornell-bunny.vmap, printing its summary, then
# draws the paper's Fig. 9 from it: the points visible from a point on the floor in front of the
# bunny in purple (the eye cyan), the bunny's shadow on the back wall not (out/fig9.png). Then
# global illumination at its defaults (vmap gi builds its own V-map of the scene, with the
# occluder eps measured for the GI: docs/gi.md): out/cornell-bunny-gi.png, the lit points as a
# PLY with linear radiosity. It also builds the Python module and makes `import vmap` work
# (scripts/python-path.sh). Extra arguments go to `vmap build` (e.g. --backend cpu).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
cmake --preset default >/dev/null
cmake --build build -j"$(nproc)" --target vmap
# The Python module, where CMake found python3-dev and pybind11, importable from then on.
if [[ -d build/python ]]; then
    cmake --build build -j"$(nproc)" --target vmap_python
    scripts/python-path.sh build
fi
mkdir -p out
build/vmap build scenes/cornell-bunny.json -o out/cornell-bunny.vmap "$@"
build/vmap render out/cornell-bunny.vmap --scene scenes/cornell-bunny.json --mode visible \
    --eye-pos 0.2764,0,0.1 -o out/fig9.png
build/vmap gi scenes/cornell-bunny.json -o out/cornell-bunny-gi.png --ply out/cornell-bunny-gi.ply
