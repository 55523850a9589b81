#!/usr/bin/env python3
"""Share of a mesh's area whose face normals (by winding) point away from the mesh's own
centroid, and its boundary edges (0: closed). docs/validation.md "4. Open sheets by their
shape" reads the open meshes' winding convention from it.

Usage: scripts/mesh-winding.py models/cube-ouvert.off models/mushroom.off ...  (OFF files)
"""
import sys
from collections import Counter


def load_off(path):
    toks = []
    with open(path) as f:
        for line in f:
            toks += line.split("#")[0].split()
    if not toks or not toks[0].startswith("OFF"):
        sys.exit(f"{path}: not an OFF file")
    i = 1
    if toks[0] != "OFF":  # "OFF8 12 0" written together
        toks[0] = toks[0][3:]
        i = 0
    nv, nf = int(toks[i]), int(toks[i + 1])
    i += 3
    verts = [tuple(map(float, toks[i + 3 * k:i + 3 * k + 3])) for k in range(nv)]
    i += 3 * nv
    faces = []
    for _ in range(nf):
        n = int(toks[i])
        faces.append([int(t) for t in toks[i + 1:i + 1 + n]])
        i += 1 + n
    return verts, faces


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


for path in sys.argv[1:]:
    verts, faces = load_off(path)
    c = tuple(sum(v[k] for v in verts) / len(verts) for k in range(3))
    edges = Counter()
    for f in faces:
        for k in range(len(f)):
            edges[tuple(sorted((f[k], f[(k + 1) % len(f)])))] += 1
    area = away = 0.0
    for f in faces:
        for k in range(1, len(f) - 1):  # fan triangles
            a, b, d = verts[f[0]], verts[f[k]], verts[f[k + 1]]
            n = cross(sub(b, a), sub(d, a))
            w = dot(n, n) ** 0.5 / 2
            centre = tuple((a[j] + b[j] + d[j]) / 3 for j in range(3))
            area += w
            away += w * (dot(n, sub(centre, c)) > 0)
    print(f"{path}: {len(faces)} faces, {sum(1 for m in edges.values() if m == 1)} boundary "
          f"edges, area facing away from the centroid {away / area:.3f}")
