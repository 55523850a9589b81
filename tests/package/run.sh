#!/usr/bin/env bash
# The installed package as a user gets it: `cmake --install` of the build into a temporary
# prefix, then tests/package (find_package(vmap COMPONENTS validate)) and examples/ configured,
# built and run against that prefix only, the installed binary run with its installed scenes, and
# examples/minimal.py run with the built Python module when there is one.
# Usage: run.sh <build-dir> <source-dir> [<python3 the module was built for>]
set -euo pipefail
build=$(realpath "$1")
src=$(realpath "$2")
work=$(mktemp -d "${TMPDIR:-/tmp}/vmap_package.XXXXXX")
trap 'rm -rf "$work"' EXIT
prefix="$work/prefix"

cmake --install "$build" --prefix "$prefix" >"$work/install.log"
for f in bin/vmap include/vmap/vmap.h lib/cmake/vmap/vmapConfig.cmake \
         lib/cmake/vmap/vmapConfigVersion.cmake share/vmap/scenes/cornell-bunny.json; do
    [ -e "$prefix/$f" ] || { echo "FAIL: the install has no $f"; exit 1; }
done
echo "ok:   cmake --install put the binary, headers, package files and scenes in place"

gen=()
command -v ninja >/dev/null && gen=(-G Ninja)
for proj in tests/package examples; do
    cmake -S "$src/$proj" -B "$work/$proj" "${gen[@]}" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_PREFIX_PATH="$prefix" >"$work/configure.log" ||
        { cat "$work/configure.log"; echo "FAIL: configure $proj against the install"; exit 1; }
    cmake --build "$work/$proj" -j2 >"$work/build.log" ||
        { tail -40 "$work/build.log"; echo "FAIL: build $proj against the install"; exit 1; }
    echo "ok:   $proj builds against find_package(vmap)"
done

# The consumers find the scenes through VMAP_DATA_DIR (they are not under the prefix).
export VMAP_DATA_DIR="$prefix/share/vmap"
"$work/tests/package/consumer"
"$work/tests/package/consumer_validate"
(cd "$work" && "$work/examples/minimal" >minimal.txt && grep -q '^wrote out/minimal.vmap' minimal.txt) ||
    { cat "$work/minimal.txt"; echo "FAIL: examples/minimal"; exit 1; }
echo "ok:   examples/minimal writes out/minimal.vmap"
unset VMAP_DATA_DIR

# The installed binary finds its scenes from its own location (no source tree involved).
(cd "$work" && "$prefix/bin/vmap" -q build --points 1500 --max-height 4 -o inst.vmap &&
    "$prefix/bin/vmap" query inst.vmap --pair 0 1 >/dev/null) ||
    { echo "FAIL: the installed vmap with its default scene"; exit 1; }
echo "ok:   the installed vmap builds its default scene from share/vmap"

py=${3:-}
if [ -n "$py" ]; then
    (cd "$work" && PYTHONPATH="$build/python" "$py" "$src/examples/minimal.py" >py.txt &&
        grep -q '^wrote out/minimal.png' py.txt && [ -s out/minimal.png ]) ||
        { cat "$work/py.txt"; echo "FAIL: examples/minimal.py"; exit 1; }
    echo "ok:   examples/minimal.py writes out/minimal.png"
    # scripts/main.sh's step: a .pth in the user site-packages (here a scratch one) makes
    # `import vmap` work without PYTHONPATH.
    (cd "$work" && PYTHONUSERBASE="$work/userbase" "$src/scripts/python-path.sh" "$build" 2>/dev/null &&
        PYTHONUSERBASE="$work/userbase" "$py" -c "import vmap, numpy; vmap.data_dir()") ||
        { echo "FAIL: scripts/python-path.sh did not make import vmap work"; exit 1; }
    echo "ok:   scripts/python-path.sh makes import vmap work"
    site=$(ls -d "$prefix"/lib/python3*/dist-packages 2>/dev/null | head -1)
    (cd "$work" && PYTHONPATH="$site" "$py" -c \
        "import vmap, os; assert vmap.data_dir() == os.path.join('$prefix', 'share', 'vmap')") ||
        { echo "FAIL: the installed Python module (in ${site:-no dist-packages}) or its data"; exit 1; }
    echo "ok:   the installed Python module imports and finds share/vmap"
fi
