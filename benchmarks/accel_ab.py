"""Accelerator A/B in one process (not a test): ray throughput of variants on the same rays.

Each VARIANT is ``bvh`` (the current 4-wide BVH, :func:`drpt.accel.build_accel`), another
``--accel`` kind (``bvh2``, ``grid``, ...), or the path of a Python file defining
``make(scene)`` that returns an object with the accelerator queries (a modified copy of
``drpt/accel/bvh4.py``, say). All variants trace ``bench``'s rays of SCENE
(:func:`drpt.tools.bench.make_rays`: N primary, incoherent and shadow rays); every query
is compiled once first, and its hit ids are compared with the first variant's (a count
of differing rays is printed: ties between equal distances may differ between trees).
Then ROUNDS rounds time every variant on every query, alternating the order of the
variants from round to round, and the ratio of each variant against the first is taken
within each round. Prints each variant's best rate and the median ratio with the range of
the per-round ratios; on a machine whose speed drifts, the median of many rounds is the
number to read.

Run: PYTHONPATH=. .venv/bin/python benchmarks/accel_ab.py SCENE N ROUNDS VARIANT [VARIANT...]
e.g. ``benchmarks/accel_ab.py scenes/diningroom/diningroom.txt 262144 12 bvh /tmp/bvh4_b.py``.
"""

from __future__ import annotations

import importlib.util
import math
import statistics
import sys
import time

import drjit as dr
import numpy as np
from drjit.auto import Float

from drpt.accel import build_accel
from drpt.accel.registry import ACCELERATORS
from drpt.scene import load_scene
from drpt.tools.bench import device_rays, make_rays


def _variant(scene, name: str):
    if name in ACCELERATORS:
        return build_accel(scene, kind=name)
    spec = importlib.util.spec_from_file_location(f"variant_{abs(hash(name))}", name)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.make(scene)


def _timed(fn):
    dr.sync_thread()
    t0 = time.perf_counter()
    out = fn()
    dr.eval(out)
    dr.sync_thread()
    return time.perf_counter() - t0, out


def main(argv: list[str]) -> None:
    if len(argv) < 4:
        sys.exit(__doc__.strip().splitlines()[-2])
    scene = load_scene(argv[0])
    n, rounds, names = int(argv[1]), int(argv[2]), argv[3:]
    po, pd, io, idr, sd, st = device_rays(make_rays(scene, n, 1.0, 0))
    inf = Float(math.inf)
    accels = [_variant(scene, v) for v in names]
    queries = {
        "primary": lambda a: a.intersect(po, pd, inf).prim,
        "incoherent": lambda a: a.intersect(io, idr, inf).prim,
        "shadow": lambda a: a.occluded(io, sd, st),
    }
    first = {}
    for name, a in zip(names, accels):
        for q, f in queries.items():
            _, out = _timed(lambda f=f, a=a: f(a))
            got = out.numpy()
            ref = first.setdefault(q, got)
            if not np.array_equal(got, ref):
                print(f"{name} {q}: {int(np.sum(got != ref))} rays differ from {names[0]}")
    best = {(i, q): math.inf for i in range(len(names)) for q in queries}
    ratios = {(i, q): [] for i in range(len(names)) for q in queries}
    for r in range(rounds):
        order = list(range(len(names)))
        if r % 2:
            order.reverse()
        for q, f in queries.items():
            dt = {}
            for i in order:
                dt[i], _ = _timed(lambda f=f, a=accels[i]: f(a))
                best[(i, q)] = min(best[(i, q)], dt[i])
            for i in order:
                ratios[(i, q)].append(dt[0] / dt[i])
    for q in queries:
        cells = []
        for i, name in enumerate(names):
            rs = ratios[(i, q)]
            cells.append(f"{name}: {n / best[(i, q)] / 1e6:.2f} Mrays/s, "
                         f"{statistics.median(rs):.3f}x [{min(rs):.2f}-{max(rs):.2f}]")
        print(f"{q:10s}  " + "  |  ".join(cells))


if __name__ == "__main__":
    main(sys.argv[1:])
