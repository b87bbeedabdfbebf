"""drpt's and Mitsuba's ray queries on ``bench``'s rays, interleaved in one process (not a test).

``bench`` times Mitsuba's queries, then drpt's, best of ``--repeat``; Mitsuba's rates move
by up to 40% between runs, and the ratios with them. This script builds drpt's
accelerator (``auto``) and loads the scene into Mitsuba once, then alternates the two
renderers' closest-hit (primary, incoherent) and shadow queries for ROUNDS rounds and
prints each one's median and best Mrays/s and the median of per-round ratios (drpt /
Mitsuba). Mitsuba runs with Dr.Jit's own settings (``drpt.llvm_tuning.dr_default``).

Run: PYTHONPATH=. .venv/bin/python benchmarks/rays_vs_mitsuba.py SCENE [ROUNDS] [RAYS]
(defaults 16, 262144; square image rays, seed 0).
"""

from __future__ import annotations

import contextlib
import math
import os
import statistics
import sys
import time

import drjit as dr


def main(argv: list[str]) -> None:
    from drjit.auto import Float

    from drpt import llvm_tuning
    from drpt.accel import build_accel
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.scene import load_scene
    from drpt.tools.bench import device_rays, make_rays, mitsuba_rays

    scene = load_scene(argv[0])
    rounds = int(argv[1]) if len(argv) > 1 else 16
    n = int(argv[2]) if len(argv) > 2 else 262144
    ensure()
    rays = make_rays(scene, n, 1.0, 0)
    po, pd, io, idr, sd, st = device_rays(rays)
    accel = build_accel(scene, kind="auto")
    mi = set_mitsuba_variant()
    with llvm_tuning.dr_default():
        ms = mi.load_dict(to_mitsuba_dict(scene, 64, 64, 1, bsdf="auto"))
        rp, ri, rs = mitsuba_rays(rays)
    inf = Float(math.inf)

    def drpt_hit(o, d):
        h = accel.intersect(o, d, inf)
        return h.t, h.prim

    def mitsuba_hit(r):
        pi = ms.ray_intersect_preliminary(r)
        return pi.t, pi.prim_index

    queries = {
        "primary": (lambda: drpt_hit(po, pd), lambda: mitsuba_hit(rp)),
        "incoherent": (lambda: drpt_hit(io, idr), lambda: mitsuba_hit(ri)),
        "shadow": (lambda: accel.occluded(io, sd, st), lambda: ms.ray_test(rs)),
    }
    print(f"{accel.__class__.__name__}, {n} rays, {rounds} rounds, load average "
          f"{os.getloadavg()[0]:.2f}")
    for name, (ours, theirs) in queries.items():
        times = {"drpt": [], "mitsuba": []}

        def run(who: str, ours=ours, theirs=theirs) -> float:
            with llvm_tuning.dr_default() if who == "mitsuba" else contextlib.nullcontext():
                fn = ours if who == "drpt" else theirs
                dr.sync_thread()
                t0 = time.perf_counter()
                dr.eval(fn())
                dr.sync_thread()
                return time.perf_counter() - t0

        run("drpt"), run("mitsuba")  # compile
        for i in range(rounds):
            for who in (("drpt", "mitsuba") if i % 2 == 0 else ("mitsuba", "drpt")):
                times[who].append(run(who))
        rate = {w: (n / statistics.median(t) / 1e6, n / min(t) / 1e6) for w, t in times.items()}
        ratio = statistics.median(m / d for d, m in zip(times["drpt"], times["mitsuba"]))
        print(f"{name:10s} drpt {rate['drpt'][0]:.1f} (best {rate['drpt'][1]:.1f}) Mrays/s, "
              f"Mitsuba {rate['mitsuba'][0]:.1f} (best {rate['mitsuba'][1]:.1f}), "
              f"drpt / Mitsuba {ratio:.2f}x")


if __name__ == "__main__":
    main(sys.argv[1:])
