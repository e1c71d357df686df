#!/usr/bin/env python3
"""Taichi (CPU) baseline for the cloth section of BENCHMARKS.md: the same mass-spring cloth
as imprint's comparison scene, written plainly, timed in the same run.

Model (the one ``imprint_stages::cloth`` runs with ``stiffness_mode: Strain``):

* an N x N grid of particles, 1 m wide, flat at height ``--height``, centred on
  (``--offset-x``, ``--offset-z``) in x/z; particle mass ``--mass``;
* structural (4) and shear (4 diagonal) springs, force f = Y (l / l0 - 1) along the spring;
* gravity (0, -9.81, 0);
* position Verlet with damping d: x' = x + d (x - x_prev) + (F / m + g) dt^2;
* a sphere of radius ``--radius`` at the origin, analytic: with s = |x' - c| - r and the
  outward normal n = (x' - c) / |x' - c|, when s < eps the particle is moved along n to
  distance eps (x' += (eps - s) n), then the fraction b of its tangential displacement over
  the substep is cancelled: step = x' - x, x' -= b (step - (step . n) n)
  (imprint's ``cloth::contact::respond``).

One kernel call per substep (``--substeps`` per frame of 1 / ``--fps`` s), as Taichi's own
cloth example does it: the first top-level loop computes every particle's next position from
the current and previous ones, the second rotates the buffers (Taichi runs a kernel's
top-level loops one after the other, each in parallel over the particles).

Timing: one frame is run first and thrown away (JIT compile), the state is reset, then the
``--frames`` frames are run ``--repeat`` times from the start, each run timed as a whole
(``ti.sync()`` before reading the clock) and frame by frame. Prints one JSON object (last line
of stdout) and writes it to ``--out`` when given: ``ms_per_frame`` (median over runs of
total / frames), ``median_frame_ms`` (median frame of the last run), ``ns_per_particle_substep``,
``mean_height`` (mean y after the last frame), ``min_sphere_distance`` (smallest |x - c| - r),
``taichi_version``, ``threads``.

Run it with any ``python3``: like baselines.py it re-executes itself under install.sh's venv
(``benches/compare/.venv`` or ``$IMPRINT_BASELINES_VENV``) when that exists.
"""

import argparse
import json
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
VENV = os.environ.get("IMPRINT_BASELINES_VENV", os.path.join(HERE, ".venv"))


