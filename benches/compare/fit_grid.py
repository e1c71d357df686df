#!/usr/bin/env python3
"""Write a GRID.json fitted to an OBJ the way imprint's benchmark fits its grid.

Cubic cells, RES cells along the longest side of the bounding box grown by 10% of the
longest side on every side: cell = 1.2 * longest / RES; dims per axis =
ceil((extent + 0.2 * longest) / cell), capped at RES; the grid is centred on the box centre;
origin (centre of cell 0,0,0) = grid min corner + cell / 2.

Only for running baselines.py by hand: the harness writes the grid imprint really used.

    python3 fit_grid.py --mesh MESH.obj [--res 128] --out GRID.json
"""

import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
os.environ.setdefault("IMPRINT_BASELINES_NO_REEXEC", "1")
from baselines import load_obj  # noqa: E402


def fit(V, res):
    lo = V.min(axis=0)
    hi = V.max(axis=0)
    ext = hi - lo
    longest = float(ext.max())
    cell = 1.2 * longest / res
    dims = [min(res, max(1, int(math.ceil((float(e) + 0.2 * longest) / cell)))) for e in ext]
    centre = (lo + hi) * 0.5
    origin = [float(centre[a] - dims[a] * cell * 0.5 + cell * 0.5) for a in range(3)]
    return {"origin": origin, "cell_size": cell, "dims": dims}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    V, _ = load_obj(a.mesh)
    g = fit(V, a.res)
    with open(a.out, "w") as f:
        json.dump(g, f, indent=2)
        f.write("\n")
    print(json.dumps(g))


if __name__ == "__main__":
    main()
