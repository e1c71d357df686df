#!/usr/bin/env python3
"""Writes tests/data/walker.gltf: a clean, synthetic walking character.

Run from anywhere: `python3 tests/data/make_walker.py` (standard library only).

Y up, metres, facing +z (glTF's front), so its left foot is on +x.

- Joints: `root` at (0, 0.5, 0) with children `foot_l` and `foot_r`, whose origins are their
  foot's apex: (+0.12, 0, 0) and (-0.12, 0, 0) at bind. Inverse bind matrices are the inverse
  bind world transforms (pure translations).
- Mesh: a body box 0.3 x 0.4 x 0.2 m (x, y, z) centred at (0, 0.5, 0), all weight on `root`;
  two feet, each an inverted square pyramid (apex down at y = 0, base 0.10 x 0.14 m (x, z)
  at y = 0.06), all weight on its foot joint. Closed, wound counter-clockwise seen from
  outside.
- Clip "Walk", LINEAR, 2 s, keys at t = 0, .4, .5, .9, 1, 1.4, 1.5, 1.9, 2: `root` moves
  along +z at 0.5 m/s (the root motion is in the clip). Each foot repeats a 1 s cycle:
  stance 0.4 s (apex planted at world y = -0.03, its world position fixed: its local z falls
  exactly as the root advances), lift 0.1 s straight up to y = +0.08, swing 0.4 s forward
  0.5 m at that height, descent 0.1 s straight down onto the next plant. The left foot's
  stances start at t = 0 and 1 (plants at z = 0.10, 0.60), the right's at t = 0.5 and 1.5
  (plants at z = 0.35, 0.85; at t = 0 it is up above its previous plant at z = -0.15, and at
  t = 2 it has just lifted). Every segment moves the foot along a straight world line while
  the root moves linearly, so the local keys interpolate it exactly: a planted foot is still.
  Plants lie on whole centimetres, the centres of a 1 cm ground grid with a cell at x = 0.
"""

import base64
import json
import os
import struct

ROOT_Y = 0.5
SPEED = 0.5  # root, m/s along +z
FOOT_X = {"foot_l": 0.12, "foot_r": -0.12}
# First plant's z and the clip time its stance starts; a cycle is 1 s and 0.5 m.
FIRST_PLANT = {"foot_l": (0.10, 0), "foot_r": (0.35, 5)}  # time in tenths of a second
PLANTED_Y, LIFTED_Y = -0.03, 0.08
KEYS = [0, 4, 5, 9, 10, 14, 15, 19, 20]  # tenths of a second


def foot_world(foot, u):
    """World (y, z) of a foot's apex at key time u (tenths of a second, a phase boundary)."""
    z0, start = FIRST_PLANT[foot]
    n, s = divmod(u - start, 10)
    plant = lambda m: z0 + 0.5 * m
    return {
        0: (PLANTED_Y, plant(n)),  # touched down
        4: (PLANTED_Y, plant(n)),  # stance ends
        5: (LIFTED_Y, plant(n)),  # lifted
        9: (LIFTED_Y, plant(n + 1)),  # swung forward, about to descend
    }[s]


def box(cx, cy, cz, hx, hy, hz):
    p = [
        (cx + sx * hx, cy + sy * hy, cz + sz * hz)
        for sx in (-1, 1)
        for sy in (-1, 1)
        for sz in (-1, 1)
    ]
    # Corner index = 4·(x>0) + 2·(y>0) + (z>0); faces counter-clockwise from outside.
    quads = [
        (0, 1, 3, 2),  # -x
        (4, 6, 7, 5),  # +x
        (0, 4, 5, 1),  # -y
        (2, 3, 7, 6),  # +y
        (0, 2, 6, 4),  # -z
        (1, 5, 7, 3),  # +z
    ]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return p, tris


def inverted_pyramid(x, hx=0.05, hz=0.07, h=0.06):
    apex = (x, 0.0, 0.0)
    # Base corners counter-clockwise seen from above (+y).
    base = [(x - hx, h, -hz), (x - hx, h, hz), (x + hx, h, hz), (x + hx, h, -hz)]
    p = [apex] + base
    # Sides: seen from outside (below and beside), apex then the base edge reversed.
    sides = [(0, 1 + (i + 1) % 4, 1 + i) for i in range(4)]
    top = [(1, 2, 3), (1, 3, 4)]
    return p, sides + top


