#!/usr/bin/env python3
"""Baselines for imprint's narrow-band unsigned distance field, timed in the same run.

What a user would pick instead of imprint:

* OpenVDB ``meshToLevelSet`` (Python: ``pyopenvdb.FloatGrid.createLevelSetFromPolygons``),
  half-width ``--band`` voxels, its transform aligned with imprint's grid so that voxel
  (i, j, k) has its centre at imprint's cell centre ``origin + (i, j, k) * cell``.
  We compare the unsigned distance ``abs(level set)``; inactive voxels read the background
  ``band * cell``, the same "far" value imprint uses.
* Open3D's exact closest-point distance
  ``open3d.t.geometry.RaycastingScene().compute_distance`` (Embree BVH), on the band cells,
  with its default thread count (``nthreads=0``) and with 2 threads.

Each baseline is timed ``--repeat`` times after one untimed warm-up run (reported as
``cold_ms``). The timed region holds only the library calls; OBJ loading and array/tensor
preparation are reported apart (``mesh.load_ms``, ``prep_ms``). Missing libraries are
reported as ``{"available": false, "why": ...}``; the script still writes its JSON.

Run ``python3 baselines.py --help`` for the options; README.md beside this file says how
the benchmark harness calls it.
"""

import argparse
import json
import math
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
VENV = os.environ.get("IMPRINT_BASELINES_VENV", os.path.join(HERE, ".venv"))


def _maybe_reexec():
    """Run under install.sh's virtual environment when it exists and we are not in it
    (else under /usr/bin/python3 when this interpreter lacks numpy or OpenVDB).

    The venv is made from Debian's /usr/bin/python3 with --system-site-packages, so it sees
    Debian's pyopenvdb and numpy and also has open3d from PyPI: one interpreter for both.
    """
    if os.environ.get("IMPRINT_BASELINES_NO_REEXEC"):
        return
    py = os.path.join(VENV, "bin", "python")
    if os.path.exists(py):
        if os.path.realpath(sys.prefix) == os.path.realpath(VENV):
            return
    else:
        # No venv (Open3D not installed): Debian's pyopenvdb still runs under /usr/bin/python3.
        import importlib.util as iu
        py = "/usr/bin/python3"
        if (not os.path.exists(py) or os.path.realpath(sys.executable) == os.path.realpath(py)
                or (iu.find_spec("numpy") and (iu.find_spec("pyopenvdb") or iu.find_spec("openvdb")))):
            return
    os.environ["IMPRINT_BASELINES_NO_REEXEC"] = "1"
    os.execv(py, [py, os.path.abspath(__file__)] + sys.argv[1:])


_maybe_reexec()

try:
    import numpy as np
except Exception as e:  # pragma: no cover - only without numpy
    np = None
    _NUMPY_WHY = "import numpy failed: %s: %s" % (type(e).__name__, e)


# --------------------------------------------------------------------------- libraries

def import_openvdb():
    """Return (module, info) or (None, why). Debian names the module pyopenvdb."""
    errors = []
    for name in ("openvdb", "pyopenvdb"):
        try:
            mod = __import__(name)
            if not hasattr(mod, "FloatGrid"):
                errors.append("%s has no FloatGrid" % name)
                continue
            ver = getattr(mod, "LIBRARY_VERSION", None)
            ver = ".".join(str(x) for x in ver) if isinstance(ver, tuple) else str(ver)
            return mod, {"module": name, "version": ver}
        except Exception as e:
            errors.append("import %s: %s: %s" % (name, type(e).__name__, e))
    return None, "; ".join(errors) + " (install: apt-get install python3-openvdb, for /usr/bin/python3)"


def import_open3d():
    try:
        import open3d as o3d
    except Exception as e:
        return None, "import open3d: %s: %s (install: pip install open3d-cpu or open3d)" % (
            type(e).__name__, e)
    info = {"module": "open3d", "version": getattr(o3d, "__version__", "?")}
    try:
        from importlib import metadata
        for dist in ("open3d-cpu", "open3d"):
            try:
                info["package"] = "%s %s" % (dist, metadata.version(dist))
                break
            except metadata.PackageNotFoundError:
                pass
    except Exception:
        pass
    if not hasattr(getattr(getattr(o3d, "t", None), "geometry", None), "RaycastingScene"):
        return None, "open3d %s has no t.geometry.RaycastingScene" % info["version"]
    return o3d, info


