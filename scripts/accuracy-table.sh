#!/usr/bin/env bash
# Accuracy where people look, at the defaults (or with extra `vmap validate` options), on every
# shipped scene and test scene: one row per scene at the scene's own octree height, over all
# pairs, pairs with an end on a model, and eyes on the models. The table behind
# docs/validation.md "Where people look".
# Usage: scripts/accuracy-table.sh [-b path/to/vmap] [validate options...]
# Environment: SCENES (default: scenes/*.json scenes/test/*.json), PAIRS (default 200000),
# EYES (default 100), AS_CLOUD (normals|bare: score the samples as a raw cloud). The held-out
# orientation scenes: SCENES="$(ls scenes/test/held/*.json)" (scripts/held-out-scenes.py).
# SEEDS="0 1 2": each scene once per sampling seed (a copy of the scene file with
# sampling.seed = 1000 x its own + k), one row each, then a table of the means over the seeds
# per scene and over all scenes (one sample's points decide a row to a few tenths of a point).
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
# The scene files to score: each scene, or a copy per seed (mesh paths made absolute).
runs=()
for s in $scenes; do
    if [[ -z "${SEEDS:-}" ]]; then runs+=("$s"); continue; fi
    for k in $SEEDS; do
        out="$work/$(basename "${s%.json}").seed$k.json"
        python3 - "$s" "$out" "$k" <<'PY'
import json, os, sys
src, out, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
d = json.load(open(src))
base = os.path.dirname(os.path.abspath(src))
for m in d.get("meshes", []):
    if "file" in m and not os.path.isabs(m["file"]):
        m["file"] = os.path.normpath(os.path.join(base, m["file"]))
d.setdefault("sampling", {})
d["sampling"]["seed"] = int(d["sampling"].get("seed", 1)) * 1000 + k
json.dump(d, open(out, "w"))
PY
        runs+=("$out")
    done
done
for s in "${runs[@]}"; do
    h=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1])).get("octree", {}).get("max_height", ""))' "$s")
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
done | tee "$work/rows"
[[ -z "${SEEDS:-}" ]] && exit 0
# The means over the seeds, per scene, then over the scenes (each scene once).
python3 - "$work/rows" <<'PY'
import collections, sys
by = collections.OrderedDict()
for line in open(sys.argv[1]):
    c = [x.strip() for x in line.strip().strip("|").split("|")]
    by.setdefault(c[0], []).append([float(x.rstrip("%")) for x in c[3:14]])
mean = lambda rows: [sum(x) / len(x) for x in zip(*rows)]
print(f"\nMeans over the seeds ({', '.join(str(len(v)) for v in list(by.values())[:1])} a scene):\n")
print("| scene | all: agree | FV | FH | model pairs: agree | FV | FH | eyes on models: agree | FV | FH | eyes uniform: agree | FV |")
print("|---|" + "---:|" * 11)
means = {k: mean(v) for k, v in by.items()}
for k, m in list(means.items()) + [("**mean of the scenes**", mean(list(means.values())))]:
    print(f"| {k} | " + " | ".join(f"{x:.2f}%" for x in m) + " |")
PY
