#!/usr/bin/env python3
"""Writes the held-out bare-cloud scenes, scenes/test/held/*.json (issue 10: orientation).

Placements are computed from the meshes' own bounds (models/*.off, scripts/fetch-models.sh), as
src/scene/scene.cpp places a mesh (centre its box, scale, rotate x, y, z, stand the bottom centre
on "position"), so that a gap such as "3 mm from the back wall" is exact. Usage:
    scripts/held-out-scenes.py            # rewrites scenes/test/held/*.json
"""
import json
import math
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = [0.5528, 0.5488, 0.5592]  # W (x), H (y), D (z); open at z = 0


def off_vertices(name):
    with open(os.path.join(ROOT, "models", name + ".off")) as f:
        words = [w for line in f for w in line.split("#")[0].split()]
    assert words[0] == "OFF", name
    nv = int(words[1])
    return [tuple(float(w) for w in words[4 + 3 * i: 7 + 3 * i]) for i in range(nv)]


def rotate(p, deg):
    x, y, z = p
    for axis, a in enumerate(deg):
        c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
        if axis == 0:
            y, z = c * y - s * z, s * y + c * z
        elif axis == 1:
            x, z = c * x + s * z, -s * x + c * z
        else:
            x, y = c * x - s * y, s * x + c * y
    return x, y, z


def extents(name, size=None, scale=None, rot=(0, 0, 0)):
    """Half extents (x, y, z) and height of the placed mesh, as scene.cpp places it."""
    v = off_vertices(name)
    lo = [min(p[a] for p in v) for a in range(3)]
    hi = [max(p[a] for p in v) for a in range(3)]
    mid = [(lo[a] + hi[a]) / 2 for a in range(3)]
    s = size / max(hi[a] - lo[a] for a in range(3)) if size else 1.0
    ax = scale or [1, 1, 1]
    pts = [rotate([(p[a] - mid[a]) * s * ax[a] for a in range(3)], rot) for p in v]
    lo = [min(p[a] for p in pts) for a in range(3)]
    hi = [max(p[a] for p in pts) for a in range(3)]
    return [(hi[a] - lo[a]) / 2 for a in range(3)], hi[1] - lo[1]


def mesh(name, x=None, y=0.0, z=None, size=None, scale=None, rot=None, label=None, **at):
    """A mesh entry; x / z may be given as a wall gap: at={'right': 0.003} puts the mesh's box
    3 mm from the wall x = W, and likewise 'left' (x = 0), 'back' (z = D), 'front' (z = 0)."""
    half, height = extents(name, size, scale, rot or (0, 0, 0))
    room = at.pop("room", CORNELL)
    if "left" in at:
        x = at["left"] + half[0]
    if "right" in at:
        x = room[0] - at["right"] - half[0]
    if "back" in at:
        z = room[2] - at["back"] - half[2]
    if "front" in at:
        z = at["front"] + half[2]
    if "ceiling" in at:
        y = room[1] - at["ceiling"] - height
    e = {"file": "../../../models/" + name + ".off"}
    if label:
        e["name"] = label
    if size:
        e["size"] = size
    if scale:
        e["scale"] = scale
    if rot:
        e["rotate"] = rot
    e["position"] = [round(x, 5), round(y, 5), round(z, 5)]
    return e, half, height


def room(size=CORNELL):
    return {"size": size}


def light(size=CORNELL):
    return {"center": [size[0] / 2, size[2] / 2], "size": [0.13, 0.105], "emission": [17, 12, 4]}


def scene(name, description, meshes, points, seed, size=CORNELL, has_room=True):
    s = {"name": name, "description": description}
    s["room"] = room(size) if has_room else None
    if has_room:
        s["light"] = light(size)
    s["meshes"] = [m[0] for m in meshes]
    s["sampling"] = {"points": points, "seed": seed}
    return s


def near_walls():
    return scene("held-near-walls",
                 "Held-out scene (orientation): an elk 3 mm from the back wall, a head 2 mm from "
                 "the left wall, a sphere on the floor 2 mm from the red wall, a camel in the open.",
                 [mesh("elk", x=0.3, size=0.2, back=0.003),
                  mesh("head", z=0.25, size=0.15, left=0.002),
                  mesh("sphere", z=0.12, size=0.08, right=0.002),
                  mesh("camel", x=0.33, z=0.2, size=0.16, rot=[0, 40, 0])],
                 45000, 11)


def touching():
    bull = mesh("bull", size=0.16, x=0.15, z=0.35)
    # The cow's box touches the bull's (gap 0), the elephant and triceratops overlap 5 mm.
    cow = mesh("cow", size=0.15, z=0.35, left=0.15 + bull[1][0])
    cube = mesh("cube", label="box", scale=[0.05, 0.05, 0.05], x=0.12, z=0.12)
    sphere = mesh("sphere", size=0.09, x=0.12, y=cube[2], z=0.12)
    ele = mesh("elephant", size=0.14, x=0.33, z=0.14)
    tri = mesh("triceratops", size=0.14, z=0.14, left=0.33 + ele[1][0] - 0.005)
    return scene("held-touching",
                 "Held-out scene (orientation): a bull and a cow whose boxes touch, an elephant and "
                 "a triceratops overlapping by 5 mm, a sphere resting on a box.",
                 [bull, cow, cube, sphere, ele, tri], 45000, 12)