# --------------------------------------------------------------------------- inputs

def load_obj(path):
    """Minimal OBJ reader: 'v' and 'f' lines; polygons fan-triangulated; 1-based and
    negative (relative) indices; 'a', 'a/b', 'a//c', 'a/b/c' forms. Returns
    (vertices float64 [N,3], triangles int64 [M,3]). Other statements are ignored."""
    verts = []
    tris = []
    with open(path, "r", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "v":
                if len(parts) < 4:
                    raise ValueError("%s:%d: vertex with fewer than 3 coordinates" % (path, lineno))
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif tag == "f":
                idx = []
                nv = len(verts)
                for tok in parts[1:]:
                    s = tok.split("/", 1)[0]
                    if not s:
                        raise ValueError("%s:%d: face corner without vertex index" % (path, lineno))
                    i = int(s)
                    if i > 0:
                        i -= 1
                    elif i < 0:
                        i += nv
                    else:
                        raise ValueError("%s:%d: vertex index 0" % (path, lineno))
                    if not 0 <= i < nv:
                        raise ValueError("%s:%d: vertex index %s out of range" % (path, lineno, s))
                    idx.append(i)
                for k in range(1, len(idx) - 1):
                    tris.append((idx[0], idx[k], idx[k + 1]))
    v = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    return v, t


def load_grid(path):
    with open(path) as f:
        g = json.load(f)
    origin = [float(x) for x in g["origin"]]
    h = float(g["cell_size"])
    dims = [int(x) for x in g["dims"]]
    if len(origin) != 3 or len(dims) != 3 or h <= 0 or min(dims) <= 0:
        raise ValueError("bad grid %r" % (g,))
    return {"origin": origin, "cell_size": h, "dims": dims}


def cell_centres(grid, ijk):
    """ijk int [N,3] as (i, j, k) -> world float32 [N,3]."""
    o = np.asarray(grid["origin"], dtype=np.float64)
    return (o + ijk.astype(np.float64) * grid["cell_size"]).astype(np.float32)


def all_cells_zyx(grid):
    """World centres of every cell, float32 [nz, ny, nx, 3] (x fastest)."""
    nx, ny, nz = grid["dims"]
    h = grid["cell_size"]
    o = grid["origin"]
    x = o[0] + np.arange(nx) * h
    y = o[1] + np.arange(ny) * h
    z = o[2] + np.arange(nz) * h
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    return np.stack([xx, yy, zz], axis=-1).astype(np.float32)


def ms(t):
    return round(t * 1e3, 4)


def stats_ms(times):
    s = sorted(times)
    n = len(s)
    med = s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])
    return {"median_ms": ms(med), "min_ms": ms(s[0]), "max_ms": ms(s[-1]),
            "times_ms": [ms(t) for t in times]}


def diff_stats(a, b, band):
    """Stats of a - b (cells), both clamped to [0, band] first."""
    a = np.minimum(a.astype(np.float64), band)
    b = np.minimum(b.astype(np.float64), band)
    d = a - b
    ad = np.abs(d)
    if d.size == 0:
        return {"n": 0}
    return {
        "n": int(d.size),
        "abs_max": float(ad.max()),
        "abs_p99": float(np.percentile(ad, 99)),
        "abs_median": float(np.median(ad)),
        "abs_mean": float(ad.mean()),
        "max_over": float(d.max()),      # a above b by this much at most
        "max_under": float(-d.min()),    # a below b by this much at most
        "frac_abs_gt_0.01": float((ad > 0.01).mean()),
        "frac_abs_gt_0.1": float((ad > 0.1).mean()),
    }


# --------------------------------------------------------------------------- baselines

