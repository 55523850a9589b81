#!/usr/bin/env bash
# Where a bare cloud loses against its true normals: the signs or the axes of the estimated
# normals. For each scene, `vmap validate --as-cloud bare --dump-eyes` gives the scene's samples
# with the normals vmap estimates for them; three PLY clouds of the same points are then scored
# with `vmap validate --cloud` (radii estimated in all three, as for any cloud without them):
#   estimated   the estimated normals as they are (what a bare cloud gets),
#   signs fixed the estimated axes, each turned to the true normal's side,
#   true        the true normals.
# "signs fixed" minus "estimated" is what a perfect orientation would gain; "true" minus "signs
# fixed" is what the axes (the fits) cost. The table in docs/validation.md "Where the targets
# stand".
# Usage: scripts/normals-gap.sh [-b path/to/vmap] [vmap validate options...]
# Environment: SCENES (default: scenes/*.json scenes/test/*.json scenes/test/held/*.json but the
# empty room), PAIRS (default 50000), EYES (default 30).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
vmap=build-cpu/vmap
[[ -x $vmap ]] || vmap=build/vmap
if [[ "${1:-}" == -b ]]; then vmap="$2"; shift 2; fi
py=/usr/bin/python3  # Debian's python3-numpy (scripts/setup.sh installs it)
scenes="${SCENES:-$(ls scenes/*.json scenes/test/*.json scenes/test/held/*.json | grep -v cornell-empty)}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

printf '| scene | height | model points: sign wrong | axis off > 20 deg | > 45 deg | model pairs: estimated | signs fixed | true | FV: estimated | signs fixed | true |\n'
printf '|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n'
for s in $scenes; do
    h=$(sed -n 's/.*"max_height": *\([0-9]*\).*/\1/p' "$s" | head -1)
    h=${h:-9}
    "$vmap" validate "$s" --predict direct --heights "$h" --pairs 1 --eyes 1 --as-cloud bare \
        --dump-eyes "$work/d.npz" "$@" >/dev/null 2>"$work/err" || { cat "$work/err" >&2; exit 1; }
    # The three clouds, and the estimated normals' errors on the models' points.
    errs=$("$py" - "$work" <<'PY'
import sys
import numpy as np
w = sys.argv[1]
d = np.load(f"{w}/d.npz")
pos, true, est = d["positions"], d["normals"], d["pred_normals"]
side = np.sign(np.einsum("ij,ij->i", true, est))
side[side == 0] = 1
head = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(pos) +
        "".join(f"property float {c}\n" for c in ("x", "y", "z", "nx", "ny", "nz")) +
        "end_header\n").encode()
for name, nrm in (("estimated", est), ("signs", est * side[:, None]), ("true", true)):
    with open(f"{w}/{name}.ply", "wb") as f:
        f.write(head)
        f.write(np.hstack([pos, nrm]).astype("<f4").tobytes())
m = d["on_model"] == 1
off = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", true, est)), 0, 1)))
pct = lambda x: f"{100 * x.mean():.1f}%" if x.size else "-"
print(pct(side[m] < 0), pct(off[m] > 20), pct(off[m] > 45))
PY
)
    read -r wrong off20 off45 <<<"$errs"
    agree=() fv=()
    for c in estimated signs true; do
        "$vmap" validate "$s" --cloud "$work/$c.ply" --predict direct --heights "$h" \
            --pairs "${PAIRS:-50000}" --eyes "${EYES:-30}" --json "$work/r.json" "$@" >/dev/null 2>"$work/err" ||
            { cat "$work/err" >&2; exit 1; }
        read -r a f <<<"$("$py" -c '
import json, sys
c = json.load(open(sys.argv[1]))[0]["heights"][0]["model"]
print("%.2f%% %.2f%%" % (100 * c["agreement"], 100 * c["false_visible_rate"]))' "$work/r.json")"
        agree+=("$a") fv+=("$f")
    done
    name=$(basename "$s" .json)
    echo "| $name | $h | $wrong | $off20 | $off45 | ${agree[0]} | ${agree[1]} | ${agree[2]} | ${fv[0]} | ${fv[1]} | ${fv[2]} |"
done
