#!/usr/bin/env python3
"""vmap against hidden point removal (Katz, Tal and Basri 2007, Open3D's
PointCloud.hidden_point_removal) with a facing test, on the eyes of `vmap validate --dump-eyes`.

Each dump holds the points, their normals, the eyes, the exact truth (Embree, both normals
facing and no triangle across the segment) and the V-map's answers. For each eye, HPR runs from
the eye (moved off its surface along its normal by the truth rays' end offset) over all points;
a point counts as seen when HPR keeps it and the pair faces each other (the truth's facing test
on the normals vmap was given). Pairs the V-map leaves out (the eye's own leaf) are left out of
both scores, so both are scored on exactly the same pairs.

HPR's one parameter is the radius of the spherical flip, R = max distance from the eye * 10^g.
--sweep scores every g of --gammas on every dump and picks the one g with the best mean
agreement over the scenes for eyes on models (the value most favourable to HPR, one for all);
the table then gives that g per scene. Usage:
  hpr-compare.py [--gammas 0.5,1,...] [--gamma G] [--max-eyes N] DUMP.npz...
"""
import argparse
import os
import sys

import numpy as np
import open3d as o3d


def facing(p, n, q, nq):
    """The truth's facing test, vectorised over q: n.(q-p) > 1e-6 |q-p| and nq.(p-q) > 1e-6 |q-p|."""
    d = q - p
    ln = np.linalg.norm(d, axis=1)
    return (d @ n > 1e-6 * ln) & (np.einsum("ij,ij->i", -d, nq) > 1e-6 * ln)


def hpr_seen(cloud, pts, nrm, eye, offset, gammas):
    """Per gamma, the points HPR with a facing test calls seen from eye index `eye`."""
    cam = pts[eye] + offset * nrm[eye]
    radius0 = np.linalg.norm(pts - cam, axis=1).max()
    face = facing(pts[eye], nrm[eye], pts, nrm)
    out = []
    for g in gammas:
        _, idx = cloud.hidden_point_removal(cam.tolist(), float(radius0 * 10.0**g))
        seen = np.zeros(len(pts), bool)
        seen[np.asarray(idx, dtype=np.int64)] = True
        out.append(seen & face)
    return out


def score(truth, pred, keep):
    t, p = truth[keep].astype(bool), pred[keep].astype(bool)
    n = max(1, keep.sum())
    return np.array([(t == p).sum(), (~t & p).sum(), (t & ~p).sum()]) / n, keep.sum()


def compare(path, gammas, sets, max_eyes):
    """Scores of vmap and of HPR at each gamma for the eye sets `sets` of one dump (its first
    max_eyes eyes)."""
    d = np.load(path)
    pts = d["positions"].astype(np.float64)
    nrm = d["pred_normals"].astype(np.float64)
    offset = float(d["offset"])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    res = {}
    for s in sets:
        eyes, truth, pred = (d[k + s][:max_eyes] for k in ("eyes_", "truth_eyes_", "pred_eyes_"))
        tot_v = np.zeros(3)
        tot_h = np.zeros((len(gammas), 3))
        npairs = 0
        for k, e in enumerate(eyes):
            keep = pred[k] != 2
            keep[e] = False
            sv, n = score(truth[k], pred[k] == 1, keep)
            tot_v += sv * n
            npairs += n
            for gi, seen in enumerate(hpr_seen(cloud, pts, nrm, int(e), offset, gammas)):
                sh, _ = score(truth[k], seen, keep)
                tot_h[gi] += sh * n
        res[s] = (tot_v / max(1, npairs), tot_h / max(1, npairs), len(eyes))
    name = os.path.basename(path).removesuffix(".npz")
    return name, res


def pct(x):
    return f"{100 * x:.2f}%"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dumps", nargs="+")
    ap.add_argument("--gammas", default="1,1.5,2,2.5,3")
    ap.add_argument("--gamma", type=float, help="skip the sweep: use this g")
    ap.add_argument("--max-eyes", type=int, default=None, help="score only each dump's first N eyes")
    a = ap.parse_args()
    gammas = [a.gamma] if a.gamma is not None else [float(g) for g in a.gammas.split(",")]
    rows = []
    for path in a.dumps:
        rows.append(compare(path, gammas, ("model",), a.max_eyes))
        print(f"{rows[-1][0]}: swept", file=sys.stderr)
    mean = np.mean([r["model"][1][:, 0] for _, r in rows], axis=0)
    best = int(np.argmax(mean))
    for path, (_, r) in zip(a.dumps, rows):  # the uniform eyes at the chosen radius only
        r["all"] = compare(path, [gammas[best]], ("all",), a.max_eyes)[1]["all"]
        r["all"] = (r["all"][0], np.repeat(r["all"][1], len(gammas), axis=0), r["all"][2])
    if len(gammas) > 1:
        print("HPR radius sweep, R = (farthest point from the eye) * 10^g: mean agreement over "
              "the scenes, eyes on models\n")
        print("| g | " + " | ".join(f"{g:g}" for g in gammas) + " |")
        print("|---|" + "---:|" * len(gammas))
        print("| mean agreement | " + " | ".join(pct(m) for m in mean) + " |\n")
    print(f"Per scene at g = {gammas[best]:g} (one value for all scenes)\n")
    print("| scene | eyes | eyes on models: vmap agree | FV | FH | HPR agree | FV | FH | "
          "vmap - HPR | eyes uniform: vmap agree | HPR agree |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in rows:
        vm, hm, ne = r["model"][0], r["model"][1][best], r["model"][2]
        va, ha = r["all"][0], r["all"][1][best]
        print(f"| {name} | {ne} | {pct(vm[0])} | {pct(vm[1])} | {pct(vm[2])} | {pct(hm[0])} | "
              f"{pct(hm[1])} | {pct(hm[2])} | {100 * (vm[0] - hm[0]):+.2f} | {pct(va[0])} | "
              f"{pct(ha[0])} |")


if __name__ == "__main__":
    main()
