"""drpt BVH vs Mitsuba 3 (llvm_ad_rgb): build time and ray throughput, one process.

Scenes: (a) the Cornell box (``scenes/cornellbox/cornellbox.txt``), (b) a
procedural displaced sphere (~500k triangles, ``--nt 354``).

Per scene, measured in the same process:

* build: drpt ``build_accel`` (host build + upload) vs Mitsuba scene creation
  (``to_mitsuba_dict`` + ``mi.load_dict``, which includes its BVH build);
* ``primary``: closest hit for the camera's rays (a ``W x H`` image in scanline
  order, coherent);
* ``incoherent``: closest hit for rays from uniform random points inside the
  scene bounds in uniform random directions;
* ``shadow``: ``occluded`` vs Mitsuba ``ray_test`` for segments between two
  uniform random points inside the bounds (``tmax = 1``, ``d = p1 - p0``).

Every query is compiled once (warm-up), then timed 3 times with fresh device
inputs (new buffers + ``dr.make_opaque``) between ``dr.sync_thread()`` calls;
the best time counts. Mitsuba and
the drpt variants alternate within each repetition (the machine may be
shared; alternating spreads load changes evenly). Ratios are drpt / Mitsuba (higher is better for
Mrays/s; for build time the ratio is drpt seconds / Mitsuba seconds).

``--variants base,new`` also measures a frozen copy of an earlier BVH next
to the current one, for before/after ratios in the same run. The copy is not
kept in the repository; recreate it from the commit to compare against, e.g.
``git show c4f0a3f:drpt/accel/bvh.py > benchmarks/_baseline_bvh.py`` and the
same for ``bvh_build.py`` -> ``benchmarks/_baseline_bvh_build.py`` (fix its
relative imports to absolute ``drpt.`` ones).

Run: /work/venv/bin/python benchmarks/accel_vs_mitsuba.py [--nt 354] [--res 1024]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import drjit as dr
import numpy as np
from drjit.llvm import Array3f, Float

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from drpt.accel import build_accel  # noqa: E402
from drpt.render.camera import RayCamera  # noqa: E402
from drpt.scene import load_scene  # noqa: E402
from drpt.scene import model as M  # noqa: E402


REPS = 3


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


def sphere_scene(nt: int):
    tris = displaced_sphere(nt)
    F = len(tris)
    cam = M.PerspectiveCamera((0.3, 0.4, -3.2), (-0.1, -0.12, 1), (0, 1, 0), 40)
    return M.Scene(path=None, camera=cam, materials=[M.Material("m")],
                   triangles=M.Triangles(tris, np.zeros(F, np.int32)))


# ------------------------------------------------------------------------ rays
def make_rays(scene, kind: str, res: int, n: int, seed: int):
    """numpy ``(o, d, tmax)`` float32 arrays of one ray set."""
    rng = np.random.default_rng(seed)
    if kind == "primary":
        cam = RayCamera(scene.camera, res, res)
        j, i = np.divmod(np.arange(res * res), res)
        x = Float((i + 0.5).astype(np.float32))
        y = Float((j + 0.5).astype(np.float32))
        o, d = cam.ray(x, y)
        o = np.stack([np.broadcast_to(o[k].numpy(), (res * res,)) for k in range(3)], 1)
        d = np.stack([d[k].numpy() for k in range(3)], 1)
        return o.astype(np.float32), d.astype(np.float32), np.full(res * res, np.inf, np.float32)
    lo, hi = scene.bounds()
    ext = hi - lo
    lo, hi = lo + 0.01 * ext, hi - 0.01 * ext
    o = lo + rng.random((n, 3)) * (hi - lo)
    if kind == "incoherent":
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return o.astype(np.float32), d.astype(np.float32), np.full(n, np.inf, np.float32)
    p1 = lo + rng.random((n, 3)) * (hi - lo)
    return o.astype(np.float32), (p1 - o).astype(np.float32), np.ones(n, np.float32)


def drpt_runner(accel, rays, query):
    """Warmed-up ``(run(rep), n_rays)`` for a drpt accelerator."""
    o, d, tm = rays

    def inputs():
        O = Array3f(*o.T)
        D = Array3f(*d.T)
        T = Float(tm)
        dr.make_opaque(O, D, T)
        return O, D, T

    prepared = []

    def run(rep):
        O, D, T = prepared[rep]
        if query == "occluded":
            dr.eval(accel.occluded(O, D, T))
        else:
            h = accel.intersect(O, D, T)
            dr.eval(h.t, h.prim, h.u, h.v, h.valid)

    prepared[:] = [inputs()]
    dr.eval(prepared)
    run(0)  # warm-up: compile
    dr.sync_thread()
    prepared[:] = [inputs() for _ in range(REPS)]  # fresh inputs for each timed run
    dr.eval(prepared)
    dr.sync_thread()
    return run


def mitsuba_runner(mi, mscene, rays, query):
    o, d, tm = rays

    def inputs():
        r = mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T))
        r.maxt = mi.Float(tm)
        dr.make_opaque(r)
        return r

    prepared = []

    def run(rep):
        r = prepared[rep]
        if query == "occluded":
            dr.eval(mscene.ray_test(r))
        else:
            pi = mscene.ray_intersect_preliminary(r)
            dr.eval(pi.t, pi.prim_index, pi.prim_uv, pi.shape_index)

    prepared[:] = [inputs()]
    dr.eval(prepared)
    run(0)
    dr.sync_thread()
    prepared[:] = [inputs() for _ in range(REPS)]
    dr.eval(prepared)
    dr.sync_thread()
    return run


def time_interleaved(runners: dict, n: int) -> dict:
    """Best-of-REPS Mrays/s per runner; runners alternate within each round so
    that load changes on the machine hit all of them alike."""
    best = {k: np.inf for k in runners}
    for rep in range(REPS):
        for k, run in runners.items():
            dr.sync_thread()
            t0 = time.perf_counter()
            run(rep)
            dr.sync_thread()
            best[k] = min(best[k], time.perf_counter() - t0)
    return {k: n / v / 1e6 for k, v in best.items()}


def load_mitsuba(mi, scene):
    from drpt.export.mitsuba import to_mitsuba_dict

    best = np.inf
    for _ in range(2):
        dr.sync_thread()
        t0 = time.perf_counter()
        ms = mi.load_dict(to_mitsuba_dict(scene, 64, 64, 4))
        dr.sync_thread()
        best = min(best, time.perf_counter() - t0)
    return ms, best


def build_variant(name, scene, args):
    kw = dict(method="sah", leaf_size=args.leaf, bins=args.bins)
    ct, ci = args.ct, args.ci
    # "new#leaf=8#ct=2#ci=1": build options per variant
    for kv in name.split("@")[0].split("#")[1:]:
        k, v = kv.split("=")
        if k == "leaf":
            kw["leaf_size"] = int(v)
        elif k == "ct":
            ct = float(v)
        elif k == "ci":
            ci = float(v)
        elif k == "method":
            kw["method"] = v
    best, acc = np.inf, None
    for _ in range(args.build_reps):
        if name.split("@")[0].split("#")[0] == "base":
            import _baseline_bvh

            acc = _baseline_bvh.BVH(scene, **kw)
        else:
            from drpt.accel.bvh import BVH

            saved = BVH.traversal_cost, BVH.intersection_cost
            BVH.traversal_cost, BVH.intersection_cost = ct, ci
            acc = build_accel(scene, "bvh", **kw)
            BVH.traversal_cost, BVH.intersection_cost = saved
        best = min(best, acc.build_seconds)
    # "name@attr=value@...": set attributes on the accelerator (A/B switches)
    for kv in name.split("@")[1:]:
        k, v = kv.split("=")
        setattr(acc, k, type(getattr(acc, k))(eval(v)))
    return acc, best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--nt", type=int, default=354, help="sphere tessellation (2*nt^2*2 tris)")
    ap.add_argument("--res", type=int, default=1024, help="primary rays: res x res")
    ap.add_argument("--rays", type=int, default=1 << 20, help="incoherent/shadow rays")
    ap.add_argument("--variants", default="new", help="comma list of base,new")
    ap.add_argument("--scenes", default="cornell,sphere")
    ap.add_argument("--queries", default="primary,incoherent,shadow")
    ap.add_argument("--leaf", type=int, default=4)
    ap.add_argument("--bins", type=int, default=16)
    ap.add_argument("--build-reps", type=int, default=2)
    ap.add_argument("--ct", type=float, default=1.0, help="SAH traversal cost (new only)")
    ap.add_argument("--ci", type=float, default=1.0, help="SAH intersection cost (new only)")
    ap.add_argument("--reps", type=int, default=3, help="timed repetitions (best counts)")
    args = ap.parse_args()
    global REPS
    REPS = args.reps

    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    variants = args.variants.split(";" if ";" in args.variants else ",")
    rows = []
    for sname in args.scenes.split(","):
        if sname == "cornell":
            scene = load_scene(os.path.join(ROOT, "scenes/cornellbox/cornellbox.txt"))
        else:
            scene = sphere_scene(args.nt)
        F = len(scene.triangles)
        mscene, t_mi = load_mitsuba(mi, scene)
        accs = {}
        cache = {}
        for v in variants:
            key = v.split("@")[0]
            if key in cache:  # same build, other switches: share the build
                import copy

                acc, tb = copy.copy(cache[key][0]), cache[key][1]
                for kv in v.split("@")[1:]:
                    k, val = kv.split("=")
                    setattr(acc, k, type(getattr(acc, k))(eval(val)))
            else:
                acc, tb = build_variant(v, scene, args)
                cache[key] = (acc, tb)
            accs[v] = acc
            rows.append((sname, F, "build [s]", v, tb, t_mi, tb / t_mi))
            print(f"{sname} F={F} {v}: build {tb:.3f} s, mitsuba load {t_mi:.3f} s, "
                  f"stats {acc.stats}", flush=True)
        for qi, q in enumerate(args.queries.split(",")):
            rays = make_rays(scene, q, args.res, args.rays, seed=qi + 1)
            query = "occluded" if q == "shadow" else "intersect"
            runners = {"mitsuba": mitsuba_runner(mi, mscene, rays, query)}
            for v in variants:
                runners[v] = drpt_runner(accs[v], rays, query)
            res = time_interleaved(runners, len(rays[0]))
            r_mi = res["mitsuba"]
            for v in variants:
                r_d = res[v]
                rows.append((sname, F, f"{q} [Mrays/s]", v, r_d, r_mi, r_d / r_mi))
                print(f"{sname} {q:10s} {v}: drpt {r_d:7.2f}  mitsuba {r_mi:7.2f}  "
                      f"ratio {r_d / r_mi:.3f}", flush=True)
        del mscene

    print()
    print(f"{'scene':8s} {'tris':>7s} {'metric':20s} {'variant':7s} {'drpt':>9s} "
          f"{'mitsuba':>9s} {'ratio':>7s}")
    for s, F, m, v, a, b, r in rows:
        print(f"{s:8s} {F:7d} {m:20s} {v:7s} {a:9.3f} {b:9.3f} {r:7.3f}")
    if len(variants) > 1 and "base" in variants:
        print("\nvariant / base (same run; Mrays/s: >1 faster; build seconds: <1 faster):")
        base = {(s, m): a for s, F, m, v, a, b, r in rows if v == "base"}
        for s, F, m, v, a, b, r in rows:
            if v != "base":
                print(f"  {s:8s} {m:20s} {v:7s} {a / base[(s, m)]:6.2f}x")


if __name__ == "__main__":
    main()
