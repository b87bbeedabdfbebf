"""Scenes and rays for the accelerator tests (``tests/accel/``): random triangle soups, an
icosphere, mixed scenes of triangles, spheres and a plane, and the brute-force closest hits
every accelerator is compared against."""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Float

from drpt.accel import build_accel
from drpt.scene import model as M

INF = float("inf")


def make_scene(tris=None, spheres=None, planes=None):
    kw = {}
    if tris is not None:
        kw["triangles"] = M.Triangles(np.asarray(tris, np.float64), np.zeros(len(tris), np.int32))
    if spheres is not None:
        c, r = spheres
        kw["spheres"] = M.Spheres(np.asarray(c, np.float64), np.asarray(r, np.float64),
                                  np.zeros(len(r), np.int32))
    if planes is not None:
        n, off = planes
        kw["planes"] = M.Planes(np.asarray(n, np.float64), np.asarray(off, np.float64),
                                np.zeros(len(off), np.int32))
    cam = M.PerspectiveCamera((0, 0, 0), (0, 0, 1), (0, 1, 0), 40.0)
    return M.Scene(path=None, camera=cam, materials=[M.Material("m")], **kw)


def soup(rng, F, scale=1.0, size=0.5):
    p = rng.random((F, 3, 3)) * 10
    p[:, 1:] = p[:, :1] + rng.normal(size=(F, 2, 3)) * size
    return p * scale


def icosphere(level=2):
    t = (1 + 5**0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(level):
        verts = list(map(tuple, v))
        index = {}

        def mid(a, b, verts=verts, index=index):
            key = (min(a, b), max(a, b))
            if key not in index:
                m = (np.asarray(verts[a]) + verts[b]) / 2
                verts.append(tuple(m / np.linalg.norm(m)))
                index[key] = len(verts) - 1
            return index[key]

        nf = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        v, f = np.asarray(verts), np.asarray(nf)
    return v, f


def rays(o, d):
    o = np.asarray(o, np.float32)
    d = np.asarray(d, np.float32)
    return Array3f(*o.T), Array3f(*d.T)


def hits(accel, o, d, tmax=INF):
    """``accel``'s closest hits and occlusion for the rays ``(o, d)`` (numpy) up to ``tmax``
    (a scalar or per ray), as numpy arrays ``(t, prim, u, v, valid, occluded)``."""
    O, D = rays(o, d)
    T = Float(np.broadcast_to(np.float32(tmax), (len(o),)).copy())
    h = accel.intersect(O, D, T)
    occ = accel.occluded(O, D, T)
    dr.eval(h, occ)
    return [x.numpy() for x in (h.t, h.prim, h.u, h.v, h.valid, occ)]


def mixed_scene_and_rays(seed=8, n_tris=600, n_sph=20, n_rays=3000):
    """A soup of triangles, spheres and the plane z = -0.5, and random rays
    ``(o, d)`` through it (numpy), all from one generator of ``seed``."""
    rng = np.random.default_rng(seed)
    tris = soup(rng, n_tris)
    c = rng.random((n_sph, 3)) * 10
    sc = make_scene(tris, spheres=(c, rng.random(n_sph) * 0.4 + 0.05),
                    planes=([[0.0, 0.0, 1.0]], [-0.5]))
    o = rng.random((n_rays, 3)) * 12 - 1
    d = rng.normal(size=(n_rays, 3))
    return sc, o, d, rng


def brute_hits(scene, o, d, tmax=INF):
    """Brute-force closest hits (evaluated), to share between several BVHs."""
    O, D = rays(o, d)
    T = Float(np.broadcast_to(np.float32(tmax), (len(o),)).copy())
    g = build_accel(scene, "brute").intersect(O, D, T)
    dr.eval(g)
    return g


def closed_mesh_rays(level: int, seed: int):
    """A closed icosphere (radius 3, faces sharing vertices bitwise) and rays
    from four points inside it through its vertices, edge midpoints and random
    edge points, reaching them at ``t = 1``: ``(triangles, o, d)``."""
    v, f = icosphere(level)
    rng = np.random.default_rng(seed)
    v = v * 3 + np.float64([0.1, -0.2, 0.3])
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    w = rng.random((len(e), 1))
    targets = np.concatenate([v, (v[e[:, 0]] + v[e[:, 1]]) / 2, v[e[:, 0]] * w + v[e[:, 1]] * (1 - w)])
    centers = np.float64([0.1, -0.2, 0.3]) + rng.normal(size=(4, 3)) * 0.3
    o = np.repeat(centers, len(targets), axis=0)
    return v[f], o, np.tile(targets, (4, 1)) - o
