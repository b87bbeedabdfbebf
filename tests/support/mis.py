"""Scenes and vertices for the MIS tests at an emitter hit (``tests/render/integrators/
test_path_mis.py``, ``test_volpath_mis.py``, ``test_bdpt_mis.py``): points on a floor at height
``z`` beside a small light above it, a next-event sample of the light from each, and the hit
of the sampled direction's ray from the spawned origin; a floor and light that are exactly one
scene translated between ``z = 0`` and :data:`FAR`, its image means per seed
(:func:`floor_means`) and a camera connection traced from the spawned origin
(:func:`spawned_segment`), for the far-light-path test and benchmark."""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float

from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators.common import SHADOW_SHRINK
from drpt.render.renderer import Renderer
from drpt.render.spawn import origin
from drpt.scene.model import Material, PerspectiveCamera, Scene, Triangles

FAR = 4096.0  # a power of two: the scene's coordinates (multiples of 1/64) stay exact there


def floor_scene(z: float) -> Scene:
    """A floor at height ``z`` lit by a small triangle 1/64 above it (facing down), seen from
    1 above through an 8-degree lens: every coordinate a multiple of 1/64, exact in float32 at
    ``z = 0`` and at :data:`FAR` alike, so the two are one scene translated."""
    h = 1 / 64
    floor = [[(-1, -1, z), (1, -1, z), (1, 1, z)], [(-1, -1, z), (1, 1, z), (-1, 1, z)]]
    tri = [[(0, 0, z + h), (0, 2 * h, z + h), (2 * h, 0, z + h)]]
    tris = Triangles(np.array(floor + tri, float), np.array([0, 0, 1], np.int32))
    mats = [Material("floor"), Material("light", emission=(1, 1, 1))]
    cam = PerspectiveCamera((h, h, z + 1), (0, 0, -1), (0, 1, 0), 8)
    return Scene(path=None, camera=cam, materials=mats, triangles=tris)


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


def floor_means(z: float, integrator: str, seeds: int) -> np.ndarray:
    """The mean of :func:`floor_scene` at height ``z`` rendered by ``integrator`` with seeds
    ``0..seeds-1`` (32x32, 16 spp, ``max_depth`` 2, independent sampler), one per seed."""
    out = []
    for seed in range(seeds):
        opts = RenderOptions(width=32, height=32, spp=16, seed=seed, progress=False, integrator=integrator,
                             sampler="independent", path=PathOptions(max_depth=2))
        out.append(float(Renderer(floor_scene(z), opts).render().image.mean()))
    return np.array(out)


def spawned_segment(center, p, ng, err, wc, dist):
    """A camera connection's shadow ray from ``p`` moved off its surface to the camera's
    center (``camera_segment``'s signature): the negative control of camera connections
    traced from the camera."""
    o = origin(p, ng, err, wc)
    to = center - o
    n = dr.norm(to)
    return o, to / n, n * SHADOW_SHRINK
