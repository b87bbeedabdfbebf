"""Ray/parallelogram intersection, for two triangles that form one.

A rectangle of a Mitsuba scene (``shape type="rectangle"``), a quad of an OBJ file,
is two triangles ``A`` and ``B`` sharing a diagonal. Where the four points form a
parallelogram ``P(a, b) = c + a e1 + b e2`` (``0 <= a, b <= 1``), one test answers for
both: the ray meets the plane at ``t = dot(n, c - o) / dot(n, d)`` (``n = e1 x e2``), and
the hit's parameters are ``a = dot(q, g1)``, ``b = dot(q, g2)`` for ``q = o + t d - c``,
with ``g1, g2`` the dual vectors of ``e1, e2`` in the plane (``dot(e_i, g_j) = [i == j]``,
``dot(n, g_j) = 0``). The diagonal ``a + b = 1`` splits it into the two triangles; the
test returns the triangle the point lies in (``A`` on the diagonal) and that triangle's
barycentrics, affine in ``(a, b)``: the hit record a triangle test gives, within float
rounding. This is Mitsuba's own rectangle test (a plane and a range check), a fraction of the
work of two watertight triangle tests (:func:`drpt.geometry.triangle.watertight_permuted`;
the operation counts are in docs/performance.md).

It is not watertight across the parallelogram's outer edges: a neighbour sharing one
would have to be tested the same way, bit for bit. Nor does it order ties as the watertight
tests do where another surface lies in its plane (a box standing on a floor: whether a ray
meets the floor or the box's bottom first is then float rounding). :func:`parallelogram_pairs`
therefore pairs only triangles that share none of those edges with any other triangle and
whose plane no other triangle's vertex touches, lying in no infinite plane primitive either
(separate rectangles, as Mitsuba's scenes and
Veach's MIS scene have), and only consecutive triangles (how a rectangle or a quad face is
triangulated).

Host side (numpy, float64 from the float32 vertices, constants rounded to float32 at
the end): :func:`parallelogram_pairs` finds the pairs and their constants
(:class:`Parallelogram`). Device side: :func:`intersect_parallelogram`, pure and
branch-free; misses give ``t = inf``, never NaN.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float

_INF = float("inf")
#: how far (relative to the pair's longest edge) the fourth point may lie from ``c + e1 + e2``,
#: besides :data:`ROUNDING_TOLERANCE`: a parallelogram, not a trapezoid
PARALLEL_TOLERANCE = 1e-6
#: how far (relative to the largest coordinate of the pair) the fourth point may lie from
#: ``c + e1 + e2`` besides :data:`PARALLEL_TOLERANCE`: float32 rounding of the four corners
#: (half a float32 ulp each), as a transformed rectangle's corners have
ROUNDING_TOLERANCE = 4 * 2.0**-24
#: how near (relative to the coordinates' size) another triangle's vertex may come to a pair's
#: plane before the pair is left as two triangles (:func:`parallelogram_pairs`)
PLANE_TOLERANCE = 1e-5


@dataclass(frozen=True)
class Parallelogram:
    """The constants of one pair of triangles ``first`` and ``first + 1``, computed in float64
    and rounded to float32 (Python floats holding float32 values: the kernel's literals).

    ``corner``: ``c``; ``n``: ``e1 x e2``; ``g1, g2``: the dual vectors; ``bary_a``,
    ``bary_b``: ``(2, 3)`` matrices taking ``(a, b, 1)`` to triangle ``A``'s and ``B``'s
    barycentrics ``(u, v)`` (``p = p0 + u (p1 - p0) + v (p2 - p0)`` in each one's vertex
    order)."""

    first: int
    corner: tuple
    n: tuple
    g1: tuple
    g2: tuple
    bary_a: tuple
    bary_b: tuple


def _bary_map(tri: np.ndarray, corner, g1, g2) -> np.ndarray:
    """``(2, 3)``: ``(u, v) = M @ (a, b, 1)`` for triangle ``tri``'s barycentrics."""
    ab = np.array([[np.dot(p - corner, g1), np.dot(p - corner, g2)] for p in tri])
    m = np.column_stack([ab[1] - ab[0], ab[2] - ab[0]])  # (a, b) = ab[0] + m (u, v)
    inv = np.linalg.inv(m)
    return np.column_stack([inv, -inv @ ab[0]])


def _pair(a: np.ndarray, b: np.ndarray, first: int) -> Parallelogram | None:
    """The parallelogram of triangles ``a`` and ``b`` (``(3, 3)`` float64 vertices), or
    None where they do not form one."""
    shared = [i for i in range(3) if any((a[i] == q).all() for q in b)]
    if len(shared) != 2:
        return None
    ca = a[3 - sum(shared)]  # a's vertex off the diagonal
    cb = next(q for q in b if not any((q == a[i]).all() for i in shared))
    s1, s2 = a[shared[0]], a[shared[1]]
    e1, e2 = s1 - ca, s2 - ca
    n = np.cross(e1, e2)
    n2 = float(n @ n)
    extent = float(np.abs(np.stack([a, b])).max())
    if n2 <= 0.0 or not np.all(np.isfinite(n)):
        return None
    off = np.abs(ca + e1 + e2 - cb).max()
    if off > PARALLEL_TOLERANCE * _edge_scale(e1, e2, extent) + ROUNDING_TOLERANCE * extent:
        return None
    g1, g2 = np.cross(e2, n) / n2, np.cross(n, e1) / n2
    return Parallelogram(first, _f32(ca), _f32(n), _f32(g1), _f32(g2),
                         tuple(map(_f32, _bary_map(a, ca, g1, g2))),
                         tuple(map(_f32, _bary_map(b, ca, g1, g2))))


def _edge_scale(e1: np.ndarray, e2: np.ndarray, extent: float) -> float:
    """The length :data:`PARALLEL_TOLERANCE` is relative to: the pair's longer edge (not
    ``extent``, its largest coordinate: far from the origin that would admit trapezoids)."""
    return max(float(np.linalg.norm(e1)), float(np.linalg.norm(e2)))


def _f32(v) -> tuple:
    """``v`` rounded to float32, as a tuple of Python floats."""
    return tuple(np.asarray(v, np.float32).astype(np.float64).tolist())


def parallelogram_pairs(positions: np.ndarray, others: np.ndarray | None = None,
                        planes: tuple | None = None) -> list[Parallelogram]:
    """The pairs of consecutive triangles (``(F, 3, 3)`` positions, rounded to float32 as
    the accelerators hold them) that form a parallelogram, share none of its four outer
    edges with another triangle and whose plane no other surface touches, in order; a
    triangle is in one pair at most.

    The other surfaces are the other triangles of ``positions``, the triangles ``others``
    (``(M, 3, 3)``: a scene's triangles that are not in the list, where the list is part of
    a scene, as the emissive list is) and the infinite ``planes`` (``(normals (P, 3),
    offsets (P,))``, ``dot(n, x) == offset``), which the accelerators test before any
    triangle."""
    p = np.asarray(positions, np.float32).astype(np.float64).reshape(-1, 3, 3)
    extra = (np.zeros((0, 3)) if others is None
             else np.asarray(others, np.float32).astype(np.float64).reshape(-1, 3))
    keys = [tuple(map(tuple, t)) for t in p]
    edges: dict = {}
    for t in keys:
        for i in range(3):
            e = frozenset((t[i], t[(i + 1) % 3]))
            edges[e] = edges.get(e, 0) + 1
    out = []
    i = 0
    while i + 1 < len(p):
        q = _pair(p[i], p[i + 1], i)
        if q is not None and not _touched(p, i, q, extra) and not _on_plane(p[i:i + 2], planes):
            outer = [frozenset((t[j], t[(j + 1) % 3])) for t in keys[i:i + 2] for j in range(3)]
            diagonal = [e for e in outer if outer.count(e) == 2]
            if all(edges[e] == 1 for e in outer if e not in diagonal) and all(edges[e] == 2 for e in diagonal):
                out.append(q)
                i += 2
                continue
        i += 1
    return out


def _touched(p: np.ndarray, i: int, q: Parallelogram, extra: np.ndarray) -> bool:
    """Whether a vertex of a triangle other than ``i`` and ``i + 1`` (or one of the points
    ``extra``) lies in the pair's plane (within :data:`PLANE_TOLERANCE` of the coordinates'
    size): a box standing on a floor, a face lying on it. Where two surfaces meet or overlap
    in a plane, which one a ray hits first is decided by float rounding, and the watertight
    tests decide it alike for both (the order of the tests at equal distances); the pair
    stays two triangles there."""
    n = np.asarray(q.n) / np.linalg.norm(q.n)
    corner, pair = np.asarray(q.corner), np.abs(p[i:i + 2]).max()
    # (the list's other vertices, then ``extra``: not joined, which would copy a whole
    # scene's vertices for every candidate pair of the emissive list)
    for pts in (np.delete(p, [i, i + 1], axis=0).reshape(-1, 3), extra):
        if len(pts):
            dist = np.abs((pts - corner) @ n)
            if (dist <= PLANE_TOLERANCE * np.maximum(np.abs(pts).max(axis=1), pair)).any():
                return True
    return False


def _on_plane(pair: np.ndarray, planes: tuple | None) -> bool:
    """Whether a corner of the pair (``(2, 3, 3)``) lies in one of the infinite ``planes``
    (within :data:`PLANE_TOLERANCE` of the coordinates' size): a rectangle lying on a plane
    floor, or standing on it. Ties between the two are float rounding, as in :func:`_touched`."""
    if planes is None or not len(planes[1]):
        return False
    normals = np.asarray(planes[0], np.float32).astype(np.float64).reshape(-1, 3)
    offsets = np.asarray(planes[1], np.float32).astype(np.float64).reshape(-1)
    length = np.linalg.norm(normals, axis=1)
    ok = length > 0
    pts = pair.reshape(-1, 3)
    dist = np.abs(pts @ normals[ok].T - offsets[ok]) / length[ok]  # (6, P)
    size = np.maximum(np.abs(pts).max(axis=1, keepdims=True), np.abs(offsets[ok]) / length[ok])
    return bool((dist <= PLANE_TOLERANCE * size).any())


def intersect_parallelogram(o: Array3f, d: Array3f, q: Parallelogram, tmax: Float
                            ) -> tuple[Float, Float, Float, Bool, Bool]:
    """The ray ``(o, d)`` against the parallelogram ``q`` (its constants as float32
    literals): ``(t, u, v, hit, in_b)``, ``0 < t < tmax``, ``u, v`` the barycentrics of
    the triangle hit (``first``, or ``first + 1`` where ``in_b``); ``t = inf`` and
    ``u = v = 0`` where ``hit`` is false. Two-sided; a ray in the plane misses."""
    c, n, g1, g2 = (Array3f(*v) for v in (q.corner, q.n, q.g1, q.g2))
    w = o - c
    den = dr.dot(n, d)
    ok = den != 0
    t = -dr.dot(n, w) / dr.select(ok, den, 1.0)
    a = dr.fma(t, dr.dot(d, g1), dr.dot(w, g1))
    b = dr.fma(t, dr.dot(d, g2), dr.dot(w, g2))
    hit = ok & (a >= 0) & (b >= 0) & (a <= 1) & (b <= 1) & (t > 0) & (t < tmax)
    in_b = a + b > 1

    def bary(m):
        return tuple(dr.fma(Float(r[0]), a, dr.fma(Float(r[1]), b, Float(r[2]))) for r in m)

    (ua, va), (ub, vb) = bary(q.bary_a), bary(q.bary_b)
    u = dr.select(in_b, ub, ua)
    v = dr.select(in_b, vb, va)
    return dr.select(hit, t, _INF), dr.select(hit, u, 0.0), dr.select(hit, v, 0.0), hit, in_b
