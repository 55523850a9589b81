"""The smallest vmap script: numpy points in, a V-map, numpy answers out.

    python3 examples/minimal.py [OUT_DIR]      (default ./out; needs `import vmap` to work:
                                               scripts/main.sh sets that up, or PYTHONPATH=build/python)
"""
import os
import sys

import numpy as np

import vmap

out_dir = sys.argv[1] if len(sys.argv) > 1 else "out"
os.makedirs(out_dir, exist_ok=True)

# A unit box of points with inward normals, open at z = 0 (where the camera looks in), and a
# floating square plate that casts a shadow.
# Each point stands for a disc of its share of the surface (the splat radius).
rng = np.random.default_rng(0)
points, normals, radii = [], [], []
for axis in range(3):
    for side, inward in ((0.0, 1.0), (1.0, -1.0)):
        if axis == 2 and side == 0.0:
            continue
        p = rng.random((1500, 3))
        p[:, axis] = side
        n = np.zeros((1500, 3))
        n[:, axis] = inward
        points.append(p), normals.append(n), radii.append(np.full(1500, (1 / (np.pi * 1500)) ** 0.5))
plate = rng.random((400, 3)) * [0.4, 0, 0.4] + [0.3, 0.5, 0.3]
points.append(plate), normals.append(np.tile([0.0, -1.0, 0.0], (400, 1)))
radii.append(np.full(400, (0.16 / (np.pi * 400)) ** 0.5))
points, normals, radii = map(np.concatenate, (points, normals, radii))

vm = vmap.build(points, normals, radii, max_height=6)
print(f"vmap {vmap.__version__}: {vm.num_points} points, {vm.num_links} links")

# Floor points in the plate's shadow and ceiling points right above the plate: hidden; floor
# points near the walls and the same ceiling points: visible.
x, y, z = points.T
centre = (np.abs(x - 0.5) < 0.1) & (np.abs(z - 0.5) < 0.1)
edge = (np.minimum(x, z) < 0.1)
above = np.flatnonzero((y == 1.0) & centre)[:100]
for name, floor in (("in the shadow", (y == 0.0) & centre), ("near the walls", (y == 0.0) & edge)):
    ids = np.flatnonzero(floor)[:100]
    pairs = np.stack(np.broadcast_arrays(ids[:, None], above[None, :]), axis=-1).reshape(-1, 2)
    print(f"floor {name} sees the ceiling above the plate: {vm.query(pairs).mean():.0%} of pairs")

# What a floor point in the shadow sees (purple), as the paper's Fig. 9: H x W x 3 uint8.
eye = int(np.flatnonzero((y == 0.0) & centre)[0])
image = vm.render(eye_id=eye, width=300, height=300)
vmap.write_png(os.path.join(out_dir, "minimal.png"), image)
print(f"wrote {os.path.join(out_dir, 'minimal.png')}")