def run_openvdb(vdb, info, V, T, grid, band, repeat):
    res = {"available": True}
    res.update(info)
    h = grid["cell_size"]
    t0 = time.perf_counter()
    pts = np.ascontiguousarray(V, dtype=np.float32)
    tris = np.ascontiguousarray(T, dtype=np.int32)
    quads = np.zeros((0, 4), dtype=np.int32)

    def make_xform():
        # index -> world: world = index * h + origin, so voxel (i,j,k)'s centre (OpenVDB
        # samples level sets at integer index coordinates) is imprint's cell centre.
        x = vdb.createLinearTransform(voxelSize=h)
        x.translate(tuple(grid["origin"]))
        return x

    xforms = [make_xform() for _ in range(repeat + 1)]
    res["prep_ms"] = ms(time.perf_counter() - t0)
    chk = xforms[0].indexToWorld((1, 2, 3))
    want = [grid["origin"][a] + (a + 1) * h for a in range(3)]
    res["transform_check_max_err"] = max(abs(chk[a] - want[a]) for a in range(3))
    res["call"] = ("FloatGrid.createLevelSetFromPolygons(points f32[N,3], triangles=i32[M,3], "
                   "quads=i32[0,4], transform=createLinearTransform(voxelSize=cell)"
                   ".translate(origin), halfWidth=%g)" % band)
    res["threads"] = "TBB default (all %d cores)" % (os.cpu_count() or 0)

    times = []
    grid_out = None
    for r in range(repeat + 1):
        t0 = time.perf_counter()
        g = vdb.FloatGrid.createLevelSetFromPolygons(
            pts, triangles=tris, quads=quads, transform=xforms[r], halfWidth=float(band))
        t1 = time.perf_counter()
        if r == 0:
            res["cold_ms"] = ms(t1 - t0)
        else:
            times.append(t1 - t0)
        grid_out = g
        del g
    res.update(stats_ms(times))
    res["active_voxels"] = int(grid_out.activeVoxelCount())
    try:
        res["mem_bytes"] = int(grid_out.memUsage())
    except Exception:
        pass
    res["background"] = float(grid_out.background)

    # Dense copy over imprint's grid: OpenVDB arrays are indexed [x][y][z].
    t0 = time.perf_counter()
    nx, ny, nz = grid["dims"]
    arr = np.empty((nx, ny, nz), dtype=np.float32)
    grid_out.copyToArray(arr, ijk=(0, 0, 0))
    dense = np.ascontiguousarray(np.abs(arr).transpose(2, 1, 0))  # [nz, ny, nx], world units
    res["sample_ms"] = ms(time.perf_counter() - t0)
    # Active voxels outside imprint's box (OpenVDB's band is not clipped to it).
    lo, hi = grid_out.evalActiveVoxelBoundingBox()
    res["active_bbox_index"] = [list(lo), list(hi)]
    res["active_voxels_in_grid"] = int((dense < band * h * (1 - 1e-5)).sum())
    return res, dense


def run_open3d(o3d, info, V, T, Q, repeat, threads_list):
    res = {"available": True}
    res.update(info)
    t0 = time.perf_counter()
    Vt = o3d.core.Tensor(np.ascontiguousarray(V, dtype=np.float32))
    Tt = o3d.core.Tensor(np.ascontiguousarray(T, dtype=np.uint32))
    Qt = o3d.core.Tensor(np.ascontiguousarray(Q, dtype=np.float32))
    res["prep_ms"] = ms(time.perf_counter() - t0)
    res["queries"] = int(Q.shape[0])
    res["call"] = ("RaycastingScene(nthreads); add_triangles(V f32, T u32); "
                   "compute_distance(Q f32[N,3], nthreads)  (BVH build happens in the first query)")
    runs = {}
    out = None
    for nt in threads_list:
        key = "default" if nt == 0 else "threads_%d" % nt
        r = {"nthreads": nt}
        times, qtimes = [], []
        for rep in range(repeat + 1):
            t0 = time.perf_counter()
            scene = o3d.t.geometry.RaycastingScene(nthreads=nt)
            scene.add_triangles(Vt, Tt)
            d = scene.compute_distance(Qt, nthreads=nt)
            t1 = time.perf_counter()
            # Query again on the built scene: the cost for a static mesh.
            d2 = scene.compute_distance(Qt, nthreads=nt)
            t2 = time.perf_counter()
            if rep == 0:
                r["cold_ms"] = ms(t1 - t0)
            else:
                times.append(t1 - t0)
                qtimes.append(t2 - t1)
            out = d
            del scene, d2
        r.update(stats_ms(times))
        q = stats_ms(qtimes)
        r["query_only_median_ms"] = q["median_ms"]
        r["query_only_min_ms"] = q["min_ms"]
        runs[key] = r
    res["runs"] = runs
    first = runs.get("default") or next(iter(runs.values()))
    res["median_ms"] = first["median_ms"]
    res["min_ms"] = first["min_ms"]
    return res, out.numpy()


