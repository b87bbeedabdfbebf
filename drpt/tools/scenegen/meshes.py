"""Small mesh builders and an OBJ writer for the test-scene generators.

Every builder returns ``(V, F, N)``: vertex positions ``V`` (n, 3), faces
``F`` (a list of index tuples into ``V``, 3 or 4 corners, counter-clockwise
seen from outside, so the geometric normal ``cross(p1 - p0, p2 - p0)``
points out) and per-vertex shading normals ``N`` (n, 3) or ``None`` for flat
faces. :class:`ObjWriter` writes such meshes as one OBJ file, welded (each
vertex written once per mesh), normals as ``v//n`` corners.

Closed meshes (:func:`box`, :func:`uv_sphere`, :func:`wavy_slab`) are
watertight: shared corners have bit-identical coordinates, as a dielectric
(which tracks inside and outside) needs.
"""

from __future__ import annotations

import math

import numpy as np


def _yaw(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def box(center, size, yaw_deg: float = 0.0, bottom: bool = True):
    """An axis-aligned box of ``size`` (sx, sy, sz) rotated by ``yaw_deg`` about +y
    around ``center``: 8 corners, 6 (or 5 without ``bottom``) outward quads, flat."""
    c = np.asarray(center, float)
    h = 0.5 * np.asarray(size, float)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * h
    V = corners @ _yaw(yaw_deg).T + c
    # corner index = 4 * (x > 0) + 2 * (y > 0) + (z > 0)
    F = [(0, 1, 3, 2), (4, 6, 7, 5),  # -x, +x
         (2, 3, 7, 6), (0, 4, 5, 1),  # +y, -y
         (1, 5, 7, 3), (0, 2, 6, 4)]  # +z, -z
    if not bottom:
        F.remove((0, 4, 5, 1))
    return V, F, None


def uv_sphere(center, radius: float, n_phi: int = 32, n_theta: int = 16):
    """A latitude-longitude sphere with smooth (exact radial) normals: ``n_phi``
    segments around +y, ``n_theta`` rings from pole to pole; triangles at the poles,
    quads elsewhere."""
    c = np.asarray(center, float)
    dirs = [(0.0, 1.0, 0.0)]
    for i in range(1, n_theta):
        t = math.pi * i / n_theta
        for j in range(n_phi):
            p = 2.0 * math.pi * j / n_phi
            dirs.append((math.sin(t) * math.cos(p), math.cos(t), -math.sin(t) * math.sin(p)))
    dirs.append((0.0, -1.0, 0.0))
    N = np.array(dirs)
    V = c + radius * N
    south = len(dirs) - 1

    def ring(i, j):  # vertex j of ring i (1 .. n_theta - 1)
        return 1 + (i - 1) * n_phi + j % n_phi

    F = []
    for j in range(n_phi):
        F.append((0, ring(1, j), ring(1, j + 1)))
        F.append((south, ring(n_theta - 1, j + 1), ring(n_theta - 1, j)))
    for i in range(1, n_theta - 1):
        for j in range(n_phi):
            F.append((ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)))
    return V, F, N


