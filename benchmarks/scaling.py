"""How drpt's cost grows with the triangle count, against Mitsuba 3, in one run.

The scene family (:func:`make_scene`, numpy, in memory): a closed box room
(5 x 4 x 5, white diffuse walls facing in, 12 triangles, and a 2-triangle
area light under the ceiling) around one bumpy torus, a fixed smooth surface
(major radius 1.3, minor 0.55, radial bumps ``0.12 sin(7u) sin(5v)``)
tessellated into ``n_u x n_v`` quads, 2 triangles each. Only the tessellation
changes with the size asked for; the room, light, camera and materials are
the same, so the image (up to the faceting) is the same at every size.

For each triangle count (default about 1k, 10k, 100k, 1M and 4M):

* drpt: the BVH build (``--accel``, default ``bvh``: the 4-wide BVH with
  drpt's default build rule) in seconds, measured by :class:`Renderer` (the
  whole device scene: bounds, build, collapse, upload), and the accelerator's
  device bytes (``accel.nbytes``: nodes plus primitive data);
* drpt: path-tracing seconds at ``--size`` / ``--spp`` / ``--max-depth``, one
  warm-up render (compilation) excluded, the best of ``--repeat``;
* Mitsuba 3 (``llvm_ad_rgb``): ``mi.load_dict`` of the exported scene
  (:func:`drpt.export.mitsuba.to_mitsuba_dict`, meshes in memory; the load
  includes Embree's build), and the render at equal size, spp and depth,
  warm-up excluded, the best of ``--repeat``;
* ratios Mitsuba / drpt for times (> 1: drpt faster).

One untimed run at 1k triangles comes first (one-time initialisation).
Builds and loads run once per size (a 4M-triangle build is minutes of the
budget). Before each size the script compares an estimate of the memory it
needs (the growth of the peak resident memory per added triangle between
the first size and the largest one so far, else a fixed 3 KiB per triangle) with ``MemAvailable`` and skips the size,
printing why, if it does not fit. Prints a markdown table; timers are
bracketed by ``dr.sync_thread()``. Measure on an idle machine
(docs/performance.md).

    PYTHONPATH=. python benchmarks/scaling.py [--tris 1e3,1e4,1e5,1e6,4e6]
        [--size 128 128] [--spp 4] [--repeat 2] [--max-depth 8] [--accel bvh]
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import resource
import time

import numpy as np

ROOM = (5.0, 4.0, 5.0)  # x, y, z extent; floor at y = 0, centred on x = z = 0
FALLBACK_BYTES_PER_TRI = 3 * 1024


def torus_grid(n_tris: int) -> tuple[int, int]:
    """``(n_u, n_v)`` with ``2 n_u n_v`` close to ``n_tris`` and ``n_u`` about ``2 n_v``
    (the torus is about twice as long around as across)."""
    n_v = max(3, round(math.sqrt(n_tris / 4)))
    n_u = max(3, round(n_tris / (2 * n_v)))
    return n_u, n_v


def bumpy_torus(n_u: int, n_v: int) -> np.ndarray:
    """(2 n_u n_v, 3, 3) float64 corners of the torus, outward (counter-clockwise) winding."""
    R, r, a = 1.3, 0.55, 0.12
    u = 2 * np.pi * np.arange(n_u) / n_u
    v = 2 * np.pi * np.arange(n_v) / n_v
    U, V = np.meshgrid(u, v, indexing="ij")
    rad = r + a * np.sin(7 * U) * np.sin(5 * V)
    ring = R + rad * np.cos(V)
    P = np.stack([ring * np.cos(U), 1.3 + rad * np.sin(V), ring * np.sin(U)], axis=-1)
    i0 = np.arange(n_u)
    j0 = np.arange(n_v)
    I, J = np.meshgrid(i0, j0, indexing="ij")
    I1, J1 = (I + 1) % n_u, (J + 1) % n_v
    p00, p10, p11, p01 = P[I, J], P[I1, J], P[I1, J1], P[I, J1]
    # outward winding for this parametrisation: (p00, p01, p11), (p00, p11, p10)
    t0 = np.stack([p00, p01, p11], axis=-2).reshape(-1, 3, 3)
    t1 = np.stack([p00, p11, p10], axis=-2).reshape(-1, 3, 3)
    return np.concatenate([t0, t1])


def _quad(a, b, c, d) -> list[list]:
    return [[a, b, c], [a, c, d]]


def room() -> tuple[np.ndarray, np.ndarray]:
    """The room's triangles (walls facing in) and their material ids (0 white, 1 light)."""
    hx, hy, hz = ROOM[0] / 2, ROOM[1], ROOM[2] / 2
    c = {(sx, sy, sz): (sx * hx, sy * hy, sz * hz) for sx in (-1, 1) for sy in (0, 1) for sz in (-1, 1)}
    tris = []
    tris += _quad(c[-1, 0, -1], c[1, 0, -1], c[1, 0, 1], c[-1, 0, 1])  # floor
    tris += _quad(c[-1, 1, -1], c[-1, 1, 1], c[1, 1, 1], c[1, 1, -1])  # ceiling
    tris += _quad(c[-1, 0, 1], c[1, 0, 1], c[1, 1, 1], c[-1, 1, 1])  # back wall z+
    tris += _quad(c[-1, 0, -1], c[-1, 0, 1], c[-1, 1, 1], c[-1, 1, -1])  # left x-
    tris += _quad(c[1, 0, -1], c[1, 1, -1], c[1, 1, 1], c[1, 0, 1])  # right x+
    tris += _quad(c[-1, 0, -1], c[-1, 1, -1], c[1, 1, -1], c[1, 0, -1])  # front z-
    y = hy - 0.01
    s = 0.6
    light = _quad((-s, y, -s), (-s, y, s), (s, y, s), (s, y, -s))
    pos = np.array(tris + light, float)[:, [0, 2, 1]]  # the quads above are listed outward: flip
    mat = np.array([0] * len(tris) + [1] * len(light), np.int32)
    return pos, mat