def check_closed_outward(p, tris):
    """Every edge used once each way; positive signed volume (outward winding)."""
    edges = {}
    vol = 0.0
    for a, b, c in tris:
        for e in ((a, b), (b, c), (c, a)):
            edges[e] = edges.get(e, 0) + 1
        (ax, ay, az), (bx, by, bz), (cx, cy, cz) = p[a], p[b], p[c]
        vol += (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)) / 6
    assert all(n == 1 and edges.get((b, a)) == 1 for (a, b), n in edges.items()), "not closed"
    assert vol > 0, f"inward winding (volume {vol})"


def main():
    positions, indices, joints = [], [], []
    parts = [
        (box(0.0, ROOT_Y, 0.0, 0.15, 0.2, 0.1), 0),
        (inverted_pyramid(FOOT_X["foot_l"]), 1),
        (inverted_pyramid(FOOT_X["foot_r"]), 2),
    ]
    for (p, tris), joint in parts:
        check_closed_outward(p, tris)
        base = len(positions)
        positions += p
        indices += [base + i for t in tris for i in t]
        joints += [joint] * len(p)

    times = [u / 10 for u in KEYS]
    root_t = [(0.0, ROOT_Y, SPEED * t) for t in times]
    foot_t = {}
    for foot, x in FOOT_X.items():
        out = []
        for u, t in zip(KEYS, times):
            y, z = foot_world(foot, u)
            out.append((x, y - ROOT_Y, z - SPEED * t))  # local to the root
        foot_t[foot] = out

    def translate(x, y, z):  # column-major
        return [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, y, z, 1]

    ibms = translate(0, -ROOT_Y, 0) + translate(-0.12, 0, 0) + translate(0.12, 0, 0)

    blob = bytearray()
    views, accessors = [], []

    def add(fmt, values, comp, typ, count, target=None, minmax=None):
        while len(blob) % 4:
            blob.append(0)
        data = struct.pack("<" + fmt * len(values), *values)
        view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target:
            view["target"] = target
        views.append(view)
        blob.extend(data)
        acc = {"bufferView": len(views) - 1, "componentType": comp, "count": count, "type": typ}
        if minmax:
            acc["min"], acc["max"] = minmax
        accessors.append(acc)
        return len(accessors) - 1

    f32 = lambda x: struct.unpack("<f", struct.pack("<f", x))[0]  # min/max as stored

    def vec3_bounds(vs):
        lo = [f32(min(v[i] for v in vs)) for i in range(3)]
        return lo, [f32(max(v[i] for v in vs)) for i in range(3)]

    flat = lambda vs: [c for v in vs for c in v]
    n = len(positions)
    pos = add("f", flat(positions), 5126, "VEC3", n, 34962, vec3_bounds(positions))
    idx = add("I", indices, 5125, "SCALAR", len(indices), 34963)
    jnt = add("H", flat([(j, 0, 0, 0) for j in joints]), 5123, "VEC4", n, 34962)
    wgt = add("f", flat([(1.0, 0.0, 0.0, 0.0)] * n), 5126, "VEC4", n, 34962)
    ibm = add("f", ibms, 5126, "MAT4", 3)
    tin = add("f", times, 5126, "SCALAR", len(times), None, ([f32(times[0])], [f32(times[-1])]))
    outs = [add("f", flat(v), 5126, "VEC3", len(v)) for v in (root_t, foot_t["foot_l"], foot_t["foot_r"])]

    doc = {
        "asset": {"version": "2.0", "generator": "imprint tests/data/make_walker.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "walker", "mesh": 0, "skin": 0},
            {"name": "root", "translation": [0, ROOT_Y, 0], "children": [2, 3]},
            {"name": "foot_l", "translation": [0.12, -ROOT_Y, 0]},
            {"name": "foot_r", "translation": [-0.12, -ROOT_Y, 0]},
        ],
        "meshes": [
            {
                "name": "walker",
                "primitives": [
                    {
                        "attributes": {"POSITION": pos, "JOINTS_0": jnt, "WEIGHTS_0": wgt},
                        "indices": idx,
                    }
                ],
            }
        ],
        "skins": [{"name": "walker", "joints": [1, 2, 3], "inverseBindMatrices": ibm}],
        "animations": [
            {
                "name": "Walk",
                "samplers": [
                    {"input": tin, "output": o, "interpolation": "LINEAR"} for o in outs
                ],
                "channels": [
                    {"sampler": s, "target": {"node": node, "path": "translation"}}
                    for s, node in enumerate((1, 2, 3))
                ],
            }
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [
            {
                "byteLength": len(blob),
                "uri": "data:application/octet-stream;base64,"
                + base64.b64encode(bytes(blob)).decode(),
            }
        ],
    }
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "walker.gltf")
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(f"wrote {path}: {n} vertices, {len(indices) // 3} triangles, {len(blob)} bytes")


if __name__ == "__main__":
    main()
