"""Inline accelerator for tiny scenes: every primitive compiled into the kernel.

For a scene of a few dozen primitives (the Cornell box has 32 triangles) a
BVH costs more than it saves: each traversal step is a handful of packet
gathers, a stack and a branchy loop, and a ray visits several nodes and
leaves anyway. :class:`InlineList` instead *traces* one test per primitive
at Python time, with that primitive's float32 data as literal constants: the
kernel has no loop, no gather and no memory reads for the geometry, and the
16 lanes of a packet run the same straight-line code.

The tests are the accelerators' own (the watertight triangle test of
:mod:`drpt.geometry.triangle` on the same float32 vertices, the sphere and plane
tests), evaluated in the same order as :class:`~drpt.accel.brute.BruteForce`, so the
two agree bit for bit, with one exception: two consecutive triangles that form a
parallelogram sharing no outer edge with another triangle, whose plane no other surface
touches (a separate rectangle, as Mitsuba's ``rectangle`` shapes are) are tested as one
parallelogram
(:mod:`drpt.geometry.parallelogram`, :attr:`InlineList.parallelograms`), a fraction
of the work (docs/performance.md); their hits (``t``, the triangle, its barycentrics) are brute force's
within float rounding. The plates, floor, wall and lights of Veach's MIS scene are
such rectangles; of the Cornell box, only its ceiling light.

The code grows with the scene (about 80 vector instructions per triangle),
hence a limit: :func:`~drpt.accel.build_accel` picks this accelerator by
itself (``kind="auto"``, :func:`~drpt.accel.registry.resolve_kind`) only for
scenes of at most ``inline_max_prims`` primitives (triangles + spheres +
planes; :class:`drpt.backend.Policy`, 64 on both backends: about where
``bench --accel inline,bvh`` shows the BVH overtaking). Each scene compiles its own kernels (the
constants are part of the code).
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float, UInt32

from ..geometry.parallelogram import intersect_parallelogram, parallelogram_pairs
from ..geometry.plane import intersect_plane
from ..geometry.sphere import intersect_sphere
from ..geometry.triangle import RayPrep, watertight_permuted
from .protocol import INVALID, AccelParams, Hit


class InlineList:
    """Brute force's queries with the scene's primitives as constants.

    Attributes: ``build_seconds``, ``nbytes`` (0: no device data), ``stats``, ``quads``.
    """

    coherent_gain = False  # (every primitive tested by every ray: protocol.Accelerator)

    #: test two triangles that form a separate parallelogram (a rectangle) as one
    #: (:mod:`drpt.geometry.parallelogram`); False: every triangle by the watertight test,
    #: bit for bit brute force's hits (A/B measurements, tests)
    parallelograms = True

    def __init__(self, scene):
        t0 = time.perf_counter()
        self.F, self.S, self.P = len(scene.triangles), len(scene.spheres), len(scene.planes)
        self.tris = _f32(np.asarray(scene.triangles.positions).reshape(-1, 3, 3)) if self.F else []
        #: the pairs of triangles tested as one parallelogram, by their first triangle
        #: (:func:`~drpt.geometry.parallelogram.parallelogram_pairs`; none without
        #: :attr:`parallelograms`)
        self.quads = ({q.first: q for q in parallelogram_pairs(scene.triangles.positions,
                                                               *_surroundings(scene))}
                      if self.F and self.parallelograms else {})
        self.spheres = (list(zip(_f32(scene.spheres.center), _f32(scene.spheres.radius)))
                        if self.S else [])
        self.planes = (list(zip(_f32(scene.planes.normal), _f32(scene.planes.offset)))
                       if self.P else [])
        self.nbytes = 0
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": self.F + self.S + self.P}
        self.build_seconds = time.perf_counter() - t0

    @classmethod
    def from_params(cls, scene, p: AccelParams) -> InlineList:
        """The registry's constructor (:mod:`drpt.accel.registry`)."""
        return cls(scene)

    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                  coherent: Bool | bool = False) -> Hit:
        """Closest hit with ``0 < t < tmax``."""
        bt, bj, bu, bv = self._trace(o, d, tmax, active)
        valid = bj != INVALID
        return Hit(dr.select(valid, bt, float("inf")), bj, bu, bv, valid)

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                 coherent: Bool | bool = False) -> Bool:
        """Whether anything is hit with ``0 < t < tmax``: :meth:`intersect`'s
        tests, each against ``tmax`` itself, or-ed (no running closest
        distance, so the tests do not wait on each other)."""
        bound = dr.select(Bool(active), Float(tmax), 0.0)
        hit = Bool(False)
        for test in self._tests(o, d):
            hit |= test(bound)[3]
        return hit

    def _trace(self, o, d, tmax, active):
        bt = dr.select(Bool(active), Float(tmax), 0.0)
        bj, bu, bv = UInt32(INVALID), Float(0), Float(0)
        for test in self._tests(o, d):
            t, u, v, h, j = test(bt)
            bt, bj = dr.select(h, t, bt), dr.select(h, j, bj)
            bu, bv = dr.select(h, u, bu), dr.select(h, v, bv)
        return bt, bj, bu, bv

    def _tests(self, o, d):
        """Each primitive's test, in brute force's order, ``test(tmax) -> (t, u, v, hit,
        index)`` (``u = v = 0`` off triangles; ``index`` a constant, or per lane for a
        parallelogram's two triangles, tested where the first one is)."""
        o, d = Array3f(o), Array3f(d)
        N = self.F + self.S
        for k, (n, off) in enumerate(self.planes):
            yield lambda b, n=n, off=off, j=N + k: _no_uv(*intersect_plane(o, d, Array3f(*n), Float(off), b), j)
        if self.tris:
            r = RayPrep(o, d)
            # kx, ky follow kz (x->y->z->x), so two masks on kz pick every component
            m0, m1 = r.kz == 0, r.kz == 1
            for i, (p0, p1, p2) in enumerate(self.tris):
                q = self.quads.get(i)
                if q is not None:
                    yield lambda b, q=q, i=i: _one_of_two(*intersect_parallelogram(o, d, q, b), i)
                elif i - 1 not in self.quads:
                    g = [_pick(m0, m1, p, shift) for p in (p0, p1, p2) for shift in (1, 2, 0)]
                    yield lambda b, g=g, i=i: (*watertight_permuted(r, *g, b), i)
        for i, (c, rad) in enumerate(self.spheres):
            yield lambda b, c=c, rad=rad, j=self.F + i: _no_uv(*intersect_sphere(o, d, Array3f(*c), Float(rad), b), j)