def make_scene(n_tris: int):
    """The scene family's member with about ``n_tris`` triangles (:mod:`drpt.scene.model`)."""
    from pathlib import Path

    from drpt.scene.model import Material, PerspectiveCamera, Scene, Triangles

    walls, wall_mat = room()
    n_u, n_v = torus_grid(max(n_tris - len(walls), 18))
    obj = bumpy_torus(n_u, n_v)
    pos = np.concatenate([walls, obj])
    mat = np.concatenate([wall_mat, np.full(len(obj), 2, np.int32)])
    mats = [Material("white", kd=(0.75, 0.75, 0.75)),
            Material("light", kd=(0.0, 0.0, 0.0), emission=(20.0, 20.0, 20.0)),
            Material("torus", kd=(0.7, 0.35, 0.2))]
    cam = PerspectiveCamera(center=(0.0, 2.0, -2.45), direction=(0.0, -0.25, 1.0), up=(0.0, 1.0, 0.0), fov=60.0)
    return Scene(path=Path(f"scaling_{n_tris}.txt"), camera=cam, materials=mats,
                 triangles=Triangles(pos, mat))


def _peak_rss() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB


def _mem_available() -> int:
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return 0


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def measure(n_tris: int, size=(128, 128), spp: int = 4, repeat: int = 2, max_depth: int = 8,
            accel: str = "bvh", mitsuba: bool = True) -> dict:
    """One row of the table for the scene of about ``n_tris`` triangles."""
    import drjit as dr

    from drpt.options import PathOptions, RenderOptions, parse_accel
    from drpt.render.renderer import Renderer

    scene = make_scene(n_tris)
    W, H = size
    kind, rule = parse_accel(accel)
    opts = RenderOptions(width=W, height=H, spp=spp, bsdf="phong", accel=kind, bvh_method=rule or "auto",
                         progress=False, path=PathOptions(max_depth=max_depth)).validate()
    dr.sync_thread()
    r = Renderer(scene, opts)
    dr.sync_thread()
    row = {"tris": len(scene.triangles), "build_s": r.build_seconds,
           "accel_bytes": int(r.scene.accel.nbytes)}
    r.render()  # warm-up: compilation
    row["render_s"] = min(r.render().seconds for _ in range(repeat))
    del r
    gc.collect()
    if mitsuba:
        import mitsuba as mi

        from drpt import llvm_tuning
        from drpt.backend import set_mitsuba_variant
        from drpt.export.mitsuba import to_mitsuba_dict
        from drpt.tools.bench import mitsuba_render_seconds

        set_mitsuba_variant()
        with llvm_tuning.dr_default():  # Mitsuba as it ships
            desc = to_mitsuba_dict(scene, W, H, spp, max_depth=max_depth, bsdf="phong")
            dr.sync_thread()
            t0 = time.perf_counter()
            ms = mi.load_dict(desc)
            dr.sync_thread()
            row["mi_load_s"] = time.perf_counter() - t0
            row["mi_render_s"] = mitsuba_render_seconds(ms, spp, repeat)
        del ms, desc
        gc.collect()
    return row


