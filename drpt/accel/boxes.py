"""Boxes around a scene's shapes: a ray that reaches none of them hits nothing, and its
accelerator query can be skipped.

Most camera rays of a small object in an empty world (Mitsuba's test scenes: a sphere over a
floor, a row of spheres) pass beside everything; the accelerator then still runs its query
(Embree: a packet call, its setup and the root's tests) to find nothing.
:class:`ShapeBoxes` holds an axis-aligned box per shape (the triangles of each shape, each
sphere), or one box around them all where there are more than :data:`MAX_BOXES` shapes, and
:meth:`ShapeBoxes.reach` tells which rays reach one (inline slab tests, a few dozen
operations per box and ray); :meth:`~drpt.render.scene.DeviceScene.intersect_preliminary`
queries the accelerator in a symbolic ``if`` on those lanes where asked to (camera rays).

A ray leaving a *convex* shape outward, or a *flat* one (every corner in one plane: a ground, a
floor, a light's rectangle) to either side, meets nothing of that shape, so its own box, which
holds the ray's origin, need not count (:meth:`ShapeBoxes.leaving`, then ``reach(o, d, skip)``): a
ray off a mirror sphere that escapes between the others, or off the ground beside the car that
stands on it, then skips the query too. drpt's own format gives its meshes no shapes (one
emitter per material): there the boxes are per group of materials (:func:`material_groups`:
materials merged where their common box costs no more surface area than their two boxes),
so that a car's parts are one box and the ground another. For those rays a
round shape's box is replaced by a sphere around it (its box's center, its farthest corner;
padded), where the sphere holds less volume than the box: it culls the rays that pass through
the box's corners beside the shape. A shape is
convex where every triangle's plane has all of the shape's vertices on one side, the same side
for all (:func:`outward_convex`, checked on the host when the boxes are made; a sphere always
is), and its primitive ids are one run of the global ids, so that the box a hit's primitive
belongs to is two comparisons per box.

The test is conservative: a ray that meets a primitive is never dropped. Each box is padded by
:data:`PAD` of its size (and of its coordinates' magnitude), so a flat shape's box has a
thickness and every primitive lies strictly inside; the slab test's far distance is widened
by ``1 + 2 gamma_3`` (Ize, "Robust BVH Ray Traversal", JCGT 2013), which covers its float
rounding. A direction component of zero gives infinite slab distances, or NaN where the ray
lies in the plane of a padded face, which holds no geometry (the comparison is then false:
culled, correctly). Planes are unbounded: a scene with planes has no boxes (None).
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, UInt32

#: the most shape boxes tested per ray; a scene with more shapes gets one box around them all
#: (16: the corpus's sphere grid, twelve spheres and a light, keeps a box each)
MAX_BOXES = 16
#: no box (:meth:`ShapeBoxes.leaving`): every box counts
NO_BOX = 0xFFFFFFFF
#: a vertex counts as on a triangle's inner side up to this fraction of the shape's largest
#: coordinate magnitude above its plane (a mesh file's decimals: 6 after the point in OBJ files)
CONVEX_EPS = 2.0**-16
#: the most triangles of a shape whose convexity is checked (:attr:`ShapeBoxes.outward`)
CONVEX_MAX = 1 << 20
#: a corner counts as in a flat shape's plane up to this fraction of the shape's largest
#: coordinate magnitude (float32 rounding of the coordinates, a few ulps)
FLAT_EPS = 2.0**-21
#: :attr:`ShapeBoxes.outward` of a flat shape: rays leave it to either side
FLAT = 2
#: the most materials :func:`material_groups` groups (more: one group)
MAX_GROUPS = 256
#: the stand-in for a sphere in :class:`ShapeBoxes`' shapes (always convex)
SPHERE = "sphere"
#: a vertex counts as convex where its corners' angles sum to at most ``2 pi`` plus this (a
#: flat vertex of a rounded mesh sums to ``2 pi`` up to its rounding over its edges' length)
DEFECT_EPS = 1e-3
#: :meth:`ShapeBoxes.reach`'s spheres are widened by this fraction of the ray origin's distance
SPHERE_SLACK = 2.0**-16
#: each box is padded by this fraction of its largest side and of its coordinates' magnitude
PAD = 1e-4
#: the slab test's far distance is multiplied by ``1 + 2 gamma_3`` (``gamma_n = n u / (1 - n u)``,
#: ``u = 2^-24``): Ize's bound on its rounding
FAR_SCALE = 1.0 + 2.0 * (3 * 2.0**-24) / (1.0 - 3 * 2.0**-24)


class ShapeBoxes:
    """Padded axis-aligned boxes ``lo[i] .. hi[i]`` (float32 on the device) around a scene's
    shapes (:meth:`of`)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, first: np.ndarray | None = None,
                 end: np.ndarray | None = None, shapes: list | None = None, positions=None):
        #: per box, the run ``first .. end - 1`` of global primitive ids of its shape (empty:
        #: not one shape, or not one run) and the shape (its triangles' ids into
        #: ``positions``, :data:`SPHERE`, or None) whose convexity :attr:`outward` decides
        #: when first asked
        self.first = np.zeros(len(lo), np.int64) if first is None else np.asarray(first, np.int64)
        self.end = np.zeros(len(lo), np.int64) if end is None else np.asarray(end, np.int64)
        self._shapes = shapes
        self._positions = positions
        self._outward = None
        #: per box, a sphere around its shape (padded by :data:`PAD`), tested instead of a
        #: larger box by the rays of :meth:`reach` with ``skip`` (:meth:`round`); None: not known
        self.center = self.radius = None
        size = np.max(hi - lo, axis=1, keepdims=True)
        pad = PAD * (size + np.maximum(np.abs(lo), np.abs(hi)))
        self.lo = (lo - pad).astype(np.float32)
        self.hi = (hi + pad).astype(np.float32)
        # (rounded to float32 outward: the boxes only grow)
        self.lo = np.where(self.lo > lo - pad, np.nextafter(self.lo, np.float32(-np.inf)), self.lo)
        self.hi = np.where(self.hi < hi + pad, np.nextafter(self.hi, np.float32(np.inf)), self.hi)

    @classmethod
    def of(cls, scene) -> ShapeBoxes | None:
        """The boxes of ``scene``'s shapes (a :class:`~drpt.scene.model.Scene`): per shape of
        triangles (``shape_index``, else ``shape``; else, drpt's own format, per material:
        :func:`material_groups`) and per sphere, or one around all of them where they are more
        than :data:`MAX_BOXES`; None for a scene with planes (unbounded) or no primitives."""
        if len(scene.planes) or len(scene.triangles) + len(scene.spheres) == 0:
            return None
        lo, hi, first, end, shapes, center, radius = [], [], [], [], [], [], []
        n_tri = len(scene.triangles)
        if n_tri:
            p = np.asarray(scene.triangles.positions, np.float64).reshape(-1, 3, 3)
            tris = scene.triangles
            shape = tris.shape_index if tris.shape_index is not None else tris.shape
            tlo, thi = p.min(1), p.max(1)  # per triangle, then per shape
            if shape is None:
                shape = material_groups(tlo, thi, np.asarray(tris.material, np.int64))
            order, starts, slo, shi = _label_boxes(np.asarray(shape), tlo, thi)
            lo += list(slo)
            hi += list(shi)
            if len(starts) + len(scene.spheres) <= MAX_BOXES:  # (else one box, for all)
                mid = (slo + shi) / 2  # (each shape's bounding sphere: its box's center, its farthest corner)
                of_shape = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, len(order)]))
                reach = np.linalg.norm(p[order] - mid[of_shape][:, None], axis=2).max(1)
                center += list(mid)
                radius += list(np.maximum.reduceat(reach, starts))
                for a, b in zip(starts, np.r_[starts[1:], len(order)]):
                    ids = order[a:b]
                    run = ids[-1] - ids[0] == b - a - 1  # (sorted stably: one run of ids)
                    first.append(ids[0] if run else 0)
                    end.append(ids[-1] + 1 if run else 0)
                    shapes.append(ids if run else None)
        if len(scene.spheres):
            c = np.asarray(scene.spheres.center, np.float64)
            r = np.asarray(scene.spheres.radius, np.float64)[:, None]
            lo += list(c - r)
            hi += list(c + r)
            center += list(c)
            radius += list(r[:, 0])
            first += list(n_tri + np.arange(len(c)))
            end += list(n_tri + 1 + np.arange(len(c)))
            shapes += [SPHERE] * len(c)
        lo, hi = np.array(lo), np.array(hi)
        if len(lo) > MAX_BOXES:
            return cls(lo.min(0, keepdims=True), hi.max(0, keepdims=True))
        out = cls(lo, hi, first, end, shapes, scene.triangles.positions if n_tri else None)
        pad = PAD * (np.array(radius) + np.abs(np.array(center)).max(1))
        out.center, out.radius = np.array(center, np.float32), (np.array(radius) + pad).astype(np.float32)
        return out

    @classmethod
    def of_materials(cls, scene, materials) -> ShapeBoxes | None:
        """One box around the triangles of each of ``materials`` (indices into
        ``scene.materials``; a :class:`~drpt.scene.model.Scene`), or one around all of them where
        they are more than :data:`MAX_BOXES`; None where no triangle has one of them."""
        tris = scene.triangles
        if not len(tris) or not len(materials):
            return None
        mat = np.asarray(tris.material)
        p = np.asarray(tris.positions, np.float64).reshape(-1, 3, 3)
        lo, hi = [], []
        for m in materials:
            q = p[mat == m]
            if len(q):
                lo.append(q.min((0, 1)))
                hi.append(q.max((0, 1)))
        if not lo:
            return None
        lo, hi = np.array(lo), np.array(hi)
        if len(lo) > MAX_BOXES:
            lo, hi = lo.min(0, keepdims=True), hi.max(0, keepdims=True)
        return cls(lo, hi)

    def __len__(self) -> int:
        return len(self.lo)

    def hold(self, center, radius: float = 0.0) -> bool:
        """Whether a box holds the cube of half-side ``radius`` around ``center``: rays
        from there all start inside it and reach it, so culling them tests in vain."""
        c = np.asarray(center, np.float64)
        return bool(np.any(np.all((self.lo <= c - radius) & (c + radius <= self.hi), axis=1)))

    @property
    def outward(self) -> np.ndarray:
        """Per box, the side its shape's geometric normals face where the shape is convex
        (+1 out, -1 in; :data:`FLAT`: a flat shape, either side; 0: not convex, not one shape
        or not one run of ids, or more than :data:`CONVEX_MAX` triangles):
        :func:`outward_convex`, :func:`flat`, computed when first asked."""
        if self._outward is None:
            def side(shape):
                if shape is SPHERE:
                    return 1  # (a sphere's normal faces out)
                if shape is None or len(shape) > CONVEX_MAX:
                    return 0
                p = np.asarray(self._positions).reshape(-1, 3, 3)[shape].astype(np.float64)
                return FLAT if flat(p) else outward_convex(p)
            shapes = self._shapes or [None] * len(self.lo)
            self._outward = np.array([side(sh) for sh in shapes], np.int64)
        return self._outward

    @property
    def convex(self) -> bool:
        """Whether some box is a convex or flat shape's (:meth:`leaving` can name it)."""
        return bool(np.any(self.outward != 0))

    @property
    def flat(self) -> bool:
        """Whether some box is a flat shape's (a ground: :data:`FLAT`)."""
        return bool(np.any(self.outward == FLAT))

    def leaving(self, prim: UInt32, ng: Array3f, d: Array3f, active: Bool) -> UInt32:
        """Per lane, the box of the convex shape that primitive ``prim`` belongs to where
        the ray ``d`` leaves it outward (``ng`` the hit's geometric normal in its defining
        orientation; ``active`` lanes; a flat shape: to either side), else :data:`NO_BOX`:
        ``reach(o, d, skip)`` then leaves that box out. Compares only, no gather (at most
        :data:`MAX_BOXES` boxes)."""
        out = UInt32(NO_BOX)
        side = dr.dot(ng, d)
        for i in np.flatnonzero(self.outward != 0):
            mine = active & (prim >= int(self.first[i])) & (prim < int(self.end[i]))
            off = side != 0.0 if self.outward[i] == FLAT else side * float(self.outward[i]) > 0.0
            out = dr.select(mine & off, int(i), out)
        return out

    def reach(self, o: Array3f, d: Array3f, skip: UInt32 | None = None) -> Bool:
        """Lanes whose ray ``o + t d`` (``t >= 0``) meets one of the boxes (conservatively:
        the module docstring), the box ``skip`` (per lane, :meth:`leaving`) left out."""
        inv = 1.0 / d  # (a division, correctly rounded, as the rounding bound assumes)
        out = Bool(False)
        for i, (lo, hi) in enumerate(zip(self.lo, self.hi)):
            if skip is not None and self.center is not None and self.round(i):
                meets = self._near_sphere(i, o, d)  # (inside the box: the box adds nothing)
            else:
                t0 = (Array3f(*(float(v) for v in lo)) - o) * inv
                t1 = (Array3f(*(float(v) for v in hi)) - o) * inv
                near = dr.max(dr.minimum(t0, t1))
                far = dr.min(dr.maximum(t0, t1)) * FAR_SCALE
                meets = (near <= far) & (far >= 0.0)
            if skip is not None and self.outward[i] != 0:
                meets &= skip != i
            out |= meets
        return out


    def round(self, i: int) -> bool:
        """Whether box ``i``'s sphere holds less volume than the box (a round shape's: then
        :meth:`reach` with ``skip`` tests the sphere alone, else the box alone)."""
        return 4.0 / 3.0 * np.pi * float(self.radius[i]) ** 3 < float(np.prod(self.hi[i] - self.lo[i]))

    def _near_sphere(self, i: int, o: Array3f, d: Array3f) -> Bool:
        """Lanes whose ray ``o + t d`` (``t >= 0``) passes within box ``i``'s sphere, its
        radius widened by :data:`SPHERE_SLACK` of the distance from ``o`` (float32 rounding of
        the closest approach)."""
        oc = Array3f(*(float(v) for v in self.center[i])) - o
        t = dr.maximum(dr.dot(oc, d) / dr.squared_norm(d), 0.0)
        r = float(self.radius[i]) + SPHERE_SLACK * dr.norm(oc)
        return dr.squared_norm(oc - t * d) <= r * r


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Surface areas of the boxes ``lo .. hi`` (the last axis: x, y, z)."""
    e = hi - lo
    return 2.0 * (e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0])


def _label_boxes(label: np.ndarray, tlo: np.ndarray, thi: np.ndarray):
    """The box of each label's triangles (``tlo``, ``thi``: per triangle, ``(T, 3)``), by one
    stable sort and no loop: ``(order, starts, lo, hi)``, the triangles sorted by label,
    where each label's run starts in that order, and the runs' boxes, by increasing label."""
    order = np.argsort(label, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(label[order]) != 0])
    return order, starts, np.minimum.reduceat(tlo[order], starts), np.maximum.reduceat(thi[order], starts)


def material_groups(tlo: np.ndarray, thi: np.ndarray, material: np.ndarray) -> np.ndarray:
    """Per triangle (``tlo``, ``thi``: its box, ``(T, 3)``), a group label for drpt's own
    format, whose triangles carry no shape: the triangles of each material, and then, while
    two groups' common box has no more surface area than their two boxes together (a ray
    that reaches either box would mostly test both), those two merged, the pair that saves
    the most area first. A car's parts become one group and the ground under it another; the
    walls, floor and lights of a room one. More than :data:`MAX_GROUPS` materials: one group."""
    mats, inverse = np.unique(material, return_inverse=True)
    if len(mats) > MAX_GROUPS:
        return np.zeros(len(tlo), np.int64)
    inverse = inverse.ravel()
    _, _, lo, hi = _label_boxes(inverse, tlo, thi)
    label = np.arange(len(mats))
    alive = list(range(len(mats)))
    while len(alive) > 1:
        a = np.array(alive)
        ulo, uhi = np.minimum(lo[a][:, None], lo[a][None]), np.maximum(hi[a][:, None], hi[a][None])
        own = _area(lo[a], hi[a])
        extra = _area(ulo, uhi) - (own[:, None] + own[None])  # (the common box's area less the two)
        extra[np.tril_indices(len(a))] = np.inf
        i, j = np.unravel_index(np.argmin(extra), extra.shape)
        if extra[i, j] > 0.0:
            break
        keep, gone = a[i], a[j]
        lo[keep], hi[keep] = ulo[i, j], uhi[i, j]
        label[label == gone] = keep
        alive.remove(gone)
    return label[inverse]


def flat(p: np.ndarray) -> bool:
    """Whether the triangles ``p`` (``(T, 3, 3)``, no degenerate one) lie in one plane: every
    corner within :data:`FLAT_EPS` of the largest coordinate magnitude of the plane of the
    largest triangle. A ray leaving such a shape to either side meets none of it."""
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(n, axis=1)
    if not len(p) or np.any(length == 0):
        return False
    k = int(np.argmax(length))
    unit = n[k] / length[k]
    dist = np.abs((p.reshape(-1, 3) - p[k, 0]) @ unit)
    return bool(np.all(dist <= FLAT_EPS * float(np.abs(p).max())))


def outward_convex(p: np.ndarray) -> int:
    """+1 where the triangles ``p`` (``(T, 3, 3)``) bound a convex shape with their
    normals (``(p1 - p0) x (p2 - p0)``) facing out, -1 facing in, 0 otherwise (a ray leaving
    one of them to the outer side of its plane then meets none of them). Convex here: a
    closed oriented surface (every edge joins two triangles, crossed in opposite directions;
    corners welded where their coordinates are equal) of a sphere's topology (Euler
    characteristic 2), convex at every edge (each triangle's neighbour across an edge has its
    third corner on the inner side of the triangle's plane, above it by at most
    :data:`CONVEX_EPS` of the largest coordinate magnitude) and at every vertex (its corners'
    angles sum to at most ``2 pi``, up to :data:`DEFECT_EPS`). Such a surface is the boundary
    of a convex body (its Gauss map covers the sphere once: Hadamard's theorem, Alexandrov's
    for polyhedra). A degenerate triangle (two equal corners or no area) answers 0. Work
    near ``T log T`` (sorts), no pair of distant triangles is compared."""
    t = len(p)
    if t < 4:
        return 0
    pts = p.reshape(-1, 3) + 0.0  # (-0 as +0)
    order = np.lexsort(pts.T[::-1])  # (welded: equal rows next to each other)
    new = np.r_[True, np.any(pts[order[1:]] != pts[order[:-1]], axis=1)]
    corner = np.empty(len(pts), np.int64)
    corner[order] = np.cumsum(new) - 1
    v = pts[order[new]]
    f = corner.reshape(t, 3)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(n, axis=1)
    if np.any(length == 0) or np.any((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])):
        return 0
    nv = len(v)
    if nv - 3 * t // 2 + t != 2 or (3 * t) % 2:  # (Euler characteristic of a sphere)
        return 0
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()  # (directed edges a -> b, three per triangle)
    key = a * nv + b
    order = np.argsort(key)
    if np.any(np.diff(key[order]) == 0):  # (an edge crossed twice in one direction)
        return 0
    at = np.searchsorted(key[order], b * nv + a)
    at = np.minimum(at, len(key) - 1)
    if np.any(key[order][at] != b * nv + a):  # (an edge without its reverse: not closed)
        return 0
    across = order[at] // 3  # (the neighbour across each directed edge)
    third = f[across, (order[at] + 2) % 3]  # (its corner off the edge)
    mid = v.mean(0)
    side = np.sign(np.sum(np.einsum("ij,ij->i", n, p[:, 0] - mid)))  # (the enclosed volume's sign)
    if side == 0:
        return 0
    unit = np.repeat(n / length[:, None] * side, 3, axis=0)
    above = np.einsum("ij,ij->i", unit, v[third] - np.repeat(p[:, 0], 3, axis=0))
    if np.any(above > CONVEX_EPS * float(np.abs(v).max())):
        return 0
    e1, e2 = p[:, [1, 2, 0]] - p, p[:, [2, 0, 1]] - p  # (each corner's two edges)
    cos = np.einsum("tij,tij->ti", e1, e2) / (np.linalg.norm(e1, axis=2) * np.linalg.norm(e2, axis=2))
    angles = np.bincount(f.ravel(), np.arccos(np.clip(cos, -1.0, 1.0)).ravel(), nv)
    if np.any(angles > 2.0 * np.pi + DEFECT_EPS):
        return 0
    return int(side)
