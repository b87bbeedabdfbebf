"""Coherence sort A/B (not a test): the closest-hit kernel on one bounce's rays, four orders.

A wavefront render (``--mode wavefront``, sort off) of SCENE is stopped at bounce
BOUNCE and its compacted rays (pixel order) are kept; then the accelerator's
closest-hit kernel traces the same rays in four orders, interleaved, ROUNDS
rounds: pixel order, the wavefront's key (direction octant, then origin Morton
code), Morton code only, and a random permutation. Prints the best and median
wall time of each (``dr.sync_thread`` around each launch).

Run: PYTHONPATH=. .venv/bin/python benchmarks/wavefront_sort_ab.py SCENE [SIZE] [SPP] [BOUNCE] [ROUNDS]
"""

from __future__ import annotations

import sys
import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, UInt32

from drpt.options import RenderOptions
from drpt.render.integrators import wavefront as wf
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


def main(argv: list[str]) -> None:
    scene = load_scene(argv[0])
    size = int(argv[1]) if len(argv) > 1 else 128
    spp = int(argv[2]) if len(argv) > 2 else 8
    bounce = int(argv[3]) if len(argv) > 3 else 2
    rounds = int(argv[4]) if len(argv) > 4 else 6
    r = Renderer(scene, RenderOptions(width=size, height=size, spp=spp, progress=False, mode="wavefront",
                                      accel="bvh", bsdf="auto"))
    integ = r.integrator
    integ.sort = False
    kept, seen = {}, [0]
    compact = integ._compact

    def grab(s, alive, timer):
        out, m = compact(s, alive, timer)
        if seen[0] == bounce:
            kept["s"] = out
        seen[0] += 1
        return out, m

    integ._compact = grab
    r.render()
    s = kept["s"]
    n = dr.width(s.lane)
    o, d = s.o, s.d
    lo = Array3f(dr.min(o.x), dr.min(o.y), dr.min(o.z))
    hi = Array3f(dr.max(o.x), dr.max(o.y), dr.max(o.z))
    key = wf.ray_key(o, d, lo, hi)
    orders = {"pixel order": dr.arange(UInt32, n),
              "octant + Morton": wf.sort_permutation(key, wf.KEY_BITS),
              "Morton only": wf.sort_permutation(key & ((1 << (3 * wf.MORTON_BITS)) - 1), 3 * wf.MORTON_BITS),
              "random": UInt32(np.random.default_rng(0).permutation(n).astype(np.uint32))}
    rays = {}
    for name, p in orders.items():
        oo, dd = dr.gather(Array3f, o, p), dr.gather(Array3f, d, p)
        dr.eval(oo, dd)
        rays[name] = (oo, dd)
    times: dict[str, list[float]] = {k: [] for k in rays}
    for _ in range(rounds + 1):  # the first round compiles
        for name, (oo, dd) in rays.items():
            dr.sync_thread()
            t0 = time.perf_counter()
            hit = r.scene.intersect_preliminary(oo, dd, dr.full(Bool, True, n))
            dr.eval(hit.t, hit.prim)
            dr.sync_thread()
            times[name].append(time.perf_counter() - t0)
    print(f"{n} rays of bounce {bounce} ({size}x{size}, {spp} spp), best / median of {rounds}:")
    base = min(times["pixel order"][1:])
    for name, v in times.items():
        v = v[1:]
        print(f"  {name:16s} {1e3 * min(v):8.1f} ms  {1e3 * float(np.median(v)):8.1f} ms  "
              f"({min(v) / base:.2f}x pixel order)")


if __name__ == "__main__":
    main(sys.argv[1:])