def exact_distance(o3d, V, T, pts):
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(V, dtype=np.float32)),
                        o3d.core.Tensor(np.ascontiguousarray(T, dtype=np.uint32)))
    shape = pts.shape[:-1]
    d = scene.compute_distance(o3d.core.Tensor(np.ascontiguousarray(pts.reshape(-1, 3),
                                                                    dtype=np.float32)))
    return d.numpy().reshape(shape)


def derive_band(o3d, V, T, grid, band_w, block=8):
    """Cells whose exact distance is < band_w, as ijk (i,j,k) int [N,3], ordered z, y, x.

    The distance is 1-Lipschitz, so a block of cells whose centre point is farther than
    band_w + the block's half-diagonal holds no band cell: only the other blocks' cells are
    queried (exact on every cell, far fewer queries than the whole grid)."""
    nx, ny, nz = grid["dims"]
    h = grid["cell_size"]
    o = np.asarray(grid["origin"], dtype=np.float64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(V, dtype=np.float32)),
                        o3d.core.Tensor(np.ascontiguousarray(T, dtype=np.uint32)))

    def dist(p):
        return scene.compute_distance(o3d.core.Tensor(
            np.ascontiguousarray(p.reshape(-1, 3), dtype=np.float32))).numpy().reshape(p.shape[:-1])

    axes = []
    for n in (nx, ny, nz):
        lo = np.arange(0, n, block)
        hi = np.minimum(lo + block, n) - 1
        axes.append(((lo + hi) * 0.5, (hi - lo) * 0.5))
    (cx, rx), (cy, ry), (cz, rz) = axes
    zz, yy, xx = np.meshgrid(cz, cy, cx, indexing="ij")
    centres = o + np.stack([xx, yy, zz], axis=-1) * h
    rz_, ry_, rx_ = np.meshgrid(rz, ry, rx, indexing="ij")
    radius = np.sqrt(rx_ ** 2 + ry_ ** 2 + rz_ ** 2) * h
    keep = dist(centres) - radius < band_w * (1 + 1e-4) + 1e-6 * h
    kb, jb, ib = np.nonzero(keep)
    r = np.arange(block)
    ii = (ib[:, None, None, None] * block + r[None, None, None, :])
    jj = (jb[:, None, None, None] * block + r[None, None, :, None])
    kk = (kb[:, None, None, None] * block + r[None, :, None, None])
    ii, jj, kk = np.broadcast_arrays(ii, jj, kk)
    ok = (ii < nx) & (jj < ny) & (kk < nz)
    ijk = np.stack([ii[ok], jj[ok], kk[ok]], axis=1)
    d = dist(cell_centres(grid, ijk))
    ijk = ijk[d < band_w]
    order = np.lexsort((ijk[:, 0], ijk[:, 1], ijk[:, 2]))
    return ijk[order]


# --------------------------------------------------------------------------- main