def _no_uv(t: Float, hit: Bool, j: int) -> tuple[Float, Float, Float, Bool, int]:
    return t, Float(0), Float(0), hit, j


def _one_of_two(t: Float, u: Float, v: Float, hit: Bool, in_b: Bool, first: int) -> tuple:
    """A parallelogram's hit with its triangle's index, ``first`` or ``first + 1``."""
    return t, u, v, hit, dr.select(in_b, UInt32(first + 1), UInt32(first))


def _surroundings(scene) -> tuple:
    """``(others, planes)`` for :func:`~drpt.geometry.parallelogram.parallelogram_pairs`: the
    surfaces besides ``scene``'s triangles that a pair's plane must not touch: ``scene``'s
    planes, and where ``scene`` is part of a larger scene (the emissive list,
    :class:`drpt.render.scene.EmissiveList`) its ``surroundings``, ``(triangles (M, 3, 3),
    planes or None)``, the rest of that scene."""
    others, planes = getattr(scene, "surroundings", (None, None))
    if len(scene.planes):
        planes = (scene.planes.normal, scene.planes.offset)
    return others, planes


def _f32(a) -> list:
    """``a`` rounded to float32 (the accelerators' data), as nested Python floats."""
    return np.asarray(a, np.float32).astype(np.float64).tolist()


def _pick(m0: Bool, m1: Bool, p, shift: int):
    """``p[(kz + shift) % 3]`` for constant ``p`` and ``m0 = kz == 0``, ``m1 = kz == 1``."""
    a, b, c = p[shift % 3], p[(1 + shift) % 3], p[(2 + shift) % 3]
    if a == b == c:
        return Float(a)
    return dr.select(m0, Float(a), dr.select(m1, Float(b), Float(c)))
