#!/usr/bin/env bash
# Makes `import vmap` work for the python3 the module was built for: writes a .pth file naming
# BUILD/python into that interpreter's user site-packages (python3 -m site --user-site), so no
# PYTHONPATH is needed. Usage: scripts/python-path.sh [BUILD]   (default build)
# Undo: rm "$(python3 -m site --user-site)/vmap-build.pth"
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-build}"
[[ "$build" = /* ]] || build="$root/$build"
build="$(cd "$build" && pwd)"
py="$(cat "$build/python/interpreter" 2>/dev/null || true)"
[[ -n "$py" && -f "$build/python/vmap/__init__.py" ]] ||
    { echo "python-path: no Python module in $build/python (build the vmap_python target)" >&2; exit 1; }
site="$("$py" -m site --user-site)"
mkdir -p "$site"
echo "$build/python" >"$site/vmap-build.pth"
"$py" -c "import vmap; print('python-path: import vmap works for $py (vmap', vmap.__version__ + ')')" >&2