def wavy_slab(x0: float, x1: float, z0: float, z1: float, y0: float, depth: float,
              amplitude: float, waves: float = 1.5, n: int = 12):
    """A closed slab: flat bottom at ``y0``, a wavy top around ``y0 + depth``
    (``amplitude * sin(2 pi waves u + 0.7) * cos(2 pi waves v)`` over the unit square
    ``u, v``), vertical sides following the top's edge. Returns two meshes: the top
    with smooth (exact) normals, and the bottom plus sides, flat."""
    ku, kv = 2.0 * math.pi * waves, 2.0 * math.pi * waves

    def height(u, v):
        return y0 + depth + amplitude * math.sin(ku * u + 0.7) * math.cos(kv * v)

    def normal(u, v):
        dh_du = amplitude * ku * math.cos(ku * u + 0.7) * math.cos(kv * v)
        dh_dv = -amplitude * kv * math.sin(ku * u + 0.7) * math.sin(kv * v)
        g = np.array([-dh_du / (x1 - x0), 1.0, -dh_dv / (z1 - z0)])
        return g / np.linalg.norm(g)

    us = [i / n for i in range(n + 1)]

    def point(u, v, top=True):
        return (x0 + (x1 - x0) * u, height(u, v) if top else y0, z0 + (z1 - z0) * v)

    Vt = np.array([point(u, v) for v in us for u in us])
    Nt = np.array([normal(u, v) for v in us for u in us])
    k = n + 1
    Ft = [(j * k + i, (j + 1) * k + i, (j + 1) * k + i + 1, j * k + i + 1)
          for j in range(n) for i in range(n)]

    # bottom and sides: the boundary walked clockwise seen from above (+x, then +z)
    edge = ([(u, 0.0) for u in us] + [(1.0, v) for v in us[1:]] + [(u, 1.0) for u in reversed(us[:-1])]
            + [(0.0, v) for v in reversed(us[1:-1])])
    m = len(edge)
    # bottom: a flat grid like the top's (no fan of slivers), facing -y
    Vs = np.array([point(u, v, top=True) for u, v in edge] + [point(u, v, top=False) for v in us for u in us])
    grid = {(u, v): m + j * k + i for j, v in enumerate(us) for i, u in enumerate(us)}
    Fs = [(i, (i + 1) % m, grid[edge[(i + 1) % m]], grid[edge[i]]) for i in range(m)]
    Fs += [tuple(m + c for c in reversed(q)) for q in Ft]
    return (Vt, Ft, Nt), (Vs, Fs, None)


def face_normal(V, f) -> np.ndarray:
    p = V[list(f)]
    n = np.zeros(3)
    for i in range(len(f)):  # Newell's method: fine for planar polygons of any size
        a, b = p[i], p[(i + 1) % len(f)]
        n += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]),
                       (a[0] - b[0]) * (a[1] + b[1])])
    return n


def check_outward(V, F, inside) -> None:
    """Assert that every face's normal points away from the point ``inside``."""
    inside = np.asarray(inside, float)
    for f in F:
        c = V[list(f)].mean(0)
        assert np.dot(face_normal(V, f), c - inside) > 0, f"face {f} faces inward"


class ObjWriter:
    """Accumulates meshes (``add``) and returns the OBJ text (``text``)."""

    def __init__(self, header: str, mtllib: str):
        self.lines = [f"# {line}" for line in header.splitlines()] + [f"mtllib {mtllib}"]
        self.nv = 0
        self.nn = 0
        self.faces = 0

    def add(self, name: str, material: str, mesh) -> None:
        V, F, N = mesh
        self.lines += [f"o {name}", f"usemtl {material}"]
        self.lines += ["v " + " ".join(f"{x:.6f}" for x in p) for p in V]
        if N is not None:
            self.lines += ["vn " + " ".join(f"{x:.6f}" for x in q) for q in N]
            self.lines.append("s 1")
            self.lines += ["f " + " ".join(f"{self.nv + i + 1}//{self.nn + i + 1}" for i in f) for f in F]
            self.nn += len(N)
        else:
            self.lines.append("s 0")
            self.lines += ["f " + " ".join(str(self.nv + i + 1) for i in f) for f in F]
        self.nv += len(V)
        self.faces += sum(len(f) - 2 for f in F)

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def folder_cli(main, description: str, argv=None) -> None:
    """The command line of a generator whose ``main(out)`` needs the output
    folder and returns the files it wrote: ``OUT_DIR``, then one line listing
    them and their total size."""
    import argparse
    from pathlib import Path

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("out", type=Path, help="folder to write the scene into")
    a = ap.parse_args(argv)
    files = main(a.out)
    print(f"{a.out}: {', '.join(f.name for f in files)} ({sum(f.stat().st_size for f in files) // 1024} kB)")

