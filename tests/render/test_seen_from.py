"""Hits of spawned rays as seen from their vertex (:meth:`drpt.render.surface.SurfaceData.seen_from`,
:meth:`drpt.render.scene.DeviceScene.intersect_from`).

Rays leave points ``p`` from origins ``o = p - delta`` moved off by ``|delta| = 1e-4`` (as
:func:`drpt.render.spawn.origin` moves them, in any direction here) toward a floor of two
triangles, a sphere and a plane (a wall). The hit of the ray from ``o``, taken as the parallel
ray from ``p`` meets its primitive, is that ray's exact (float64) intersection with the
primitive within ``1e-6 / cos`` (the float32 rounding of points of size 1, over the cosine at
the hit, against a move of 1e-4), and ``si.t`` its distance from ``p``, on the floor's two
triangles also where the moved point crosses their shared edge (it stays on the plane, which
the neighbour shares) and, on the sphere, wherever the cosine exceeds 0.2 (the move is then
small against the radius; a grazing hit keeps its own).
Negative control: the hit of the ray from ``o`` itself is off by more than 1e-5 on most lanes
(and with ``seen_from`` a no-op the test fails). Where ``o`` is ``p`` (delta lights, the
camera) the interaction is :meth:`~drpt.render.scene.DeviceScene.intersect`'s, bit for bit.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Bool, Float

from drpt.options import RenderOptions
from drpt.render import surface
from drpt.render.scene import DeviceScene
from drpt.scene.model import Material, PerspectiveCamera, Planes, Scene, Spheres, Triangles
from support.mis import FAR

N = 4096
MOVE = 1e-4
FLOOR = [[(-1, -1, 0), (1, -1, 0), (1, 1, 0)], [(-1, -1, 0), (1, 1, 0), (-1, 1, 0)]]
SPHERE = ((0.3, -0.2, 0.25), 0.25)
WALL = ((-1.0, 0.0, 0.0), 0.7)  # x = -0.7 (the plane dot(n, x) = offset)


def _scene() -> DeviceScene:
    tris = Triangles(np.array(FLOOR, float), np.array([0, 0], np.int32))
    sph = Spheres(np.array([SPHERE[0]], float), np.array([SPHERE[1]], float), np.array([0], np.int32))
    pl = Planes(np.array([WALL[0]], float), np.array([WALL[1]], float), np.array([0], np.int32))
    cam = PerspectiveCamera((0, 0, 3), (0, 0, 0), (0, 1, 0), 40)
    model = Scene(path=None, camera=cam, materials=[Material("m")], triangles=tris, spheres=sph, planes=pl)
    return DeviceScene(model, RenderOptions(width=4, height=4, spp=1))


def _rays(seed: int = 1):
    rng = np.random.default_rng(seed)
    p = np.column_stack([rng.uniform(-0.5, 0.5, N), rng.uniform(-0.5, 0.5, N), np.full(N, 0.9)])
    d = rng.normal(size=(N, 3))
    d[:, 2] = -np.abs(d[:, 2]) - 0.3
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    delta = rng.normal(size=(N, 3))
    delta *= MOVE / np.linalg.norm(delta, axis=1, keepdims=True)
    p, d = p.astype(np.float32), d.astype(np.float32)
    o = (p - delta).astype(np.float32)
    return p, o, d


def _a3(a: np.ndarray) -> Array3f:
    return Array3f(*(Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)))


def _exact(prim: np.ndarray, p: np.ndarray, d: np.ndarray):
    """The float64 intersection of the rays ``(p, d)`` with primitive ``prim`` (0, 1: the floor's
    triangles, on their plane, 2: the sphere, 3: the wall): ``(x, t)``."""
    p, d = p.astype(np.float64), d.astype(np.float64)
    t = np.full(len(p), np.nan)
    tri = prim < 2
    t[tri] = -p[tri, 2] / d[tri, 2]
    c, r = np.array(SPHERE[0]), SPHERE[1]
    s = prim == 2
    oc = p[s] - c
    b = np.sum(oc * d[s], axis=1)
    t[s] = -b - np.sqrt(b * b - (np.sum(oc * oc, axis=1) - r * r))
    w = prim == 3
    n = np.array(WALL[0])
    t[w] = (WALL[1] - p[w] @ n) / (d[w] @ n)
    return p + d * t[:, None], t


def _normals(prim: np.ndarray, x: np.ndarray) -> np.ndarray:
    n = np.zeros_like(x)
    n[prim < 2] = (0, 0, 1)
    n[prim == 2] = (x[prim == 2] - SPHERE[0]) / SPHERE[1]
    n[prim == 3] = WALL[0]
    return n


def test_the_hit_is_where_the_ray_from_the_vertex_meets_the_primitive():
    scene = _scene()
    p, o, d = _rays()
    si = scene.intersect_from(_a3(o), _a3(p), _a3(d), Bool(True))
    valid = np.array(si.valid)
    prim = np.array(si.prim)
    kinds = [np.sum(valid & (prim == k)) for k in range(4)]
    assert min(kinds) > 200, kinds  # every kind of primitive is hit often
    x, t = _exact(np.where(valid, prim, 0), p, d)
    cos = np.abs(np.sum(_normals(prim, x) * d, axis=1))
    got = np.array(si.p, np.float64).T
    # (a sphere lane moves along the tangent plane where the move, about 1e-4 / cos, is small)
    ok = valid & ((prim != 2) | (cos > 0.2))
    assert ok.sum() > 0.95 * valid.sum()
    # float32 rounding across the surface moves a hit by about that over the cosine
    tol = 1e-6 / cos[ok]
    err = np.linalg.norm(got - x, axis=1)[ok]
    assert np.all(err < tol), np.max(err / tol)
    assert np.all(np.abs(np.array(si.t, np.float64)[ok] - t[ok]) < tol)
    # control: the hit of the ray from o, as the scene's intersect gives it
    plain = scene.intersect(_a3(o), _a3(d), Bool(True))
    assert np.array_equal(np.array(plain.prim)[valid], prim[valid])
    off = np.linalg.norm(np.array(plain.p, np.float64).T - x, axis=1)[ok]
    assert np.mean(off > 1e-5) > 0.8, np.mean(off > 1e-5)


def test_a_ray_from_the_vertex_itself_is_intersect():
    scene = _scene()
    p, _, d = _rays(2)
    a = scene.intersect_from(_a3(p), _a3(p), _a3(d), Bool(True))
    b = scene.intersect(_a3(p), _a3(d), Bool(True))
    for name in ("valid", "t", "p", "ng", "prim"):
        assert np.array_equal(np.array(getattr(a, name)), np.array(getattr(b, name))), name
    assert dr.all(a.valid == b.valid)


CORNER_FLOOR = [[(-1, -1, 0), (1, -1, 0), (1, 1, 0)], [(-1, -1, 0), (1, 1, 0), (-1, 1, 0)]]
CORNER_WALL = [[(-0.7, -1, 0), (-0.7, 1, 0), (-0.7, 1, 1)], [(-0.7, -1, 0), (-0.7, 1, 1), (-0.7, -1, 1)]]


def _corner_min_barycentric(reach: float) -> np.ndarray:
    """Rays spawned (``MOVE`` 1e-3, the offset at ``z = FAR``) near a box corner at ``FAR``: a
    wall of two triangles at ``x = -0.7`` standing on a floor of two, rays grazing the wall
    toward its foot. Per valid hit of ``intersect_from`` (``TRIANGLE_REACH = reach``): the
    smallest float64 barycentric of its point on its own triangle."""
    tri = np.array(CORNER_FLOOR + CORNER_WALL, float) + (0.0, 0.0, FAR)
    model = Scene(path=None, camera=PerspectiveCamera((0, 0, FAR + 3), (0, 0, FAR), (0, 1, 0), 40),
                  materials=[Material("m")], triangles=Triangles(tri, np.zeros(4, np.int32)))
    rng = np.random.default_rng(7)
    p = np.column_stack([rng.uniform(-0.699, -0.69, N), rng.uniform(-0.5, 0.5, N),
                         FAR + rng.uniform(0.05, 0.5, N)])
    d = np.column_stack([-rng.uniform(0.005, 0.05, N), rng.uniform(-0.3, 0.3, N), -np.ones(N)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    delta = rng.normal(size=(N, 3))
    delta *= 1e-3 / np.linalg.norm(delta, axis=1, keepdims=True)
    p, d = p.astype(np.float32), d.astype(np.float32)
    o = (p - delta).astype(np.float32)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(surface, "TRIANGLE_REACH", reach)
        si = DeviceScene(model, RenderOptions(width=4, height=4, spp=1)).intersect_from(
            _a3(o), _a3(p), _a3(d), Bool(True))
        valid, prim = np.array(si.valid), np.array(si.prim)
        x = np.array(si.p, np.float64).T[valid]
    t = tri[prim[valid]]
    e1, e2, r = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0], x - t[:, 0]
    # barycentrics of the point's projection on its triangle's plane (least squares)
    g = np.stack([np.stack([np.sum(e1 * e1, 1), np.sum(e1 * e2, 1)], 1),
                  np.stack([np.sum(e1 * e2, 1), np.sum(e2 * e2, 1)], 1)], 1)
    uv = np.linalg.solve(g, np.stack([np.sum(r * e1, 1), np.sum(r * e2, 1)], 1)[..., None])[..., 0]
    assert np.sum(prim[valid] >= 2) > N // 4  # the wall is hit often
    return np.minimum(np.minimum(uv[:, 0], uv[:, 1]), 1.0 - uv[:, 0] - uv[:, 1])


def test_a_hit_moved_toward_a_non_coplanar_neighbour_stays_within_the_reach():
    """Far from the origin (``FAR``, where the spawn offset is 1e-3) a ray grazing a box's wall
    toward its foot is moved along the wall's plane by the offset over the cosine: the moved
    point stays within :data:`~drpt.render.surface.TRIANGLE_REACH` (in barycentrics, plus
    float32 rounding at 4096: 1e-3) of its triangle, not below the floor. Negative control: a
    reach of 1.0 lets some hit move more than 0.1 past the wall's foot."""
    assert _corner_min_barycentric(surface.TRIANGLE_REACH).min() >= -surface.TRIANGLE_REACH - 1e-3
    assert _corner_min_barycentric(1.0).min() < -0.1