def format_table(rows: list[dict], mitsuba: bool = True) -> str:
    head = ["triangles", "drpt build s", "accel MiB", "accel B/tri", "drpt render s"]
    if mitsuba:
        head += ["Mitsuba load s", "Mitsuba render s", "build / load", "render ratio"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        if "skipped" in r:
            lines.append(f"| {r['tris']} | skipped: {r['skipped']} |" + " |" * (len(head) - 2))
            continue
        cells = [f"{r['tris']}", f"{r['build_s']:.3g}", f"{r['accel_bytes'] / 2**20:.3g}",
                 f"{r['accel_bytes'] / r['tris']:.0f}", f"{r['render_s']:.3g}"]
        if mitsuba:
            cells += [f"{r['mi_load_s']:.3g}", f"{r['mi_render_s']:.3g}",
                      f"{r['mi_load_s'] / r['build_s']:.2f}x", f"{r['mi_render_s'] / r['render_s']:.2f}x"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tris", default="1e3,1e4,1e5,1e6,4e6", help="comma-separated triangle counts")
    p.add_argument("--size", type=int, nargs=2, default=(128, 128), metavar=("W", "H"))
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--repeat", type=int, default=2, help="timed renders per number, best kept")
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--accel", default="bvh")
    p.add_argument("--no-mitsuba", action="store_true")
    a = p.parse_args(argv)
    counts = [int(float(t)) for t in a.tris.split(",")]
    mitsuba = not a.no_mitsuba
    print(f"{a.size[0]}x{a.size[1]}, {a.spp} spp, max depth {a.max_depth}, --accel {a.accel}, "
          f"render best of {a.repeat} after a warm-up, build and load once; load average at start: {_load()}",
          flush=True)
    rows = []
    # one untimed run first: Dr.Jit's and Mitsuba's one-time initialisation is not the first size's
    measure(1000, (16, 16), 1, 1, a.max_depth, a.accel, mitsuba)
    first = None  # (triangles, peak RSS) of the first size measured
    per_tri = None
    for n in counts:
        need = int(n * (per_tri or FALLBACK_BYTES_PER_TRI))
        avail = _mem_available()
        if need > avail:
            reason = (f"needs about {need / 2**30:.1f} GiB (estimated), "
                      f"{avail / 2**30:.1f} GiB available")
            print(f"skipping {n} triangles: {reason}", flush=True)
            rows.append({"tris": n, "skipped": reason})
            continue
        row = measure(n, tuple(a.size), a.spp, a.repeat, a.max_depth, a.accel, mitsuba)
        peak = _peak_rss()
        if first is None:
            first = (row["tris"], peak)
        elif row["tris"] > first[0]:
            # peak memory per added triangle (the fixed cost of the libraries excluded)
            per_tri = max(per_tri or 0.0, (peak - first[1]) / (row["tris"] - first[0]))
        print(f"{row['tris']} triangles done: peak RSS {peak / 2**30:.2f} GiB, load {_load()}", flush=True)
        rows.append(row)
    print(f"load average at end: {_load()}")
    print(format_table(rows, mitsuba))
    return rows


if __name__ == "__main__":
    main()
