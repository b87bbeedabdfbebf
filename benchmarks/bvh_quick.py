"""Quick BVH benchmark (not a test): build time and closest-hit Mrays/s.

A displaced tessellated sphere (~500k triangles) is hit by ~1M random rays
(origins on a surrounding sphere, aimed at jittered points near the centre).
Run: .venv/bin/python benchmarks/bvh_quick.py [n_theta] [n_rays]
"""

from __future__ import annotations

import sys
import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Float

from drpt.accel import build_accel
from drpt.scene import model as M


def displaced_sphere(nt: int) -> np.ndarray:
    npf = 2 * nt
    th = np.linspace(0, np.pi, nt + 1)
    ph = np.linspace(0, 2 * np.pi, npf + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    r = 1 + 0.05 * np.sin(7 * T) * np.cos(9 * P) + 0.02 * np.sin(31 * P + 13 * T)
    v = np.stack([r * np.sin(T) * np.cos(P), r * np.sin(T) * np.sin(P), r * np.cos(T)], -1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    t1 = np.stack([a, b, c], 2).reshape(-1, 3, 3)
    t2 = np.stack([a, c, d], 2).reshape(-1, 3, 3)
    return np.concatenate([t1, t2])


def main():
    nt = int(sys.argv[1]) if len(sys.argv) > 1 else 354
    R = int(sys.argv[2]) if len(sys.argv) > 2 else 1 << 20
    tris = displaced_sphere(nt)
    F = len(tris)
    sc = M.Scene(path=None, camera=M.PerspectiveCamera((0, 0, 0), (0, 0, 1), (0, 1, 0), 40),
                 materials=[M.Material("m")], triangles=M.Triangles(tris, np.zeros(F, np.int32)))
    rng = np.random.default_rng(0)
    o = rng.normal(size=(R, 3))
    o = 3 * o / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.normal(size=(R, 3)) * 0.7 - o / 3
    O = Array3f(*o.T.astype(np.float32))
    D = Array3f(*d.T.astype(np.float32))
    T = Float(np.full(R, np.inf, np.float32))
    dr.eval(O, D, T)
    for method in ("sah", "median"):
        bvh = build_accel(sc, "bvh", method=method)
        print(f"{method}: {F} triangles, build {bvh.build_seconds:.2f} s, "
              f"{bvh.nbytes / 2**20:.1f} MiB, stats {bvh.stats}")
        for q in ("intersect", "occluded"):
            for it in range(3):
                # fresh inputs each run, so nothing is reused from the last one
                T = Float(np.full(R, 1e30 + it, np.float32))
                dr.eval(T)
                dr.sync_thread()
                t0 = time.perf_counter()
                if q == "intersect":
                    h = bvh.intersect(O, D, T)
                    dr.eval(h.t, h.prim, h.u, h.v)
                else:
                    h = bvh.occluded(O, D, T)
                    dr.eval(h)
                dr.sync_thread()
                dt = time.perf_counter() - t0
                print(f"  {q} run {it}: {dt:.3f} s = {R / dt / 1e6:.2f} Mrays/s")


if __name__ == "__main__":
    main()
