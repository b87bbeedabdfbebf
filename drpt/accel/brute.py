"""Brute-force reference intersector (an :class:`~drpt.accel.protocol.Accelerator`).

Every ray tests every primitive: one ``dr.while_loop`` per primitive kind
(triangles, spheres, planes) over the scene arrays in their original order.
It uses the very same primitive tests and float32 data as the BVH (watertight
triangles on ``[p0, p1, p2]`` buffers, precision-improved spheres), so on
identical inputs the two agree bit for bit up to ties between primitives at
equal ``t``. Meant for tests and tiny scenes: cost is ``O(rays * prims)``.

Hits count for ``0 < t < tmax``; ids follow the global id space of
:mod:`drpt.accel.protocol` (triangles, then spheres, then planes).
"""

from __future__ import annotations

import time

import drjit as dr
from drjit.auto import Array3f, Bool, Float, UInt32

from ..geometry.triangle import RayPrep
from .primitives import SceneGeometry, test_sphere, test_triangle
from .protocol import INVALID, AccelParams, Hit


class BruteForce:
    """Reference accelerator: loops over all primitives.

    Attributes: ``build_seconds``, ``nbytes``, ``stats`` (as every
    :class:`~drpt.accel.protocol.Accelerator`), ``geo`` (the
    :class:`~drpt.accel.primitives.SceneGeometry`, in the scene's order).
    """

    coherent_gain = False  # (every primitive tested by every ray: protocol.Accelerator)

    def __init__(self, scene):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        geo.upload_primitives(scene)
        self.nbytes = geo.nbytes()
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": geo.N}
        self.build_seconds = time.perf_counter() - t0

    @classmethod
    def from_params(cls, scene, p: AccelParams) -> BruteForce:
        """The registry's constructor (:mod:`drpt.accel.registry`)."""
        return cls(scene)

    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                  coherent: Bool | bool = False) -> Hit:
        """Closest hit with ``0 < t < tmax``."""
        return self.geo.hit(*self._trace(o, d, tmax, active))

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                 coherent: Bool | bool = False) -> Bool:
        """Whether anything is hit with ``0 < t < tmax``."""
        _, bj, _, _ = self._trace(o, d, tmax, active)
        return bj != INVALID

    def _trace(self, o, d, tmax, active):
        o, d, active = Array3f(o), Array3f(d), Bool(active)
        geo = self.geo
        bt = dr.select(active, Float(tmax), 0.0)
        bj, bu, bv = UInt32(INVALID), Float(0), Float(0)
        bt, bj = geo.intersect_planes(o, d, bt, bj, False)
        if geo.tri_buf is not None:
            tri_buf, prep, F = geo.tri_buf, RayPrep(o, d), geo.F

            def body(i, bt, bj, bu, bv):
                t, u, v, h = test_triangle(tri_buf, i, prep, bt, Bool(True))
                return (i + 1, dr.select(h, t, bt), dr.select(h, i, bj),
                        dr.select(h, u, bu), dr.select(h, v, bv))

            _, bt, bj, bu, bv = dr.while_loop((UInt32(0), bt, bj, bu, bv),
                                              lambda i, *_: i < F, body, label="drpt_brute_tri")
        if geo.sph_buf is not None:
            sph_buf, F, S = geo.sph_buf, geo.F, geo.S

            def body(i, bt, bj, bu, bv):
                t, h = test_sphere(sph_buf, i, o, d, bt, Bool(True))
                return (i + 1, dr.select(h, t, bt), dr.select(h, F + i, bj),
                        dr.select(h, 0.0, bu), dr.select(h, 0.0, bv))

            _, bt, bj, bu, bv = dr.while_loop((UInt32(0), bt, bj, bu, bv),
                                              lambda i, *_: i < S, body, label="drpt_brute_sph")
        return bt, bj, bu, bv
