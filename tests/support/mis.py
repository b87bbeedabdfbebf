"""Vertices for the MIS tests at an emitter hit (``tests/render/integrators/test_path_mis.py``,
``test_volpath_mis.py``): points on a floor at height ``z`` beside a small light above it, a
next-event sample of the light from each, and the hit of the sampled direction's ray from
the spawned origin."""

from __future__ import annotations

import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float


def floor_vertices(scene, n: int, z: float):
    """``(o, d, si, es, hit, ok)`` for ``n`` rays straight down from ``z + 0.5`` onto floor
    points 0.005-0.05 beside the light (material 0 the floor, 1 the light): ``si`` their
    hits, ``es`` a next-event sample of the light from each, ``hit`` what the ray from the
    spawned origin along ``es.wo`` reaches, ``ok`` the lanes where that is the light."""
    rng = np.random.default_rng(3)
    r = rng.uniform(0.005, 0.05, n)
    a = rng.uniform(0, 2 * np.pi, n)
    x, y = 0.01 + r * np.cos(a), 0.01 + r * np.sin(a)
    o = Array3f(Float(x.astype(np.float32)), Float(y.astype(np.float32)), Float(np.full(n, z + 0.5, np.float32)))
    d = Array3f(0.0, 0.0, -1.0)
    si = scene.intersect(o, d, Bool(True))
    on_floor = si.valid & (si.material == 0)
    u = Array2f(Float(rng.random(n).astype(np.float32)), Float(rng.random(n).astype(np.float32)))
    es = scene.sample_emitter(si, Float(rng.random(n).astype(np.float32)), u, on_floor)
    ok = on_floor & es.valid
    hit = scene.intersect(scene.spawn(si, es.wo), es.wo, ok)
    ok = ok & hit.valid & (hit.material == 1)
    return o, d, si, es, hit, ok
