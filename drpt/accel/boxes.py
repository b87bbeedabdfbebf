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
from drjit.auto import Array3f, Bool

#: the most shape boxes tested per ray; a scene with more shapes gets one box around them all
MAX_BOXES = 8
#: each box is padded by this fraction of its largest side and of its coordinates' magnitude
PAD = 1e-4
#: the slab test's far distance is multiplied by ``1 + 2 gamma_3`` (``gamma_n = n u / (1 - n u)``,
#: ``u = 2^-24``): Ize's bound on its rounding
FAR_SCALE = 1.0 + 2.0 * (3 * 2.0**-24) / (1.0 - 3 * 2.0**-24)


class ShapeBoxes:
    """Padded axis-aligned boxes ``lo[i] .. hi[i]`` (float32 on the device) around a scene's
    shapes (:meth:`of`)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray):
        size = np.max(hi - lo, axis=1, keepdims=True)
        pad = PAD * (size + np.maximum(np.abs(lo), np.abs(hi)))
        self.lo = (lo - pad).astype(np.float32)
        self.hi = (hi + pad).astype(np.float32)
        # (rounded to float32 outward: the boxes only grow)
        self.lo = np.where(self.lo > lo - pad, np.nextafter(self.lo, np.float32(-np.inf)), self.lo)
        self.hi = np.where(self.hi < hi + pad, np.nextafter(self.hi, np.float32(np.inf)), self.hi)

    @classmethod
    def of(cls, scene) -> ShapeBoxes | None:
        """The boxes of ``scene``'s shapes (a :class:`~drpt.scene.model.Scene`): one per
        shape of triangles (``shape_index``, else ``shape``; else one for all) and per
        sphere, or one around all of them where they are more than :data:`MAX_BOXES`; None
        for a scene with planes (unbounded) or no primitives."""
        if len(scene.planes) or len(scene.triangles) + len(scene.spheres) == 0:
            return None
        lo, hi = [], []
        if len(scene.triangles):
            p = np.asarray(scene.triangles.positions, np.float64).reshape(-1, 3, 3)
            tris = scene.triangles
            shape = tris.shape_index if tris.shape_index is not None else tris.shape
            shape = np.zeros(len(p), np.int64) if shape is None else np.asarray(shape)
            tlo, thi = p.min(1), p.max(1)  # per triangle, then per shape: one sort, no loop
            order = np.argsort(shape, kind="stable")
            starts = np.flatnonzero(np.r_[True, np.diff(shape[order]) != 0])
            lo += list(np.minimum.reduceat(tlo[order], starts))
            hi += list(np.maximum.reduceat(thi[order], starts))
        if len(scene.spheres):
            c = np.asarray(scene.spheres.center, np.float64)
            r = np.asarray(scene.spheres.radius, np.float64)[:, None]
            lo += list(c - r)
            hi += list(c + r)
        lo, hi = np.array(lo), np.array(hi)
        if len(lo) > MAX_BOXES:
            lo, hi = lo.min(0, keepdims=True), hi.max(0, keepdims=True)
        return cls(lo, hi)

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

    def reach(self, o: Array3f, d: Array3f) -> Bool:
        """Lanes whose ray ``o + t d`` (``t >= 0``) meets one of the boxes (conservatively:
        the module docstring)."""
        inv = 1.0 / d  # (a division, correctly rounded, as the rounding bound assumes)
        out = Bool(False)
        for lo, hi in zip(self.lo, self.hi):
            t0 = (Array3f(*(float(v) for v in lo)) - o) * inv
            t1 = (Array3f(*(float(v) for v in hi)) - o) * inv
            near = dr.max(dr.minimum(t0, t1))
            far = dr.min(dr.maximum(t0, t1)) * FAR_SCALE
            out |= (near <= far) & (far >= 0.0)
        return out
