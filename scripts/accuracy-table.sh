#!/usr/bin/env bash
# Accuracy where people look, at the defaults (or with extra `vmap validate` options), on every
# shipped scene and test scene: one row per scene at the scene's own octree height, over all
# pairs, pairs with an end on a model, and eyes on the models. The table behind
# docs/validation.md "Where people look".
# Usage: scripts/accuracy-table.sh [-b path/to/vmap] [validate options...]
# Environment: SCENES (default: scenes/*.json scenes/test/*.json), PAIRS (default 200000),
# EYES (default 100), AS_CLOUD (normals|bare: score the samples as a raw cloud). The held-out
# orientation scenes: SCENES="$(ls scenes/test/held/*.json)" (scripts/held-out-scenes.py).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
vmap=build-cpu/vmap
[[ -x $vmap ]] || vmap=build/vmap
if [[ "${1:-}" == -b ]]; then vmap="$2"; shift 2; fi
scenes="${SCENES:-$(ls scenes/*.json scenes/test/*.json | grep -v cornell-empty)}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
extra=()
[[ -n "${AS_CLOUD:-}" ]] && extra+=(--as-cloud "$AS_CLOUD")
printf '| scene | height | leaves | all: agree | FV | FH | model pairs: agree | FV | FH | eyes on models: agree | FV | FH | eyes uniform: agree | FV | normals right (models) |\n'
printf '|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n'
for s in $scenes; do
    h=$(sed -n 's/.*"max_height": *\([0-9]*\).*/\1/p' "$s" | head -1)
    "$vmap" validate "$s" --predict direct --heights "${h:-9}" --pairs "${PAIRS:-200000}" \
        --eyes "${EYES:-100}" --md "$work/r.md" --json "$work/r.json" "${extra[@]}" "$@" >&2
    python3 - "$work/r.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))[0]
h = r["heights"][0]
p = lambda c, k: f'{100 * c[k]:.2f}%'
row = [r["scene"], str(h["height"]), str(h["leaves"])]
for key in ("all", "model", "eyes_model"):
    c = h[key]
    row += [p(c, "agreement"), p(c, "false_visible_rate"), p(c, "false_hidden_rate")]
c = h["eyes_all"]
row += [p(c, "agreement"), p(c, "false_visible_rate"), f'{100 * r["normal_agreement_model"]:.1f}%']
print("| " + " | ".join(row) + " |")
PY
done