def versions():
    out = {"python": sys.executable, "python_version": platform.python_version()}
    out["numpy"] = np.__version__ if np is not None else {"available": False, "why": _NUMPY_WHY}
    if np is not None:
        vdb, i = import_openvdb()
        out["openvdb"] = dict(available=True, **i) if vdb else {"available": False, "why": i}
        o3d, i = import_open3d()
        out["open3d"] = dict(available=True, **i) if o3d else {"available": False, "why": i}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", help="OBJ mesh, used in its own coordinates")
    ap.add_argument("--grid", help='JSON {"origin":[x,y,z], "cell_size":h, "dims":[nx,ny,nz]}; '
                    "cell (i,j,k) centre = origin + (i,j,k)*h")
    ap.add_argument("--band", type=float, default=3.0, help="band half-width in cells (default 3)")
    ap.add_argument("--queries", help="f32 [N,3] world points for Open3D (imprint's band cells)")
    ap.add_argument("--dist-npy", help="imprint's distances, f32 [nz,ny,nx], world units, "
                    "far cells = band*cell; its band cells (< band*cell) are where OpenVDB "
                    "and exact distances are compared")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--o3d-threads", default="0,2",
                    help="comma list of Open3D nthreads to time (0 = its default); default 0,2")
    ap.add_argument("--skip", default="", help="comma list of baselines to skip: openvdb,open3d")
    ap.add_argument("--samples-out", help="optional .npz: band cell ijk (i,j,k) and the "
                    "distances there in cells: openvdb, exact, imprint")
    ap.add_argument("--openvdb-dist-out", help="optional .npy: OpenVDB unsigned distance on the "
                    "whole grid, f32 [nz,ny,nx], world units, far = band*cell")
    ap.add_argument("--out", help="result JSON (default: stdout)")
    ap.add_argument("--versions", action="store_true", help="print what is installed and exit")
    a = ap.parse_args(argv)

    if a.versions:
        print(json.dumps(versions(), indent=2))
        return 0
    if not a.mesh or not a.grid:
        ap.error("--mesh and --grid are required")
    if a.repeat < 1:
        ap.error("--repeat must be >= 1")

    result = {"schema": 1, "tool": "imprint benches/compare/baselines.py",
              "python": sys.executable, "python_version": platform.python_version(),
              "cpu_count": os.cpu_count(), "band_cells": a.band, "repeat": a.repeat}

    def write():
        text = json.dumps(result, indent=2)
        if a.out:
            with open(a.out, "w") as f:
                f.write(text + "\n")
        else:
            print(text)

    if np is None:
        result["error"] = _NUMPY_WHY
        result["baselines"] = {k: {"available": False, "why": _NUMPY_WHY}
                               for k in ("openvdb", "open3d")}
        write()
        return 0

    skip = {s.strip() for s in a.skip.split(",") if s.strip()}
    grid = load_grid(a.grid)
    h = grid["cell_size"]
    nx, ny, nz = grid["dims"]
    band_w = a.band * h
    result["grid"] = grid
    t0 = time.perf_counter()
    V, T = load_obj(a.mesh)
    result["mesh"] = {"path": a.mesh, "vertices": int(V.shape[0]), "triangles": int(T.shape[0]),
                      "load_ms": ms(time.perf_counter() - t0)}

    baselines = {}
    vdb = o3d = None
    if "openvdb" in skip:
        baselines["openvdb"] = {"available": False, "why": "skipped (--skip)"}
    else:
        vdb, info = import_openvdb()
        if vdb is None:
            baselines["openvdb"] = {"available": False, "why": info}
        else:
            vdb_info = info
    if "open3d" in skip:
        baselines["open3d"] = {"available": False, "why": "skipped (--skip)"}
    else:
        o3d, info = import_open3d()
        if o3d is None:
            baselines["open3d"] = {"available": False, "why": info}
        else:
            o3d_info = info

    # ---- band cells: where accuracy is compared (and Open3D's queries if none given)
    imprint = None
    band_ijk = None
    band = {}
    if a.dist_npy:
        imprint = np.load(a.dist_npy).astype(np.float32)
        if imprint.shape != (nz, ny, nx):
            raise SystemExit("--dist-npy shape %s, expected [nz,ny,nx] = %s"
                             % (imprint.shape, (nz, ny, nx)))
        kk, jj, ii = np.nonzero(imprint < band_w * (1 - 1e-5))
        band_ijk = np.stack([ii, jj, kk], axis=1)
        band["source"] = "imprint --dist-npy (cells with d < band*cell)"
    queries = None
    if a.queries:
        queries = np.load(a.queries).astype(np.float32).reshape(-1, 3)
        if band_ijk is None:
            f = (queries.astype(np.float64) - np.asarray(grid["origin"])) / h
            ijk = np.rint(f).astype(np.int64)
            on_centres = np.abs(f - ijk).max() < 1e-3 if len(f) else False
            inside = ((ijk >= 0) & (ijk < np.asarray([nx, ny, nz]))).all()
            if on_centres and inside:
                band_ijk = ijk
                band["source"] = "--queries (they lie on cell centres)"
    if band_ijk is None:
        if o3d is None:
            band["source"] = "none (needs --dist-npy, --queries on cell centres, or open3d)"
        else:
            t0 = time.perf_counter()
            band_ijk = derive_band(o3d, V, T, grid, band_w)
            band["source"] = "exact (Open3D) distance on all cells < band*cell"
            band["derive_ms"] = ms(time.perf_counter() - t0)
    if band_ijk is not None:
        band["cells"] = int(band_ijk.shape[0])
        if queries is None:
            queries = cell_centres(grid, band_ijk)
            band["queries"] = "band cell centres"
        else:
            band["queries"] = "--queries"
    result["band"] = band

    # ---- timings
    dense_vdb = None
    if vdb is not None:
        try:
            baselines["openvdb"], dense_vdb = run_openvdb(vdb, vdb_info, V, T, grid, a.band,
                                                          a.repeat)
        except Exception as e:
            baselines["openvdb"] = {"available": False,
                                    "why": "run failed: %s: %s" % (type(e).__name__, e)}
    if o3d is not None:
        if queries is None:
            baselines["open3d"] = {"available": False, "why": "no query points"}
        else:
            try:
                threads = [int(x) for x in a.o3d_threads.split(",") if x.strip()]
                baselines["open3d"], _ = run_open3d(o3d, o3d_info, V, T, queries, a.repeat,
                                                    threads)
            except Exception as e:
                o3d = None
                baselines["open3d"] = {"available": False,
                                       "why": "run failed: %s: %s" % (type(e).__name__, e)}
    result["baselines"] = baselines

    # ---- accuracy on the band cells, in cells, everything clamped to the band
    acc = {}
    samples = {}
    if band_ijk is not None and band_ijk.shape[0]:
        ii, jj, kk = band_ijk[:, 0], band_ijk[:, 1], band_ijk[:, 2]
        if o3d is not None:
            samples["exact"] = exact_distance(o3d, V, T, cell_centres(grid, band_ijk)) / h
        if dense_vdb is not None:
            samples["openvdb"] = dense_vdb[kk, jj, ii] / h
            s = samples["openvdb"]
            acc["openvdb_samples"] = {
                "n": int(s.size), "median": float(np.median(s)), "max": float(s.max()),
                "inactive_in_band": int((s >= a.band * (1 - 1e-5)).sum()),
            }
        if imprint is not None:
            samples["imprint"] = imprint[kk, jj, ii] / h
        if "openvdb" in samples and "exact" in samples:
            acc["openvdb_vs_exact"] = diff_stats(samples["openvdb"], samples["exact"], a.band)
        if "imprint" in samples and "exact" in samples:
            acc["imprint_vs_exact"] = diff_stats(samples["imprint"], samples["exact"], a.band)
        if "openvdb" in samples and "imprint" in samples:
            acc["openvdb_vs_imprint"] = diff_stats(samples["openvdb"], samples["imprint"], a.band)
        acc["note"] = ("cells; a_vs_b = a - b after clamping both to [0, band]; "
                       "max_over: a above b at most; max_under: a below b at most")
    result["accuracy"] = acc

    if a.samples_out and band_ijk is not None:
        np.savez_compressed(a.samples_out, ijk=band_ijk.astype(np.int32),
                            **{k: v.astype(np.float32) for k, v in samples.items()})
    if a.openvdb_dist_out and dense_vdb is not None:
        np.save(a.openvdb_dist_out, dense_vdb.astype(np.float32))
    write()
    return 0


if __name__ == "__main__":
    sys.exit(main())
