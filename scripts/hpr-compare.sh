#!/usr/bin/env bash
# vmap against hidden point removal with a facing test (scripts/hpr-compare.py), on exactly the
# eyes, points and truth of `vmap validate --eyes` at each scene's own octree height: the table
# in docs/validation.md "Hidden point removal". Installs Debian's python3-open3d when missing.
# Usage: scripts/hpr-compare.sh [-b path/to/vmap] [hpr-compare.py options...]
# Environment: SCENES (default: scenes/*.json scenes/test/*.json but the empty room), EYES
# (default 50), AS_CLOUD (normals|bare), VALIDATE (extra `vmap validate` options).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
vmap=build-cpu/vmap
[[ -x $vmap ]] || vmap=build/vmap
if [[ "${1:-}" == -b ]]; then vmap="$2"; shift 2; fi
py=/usr/bin/python3  # Debian's python, where python3-open3d installs
if ! "$py" -c 'import open3d' 2>/dev/null; then
    echo "hpr-compare: installing python3-open3d" >&2
    apt-get install -y -q python3-open3d >&2
fi
scenes="${SCENES:-$(ls scenes/*.json scenes/test/*.json | grep -v cornell-empty)}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
extra=()
[[ -n "${AS_CLOUD:-}" ]] && extra+=(--as-cloud "$AS_CLOUD")
dumps=()
for s in $scenes; do
    h=$(sed -n 's/.*"max_height": *\([0-9]*\).*/\1/p' "$s" | head -1)
    name="$(basename "$s" .json)"
    "$vmap" validate "$s" --predict direct --heights "${h:-9}" --pairs 1 --eyes "${EYES:-50}" \
        --md "$work/discard.md" --dump-eyes "$work/$name.npz" "${extra[@]}" ${VALIDATE:-} >&2
    dumps+=("$work/$name.npz")
done
"$py" scripts/hpr-compare.py "$@" "${dumps[@]}"