def _maybe_reexec():
    """Run under install.sh's virtual environment when it exists and we are not in it."""
    if os.environ.get("IMPRINT_BASELINES_NO_REEXEC"):
        return
    py = os.path.join(VENV, "bin", "python")
    if not os.path.exists(py) or os.path.realpath(sys.prefix) == os.path.realpath(VENV):
        return
    os.environ["IMPRINT_BASELINES_NO_REEXEC"] = "1"
    os.execv(py, [py, os.path.abspath(__file__)] + sys.argv[1:])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=64, help="particles per side")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--fps", type=float, default=60.0)
    ap.add_argument("--substeps", type=int, default=32)
    ap.add_argument("--stiffness", type=float, default=1e4, help="Y, N per unit strain")
    ap.add_argument("--mass", type=float, default=1.0)
    ap.add_argument("--damping", type=float, default=0.9995)
    ap.add_argument("--height", type=float, default=0.6)
    ap.add_argument("--offset-x", type=float, default=0.031)
    ap.add_argument("--offset-z", type=float, default=0.017)
    ap.add_argument("--radius", type=float, default=0.3)
    ap.add_argument("--epsilon", type=float, default=0.005)
    ap.add_argument("--friction", type=float, default=0.3)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0, help="0: Taichi's default (all cores)")
    ap.add_argument("--f64", action="store_true", help="double precision (a reference run)")
    ap.add_argument("--out", help="also write the JSON here")
    a = ap.parse_args()
    if a.n < 2 or a.frames < 1 or a.substeps < 1 or a.repeat < 1:
        ap.error("--n >= 2, --frames, --substeps and --repeat >= 1")

    import taichi as ti

    fp = ti.f64 if a.f64 else ti.f32
    init = dict(arch=ti.cpu, default_fp=fp, log_level=ti.WARN, random_seed=0)
    if a.threads > 0:
        init["cpu_max_num_threads"] = a.threads
    ti.init(**init)

    n = a.n
    l0 = 1.0 / (n - 1)
    dt = 1.0 / a.fps / a.substeps
    x = ti.Vector.field(3, dtype=fp, shape=(n, n))
    x_prev = ti.Vector.field(3, dtype=fp, shape=(n, n))
    x_next = ti.Vector.field(3, dtype=fp, shape=(n, n))

    offsets = []
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if (di, dj) != (0, 0):
                offsets.append((di, dj, l0 * (di * di + dj * dj) ** 0.5))

    Y, m, d = a.stiffness, a.mass, a.damping
    r, eps, b = a.radius, a.epsilon, a.friction
    g = ti.Vector([0.0, -9.81, 0.0], dt=fp)
    centre = ti.Vector([0.0, 0.0, 0.0], dt=fp)

    @ti.kernel
    def reset():
        for i, j in x:
            p = ti.Vector([a.offset_x + (i * l0 - 0.5), a.height, a.offset_z + (j * l0 - 0.5)])
            x[i, j] = p
            x_prev[i, j] = p

    @ti.kernel
    def substep():
        for i, j in x:
            xi = x[i, j]
            f = ti.Vector([0.0, 0.0, 0.0], dt=fp)
            for k in ti.static(range(len(offsets))):
                di, dj, rest = offsets[k]
                p, q = i + di, j + dj
                if 0 <= p < n and 0 <= q < n:
                    e = x[p, q] - xi
                    length = e.norm()
                    f += Y * (length / rest - 1.0) * e / length
            xn = xi + d * (xi - x_prev[i, j]) + (f / m + g) * (dt * dt)
            rel = xn - centre
            dist = rel.norm()
            s = dist - r
            if s < eps and dist > 0:
                nrm = rel / dist
                xn += (eps - s) * nrm
                step = xn - xi
                xn -= b * (step - step.dot(nrm) * nrm)
            x_next[i, j] = xn
        for i, j in x:
            x_prev[i, j] = x[i, j]
            x[i, j] = x_next[i, j]

    def frame():
        for _ in range(a.substeps):
            substep()

    # JIT compile outside the timing: one frame, then start again.
    t0 = time.perf_counter()
    reset()
    frame()
    ti.sync()
    warm_ms = (time.perf_counter() - t0) * 1e3

    run_ms, frame_ms = [], []
    for _ in range(a.repeat):
        reset()
        ti.sync()
        frame_ms = []
        t_run = time.perf_counter()
        for _ in range(a.frames):
            t = time.perf_counter()
            frame()
            ti.sync()
            frame_ms.append((time.perf_counter() - t) * 1e3)
        run_ms.append((time.perf_counter() - t_run) * 1e3)

    pos = x.to_numpy().reshape(-1, 3).astype("float64")
    mean_height = float(pos[:, 1].mean())
    min_dist = float(((pos ** 2).sum(axis=1) ** 0.5 - r).min())
    per_frame = sorted(t / a.frames for t in run_ms)[len(run_ms) // 2]
    out = {
        "n": n,
        "particles": n * n,
        "frames": a.frames,
        "substeps": a.substeps,
        "precision": "f64" if a.f64 else "f32",
        "ms_per_frame": per_frame,
        "median_frame_ms": sorted(frame_ms)[len(frame_ms) // 2],
        "run_ms": run_ms,
        "ns_per_particle_substep": per_frame * 1e6 / (n * n * a.substeps),
        "mean_height": mean_height,
        "min_sphere_distance": min_dist,
        "compile_and_first_frame_ms": warm_ms,
        "taichi_version": ".".join(str(v) for v in ti.__version__),
        "threads": a.threads if a.threads > 0 else os.cpu_count(),
        "python_version": platform.python_version(),
    }
    text = json.dumps(out)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    _maybe_reexec()
    sys.exit(main())