def table():
    size = [0.7, 0.5, 0.6]
    top_y = 0.2
    top = mesh("cube", label="table", scale=[0.16, 0.0015, 0.12], x=0.35, y=top_y, z=0.3, room=size)
    legs = [mesh("cube", label=f"leg{i}", scale=[0.004, top_y / 2, 0.004], x=0.35 + sx * 0.15,
                 z=0.3 + sz * 0.11, room=size)
            for i, (sx, sz) in enumerate([(-1, -1), (1, -1), (-1, 1), (1, 1)])]
    camel = mesh("camel", size=0.15, x=0.33, y=top_y + 0.003, z=0.3, room=size)
    head = mesh("head", size=0.1, x=0.37, z=0.28, room=size)
    tri = mesh("triceratops", size=0.13, x=0.12, z=0.45, rot=[0, -60, 0], room=size)
    return scene("held-table",
                 "Held-out scene (orientation), a wider room: a camel standing on a 3 mm table top "
                 "on four thin legs, a head under the table, a triceratops beside it.",
                 [top, *legs, camel, head, tri], 50000, 13, size=size)


def lone():
    return scene("held-lone", "Held-out scene (orientation): a lone bull, no room.",
                 [mesh("bull", size=0.2, x=0, z=0)], 30000, 14, has_room=False)


def cluttered():
    size = [0.45, 0.45, 0.5]
    m = [mesh("elk", size=0.12, x=0.1, z=0.12, rot=[0, 30, 0], room=size),
         mesh("camel", size=0.12, x=0.32, z=0.1, rot=[0, -70, 0], room=size),
         mesh("head", size=0.09, x=0.12, z=0.3, rot=[0, 150, 0], room=size),
         mesh("cow", size=0.11, z=0.4, right=0.004, rot=[0, 90, 0], room=size),
         mesh("triceratops", size=0.1, x=0.22, z=0.42, back=0.003, room=size),
         mesh("sphere", size=0.05, x=0.24, z=0.24, room=size),
         mesh("sphere", label="sphere2", size=0.04, x=0.24, y=0.05, z=0.24, room=size),
         mesh("elephant", size=0.1, x=0.33, z=0.26, rot=[0, 200, 0], room=size),
         mesh("bull", size=0.09, x=0.06, z=0.44, left=0.003, rot=[0, 10, 0], room=size)]
    return scene("held-cluttered",
                 "Held-out scene (orientation), a small room: nine objects close together, turned, "
                 "some millimetres from a wall, a sphere resting on another.",
                 m, 50000, 15, size=size)


def shelf():
    shelf_y = 0.3
    board = mesh("cube", label="shelf", scale=[0.12, 0.0015, 0.06], x=0.28, y=shelf_y, back=0.0)
    head = mesh("head", size=0.09, x=0.28, y=shelf_y + 0.003, back=0.01)
    hang = mesh("elephant", size=0.12, x=0.12, z=0.3, ceiling=0.004)
    ball = mesh("sphere", size=0.07, x=0.42, y=0.003, z=0.15)
    bull = mesh("bull", size=0.15, x=0.2, z=0.15, rot=[0, 120, 0])
    return scene("held-shelf",
                 "Held-out scene (orientation): a 3 mm shelf on the back wall with a head on it, an "
                 "elephant 4 mm below the ceiling, a sphere 3 mm above the floor, a bull.",
                 [board, head, hang, ball, bull], 45000, 16)


def layout(s):
    """The shipped scenes' layout: one line per key, one line per mesh."""
    one = lambda v: json.dumps(v, separators=(", ", ": "))
    lines = [f'  "{k}": {one(v)}' for k, v in s.items() if k != "meshes" and k != "sampling"]
    meshes = ",\n".join("    " + one(m) for m in s["meshes"])
    lines.append(f'  "meshes": [\n{meshes}\n  ]')
    lines.append(f'  "sampling": {one(s["sampling"])}')
    return "{\n" + ",\n".join(lines) + "\n}\n"


def main():
    out = os.path.join(ROOT, "scenes", "test", "held")
    os.makedirs(out, exist_ok=True)
    for make in (near_walls, touching, table, lone, cluttered, shelf):
        s = make()
        with open(os.path.join(out, s["name"] + ".json"), "w") as f:
            f.write(layout(s))
        print(os.path.join("scenes", "test", "held", s["name"] + ".json"))


if __name__ == "__main__":
    main()
