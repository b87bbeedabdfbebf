"""Ray/triangle intersection on Dr.Jit arrays.

Two tests are provided; both are pure, branch-free Dr.Jit code on wide arrays
and never produce NaN outputs (degenerate triangles and parallel rays report a
miss with ``t = inf``, ``u = v = 0``). A hit requires ``0 < t < tmax``
(strictly: a ray starting exactly on the triangle's plane does not report
``t == 0``).

:func:`intersect_triangle_watertight` (used by the accelerators)
    The watertight test of Woop, Benthin and Wald, "Watertight Ray/Triangle
    Intersection", JCGT 2(1), 2013. The ray is mapped to the +z axis by a
    per-ray axis permutation and shear (:class:`RayPrep`), each *vertex* is
    transformed independently, and the 2D edge functions
    ``U = Cx*By - Cy*Bx`` (etc.) are evaluated in float32. Because rounding is
    monotone and Dr.Jit's LLVM backend emits no FMA contraction for ``a*b -
    c*d``, each edge function's sign is exact or zero, and two triangles
    sharing an edge compute exactly negated values from bitwise identical
    vertices. Zero counts as inside, so rays through shared edges and vertices
    of a closed mesh always hit at least one triangle. This requires the
    *vertices* (not edge vectors) to be stored, bitwise identical between
    neighbours.

:func:`intersect_triangle`
    The Möller–Trumbore test with precomputed edges ``e1 = p1 - p0``,
    ``e2 = p2 - p0``. Cheaper, but not watertight across shared edges (the
    neighbours' edges are rounded differently).

Barycentrics: the hit point is ``p0 + u * (p1 - p0) + v * (p2 - p0)``.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array3f, Bool, Float, UInt32

_INF = float("inf")


def intersect_triangle(o: Array3f, d: Array3f, p0: Array3f, e1: Array3f, e2: Array3f,
                       tmax: Float) -> tuple[Float, Float, Float, Bool]:
    """Möller–Trumbore ray/triangle test (two-sided).

    Args:
        o, d: ray origin and direction (``d`` need not be normalized; ``t`` is
            in units of ``d``).
        p0, e1, e2: first vertex and edges ``p1 - p0``, ``p2 - p0``.
        tmax: hits must satisfy ``0 < t < tmax``.

    Returns:
        ``(t, u, v, hit)``; ``t = inf`` and ``u = v = 0`` where ``hit`` is false.
    """
    pvec = dr.cross(d, e2)
    det = dr.dot(e1, pvec)
    ok = det != 0
    inv_det = dr.select(ok, dr.rcp(dr.select(ok, det, 1.0)), 0.0)
    s = o - p0
    u = dr.dot(s, pvec) * inv_det
    q = dr.cross(s, e1)
    v = dr.dot(d, q) * inv_det
    t = dr.dot(e2, q) * inv_det
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < tmax)
    return (dr.select(hit, t, _INF), dr.select(hit, u, 0.0), dr.select(hit, v, 0.0), hit)


class RayPrep:
    """Per-ray constants of the watertight test.

    ``kx, ky, kz`` (UInt32): axis permutation with ``kz`` the dominant axis of
    ``d``; ``sx, sy, sz``: the shear ``d[kx]/d[kz], d[ky]/d[kz], 1/d[kz]``;
    ``ox, oy, oz``: the origin's permuted components.
    """

    def __init__(self, o: Array3f, d: Array3f):
        ax, ay, az = dr.abs(d.x), dr.abs(d.y), dr.abs(d.z)
        kz = dr.select((ax >= ay) & (ax >= az), UInt32(0), dr.select(ay >= az, UInt32(1), UInt32(2)))
        kx = dr.select(kz == 2, UInt32(0), kz + 1)
        ky = dr.select(kx == 2, UInt32(0), kx + 1)
        self.kx, self.ky, self.kz = kx, ky, kz
        dz = _pick(d, kz)
        rz = dr.rcp(dz)
        self.sx = _pick(d, kx) * rz
        self.sy = _pick(d, ky) * rz
        self.sz = rz
        self.ox, self.oy, self.oz = _pick(o, kx), _pick(o, ky), _pick(o, kz)


def _pick(v: Array3f, k: UInt32) -> Float:
    return dr.select(k == 0, v.x, dr.select(k == 1, v.y, v.z))


def watertight_permuted(r: RayPrep, ax, ay, az, bx, by, bz, cx, cy, cz,
                        tmax: Float) -> tuple[Float, Float, Float, Bool]:
    """Core of the watertight test on vertices already permuted by ``r``.

    ``ax`` is ``p0[r.kx]``, ``ay = p0[r.ky]``, ``az = p0[r.kz]``, and so on for
    ``p1`` (``b*``) and ``p2`` (``c*``). Accelerators gather the permuted
    components directly from memory (one gather per component, no selects).
    Returns ``(t, u, v, hit)`` as :func:`intersect_triangle_watertight`.
    """
    az = az - r.oz
    bz = bz - r.oz
    cz = cz - r.oz
    Ax = (ax - r.ox) - r.sx * az
    Ay = (ay - r.oy) - r.sy * az
    Bx = (bx - r.ox) - r.sx * bz
    By = (by - r.oy) - r.sy * bz
    Cx = (cx - r.ox) - r.sx * cz
    Cy = (cy - r.oy) - r.sy * cz
    U = Cx * By - Cy * Bx
    V = Ax * Cy - Ay * Cx
    W = Bx * Ay - By * Ax
    outside = ((U < 0) | (V < 0) | (W < 0)) & ((U > 0) | (V > 0) | (W > 0))
    det = U + V + W
    T = (U * az + V * bz + W * cz) * r.sz
    ok = ~outside & (det != 0)
    inv = dr.rcp(dr.select(ok, det, 1.0))
    t = T * inv
    hit = ok & (t > 0) & (t < tmax)
    return (dr.select(hit, t, _INF), dr.select(hit, V * inv, 0.0),
            dr.select(hit, W * inv, 0.0), hit)


def intersect_triangle_watertight(o: Array3f, d: Array3f, p0: Array3f, p1: Array3f,
                                  p2: Array3f, tmax: Float,
                                  prep: RayPrep | None = None) -> tuple[Float, Float, Float, Bool]:
    """Watertight ray/triangle test (two-sided), Woop et al. 2013.

    Args:
        o, d: ray origin and direction (``t`` in units of ``d``).
        p0, p1, p2: the vertices.
        tmax: hits must satisfy ``0 < t < tmax``.
        prep: optional :class:`RayPrep` of ``(o, d)`` to share between tests.

    Returns:
        ``(t, u, v, hit)`` with ``p = p0 + u (p1 - p0) + v (p2 - p0)``;
        ``t = inf``, ``u = v = 0`` where ``hit`` is false.
    """
    r = prep if prep is not None else RayPrep(o, d)
    return watertight_permuted(
        r, _pick(p0, r.kx), _pick(p0, r.ky), _pick(p0, r.kz),
        _pick(p1, r.kx), _pick(p1, r.ky), _pick(p1, r.kz),
        _pick(p2, r.kx), _pick(p2, r.ky), _pick(p2, r.kz), tmax)
