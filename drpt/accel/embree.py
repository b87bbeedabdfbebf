"""Embree 3's BVH, queried from inside drpt's Dr.Jit kernels: the ``"embree"`` accelerator.

:class:`EmbreeAccel` has the interface of every accelerator
(:class:`~drpt.accel.protocol.Accelerator`: the same global primitive ids, ``Hit`` records
and ``0 < t < tmax`` rule). It hands the scene's triangles and spheres to Embree 3 (one
triangle mesh, geometry id 0, and one set of sphere points, id 1, in the scene's order, high
build quality as Mitsuba 3 builds it; robust mode: :func:`drpt.scene.model.embree_robust`),
and every ``intersect`` / ``occluded`` call adds a packet query of Embree to the kernel
being traced, through Dr.Jit's ``jit_llvm_ray_trace`` (:mod:`drpt.accel.embree_lib`). The
query is a call inside the kernel: it works in symbolic loops (the megakernel's path loop)
as in the wavefront's kernels, and the rest of the kernel stays drpt's code. Planes are
tested by brute force first (:class:`~drpt.accel.primitives.SceneGeometry`),
and Embree's ``tfar`` is the nearest plane hit.

Why: on large scenes drpt's own 4-wide BVH (:mod:`drpt.accel.bvh4`, one ray per SIMD
lane, a packet looping until its slowest lane is done) traces incoherent rays at a
fraction of Embree's rate, and on the 510k-triangle dining room its traversal is more than
half of a path-traced frame (docs/performance.md, "Embree"); Embree's packet queries
fall back to single-ray traversal with SIMD across a node's children when a packet
diverges, which a lane-per-ray Dr.Jit kernel cannot express. ``--accel auto`` therefore picks this accelerator above
``inline_max_prims`` primitives on the LLVM backend when Embree 3 loads
(:func:`drpt.accel.registry.resolve_kind`), and drpt's BVH otherwise (CUDA, no Embree,
or a BVH rule asked for).

Robust mode: Embree's watertight triangle test and conservative box tests, on for drpt's
own scene format; a Mitsuba XML scene follows its ``embree_use_robust_intersections``,
off by default as in Mitsuba 3 (:func:`drpt.scene.model.embree_robust`). Off, rays aimed
within rounding of a shared edge or vertex can slip between two triangles
(``benchmarks/embree_robust_leak.py`` aims rays there to count them), and the queries take
less time (docs/performance.md, "Embree", measures both).

Agreement with drpt's own tests (``tests/accel/test_embree.py``): the same hits up to
ties between primitives at equal ``t`` and rounding of ``t, u, v`` (Embree's robust
triangle test is watertight too, but not bit-identical to
:mod:`drpt.geometry.triangle`); triangles are two-sided, ``u, v`` are the same
barycentrics (``p = p0 + u (p1 - p0) + v (p2 - p0)``), zero for spheres. Hits at
``t = 0`` are excluded by ``tnear`` = the smallest normal float.

Lifetime: Embree reads the vertex arrays in place (kept with the Embree scene). A
collected accelerator's Embree scene is released once no unevaluated query refers to
it (the reference counts of its pointer variables) and no queued kernel runs it
(``dr.sync_thread()``): at once, or at a later collection or build.
"""

from __future__ import annotations

import ctypes
import time
import weakref

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float, UInt32

from drpt.scene.model import embree_robust

from . import embree_lib as lib
from .primitives import SceneGeometry
from .protocol import INVALID, AccelParams, Hit

TNEAR = float(np.finfo(np.float32).tiny)  # excludes t = 0, as every accelerator does


_retired: list = []  # (lib, Embree scene, pointer variables, vertex arrays) of collected accelerators


def _retire(L, escene, pointers, arrays):
    _retired.append((L, escene, pointers, arrays))
    _reap()


def _reap():
    """Release the retired Embree scenes that nothing refers to any more: the
    scene's pointer variable holds only the accelerator's reference (no
    unevaluated query uses it), and after ``dr.sync_thread()`` no queued kernel
    does. (The handles' arrays go with the retired record, after the pointer variables
    that depend on them.)"""
    free = [r for r in _retired if r[0].var_ref(r[2][0]) == 1]
    if not free:
        return
    dr.sync_thread()
    for r in free:
        L, escene, pointers, _ = r
        for p in pointers:
            L.dec_ref(p)
        L.rtcReleaseScene(escene)
        _retired.remove(r)


class EmbreeAccel:
    """Triangles and spheres of a scene in an Embree 3 BVH; planes brute force.

    Raises :class:`~drpt.accel.embree_lib.EmbreeUnavailable` when Embree 3 or the
    LLVM backend is missing.

    Attributes:
        build_seconds: host time of the upload and Embree's build.
        nbytes: bytes of the vertex and sphere arrays handed to Embree plus what
            Embree allocated for the scene (its memory monitor, net of frees).
        stats: ``nodes``, ``leaves``, ``max_depth`` (0: Embree does not report them)
            and ``prims``.
        geo: the :class:`~drpt.accel.primitives.SceneGeometry` (planes).
    """

    coherent_gain = True  # (a traversal: protocol.Accelerator)

    def __init__(self, scene):
        t0 = time.perf_counter()
        L = self._lib = lib.load()
        _reap()
        self.geo = geo = SceneGeometry(scene)
        F, S = geo.F, geo.S
        self._arrays = []
        self.nbytes = 0
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": geo.N}
        bytes0 = L.device_bytes
        esc = L.rtcNewScene(L.device)
        self.robust = embree_robust(scene)
        L.rtcSetSceneFlags(esc, lib.SCENE_FLAG_ROBUST if self.robust else 0)
        L.rtcSetSceneBuildQuality(esc, lib.BUILD_QUALITY_HIGH)
        if F:
            # Embree reads vertices with 16-byte loads: one spare vertex at the end
            v = np.zeros((3 * F + 1, 3), np.float32)
            v[:-1] = np.asarray(scene.triangles.positions, np.float32).reshape(-1, 3)
            idx = np.arange(3 * F, dtype=np.uint32)
            self._attach(esc, lib.GEOMETRY_TRIANGLE, 0,
                         [(lib.BUFFER_VERTEX, lib.FORMAT_FLOAT3, v, 12, 3 * F),
                          (lib.BUFFER_INDEX, lib.FORMAT_UINT3, idx, 12, F)])
        if S:
            pts = np.zeros((S, 4), np.float32)
            pts[:, :3] = np.asarray(scene.spheres.center, np.float32)
            pts[:, 3] = np.abs(np.asarray(scene.spheres.radius, np.float32))
            self._attach(esc, lib.GEOMETRY_SPHERE_POINT, 1,
                         [(lib.BUFFER_VERTEX, lib.FORMAT_FLOAT4, pts, 16, S)])
        L.rtcCommitScene(esc)
        self.nbytes += L.device_bytes - bytes0
        err = L.rtcGetDeviceError(L.device)
        if err:
            L.rtcReleaseScene(esc)
            raise lib.EmbreeUnavailable(f"Embree failed to build the scene (RTCError {err})")
        width = L.vector_width()
        if width not in L.queries:
            L.rtcReleaseScene(esc)
            raise lib.EmbreeUnavailable(f"Dr.Jit's vector width {width} has no Embree 3 query")
        f_int, f_occ = L.queries[width]
        # the scene and the two queries as mapped one-element arrays (self.handles, which
        # dr.freeze must find among a frozen function's inputs) and pointer variables on them
        (h_scene, self._scene), (h_int, self._f_int), (h_occ, self._f_occ) = (
            L.handle(a) for a in (esc, f_int, f_occ))
        self.handles = [h_scene, h_int, h_occ]
        self._finalizer = weakref.finalize(self, _retire, L, esc,
                                           (self._scene, self._f_int, self._f_occ),
                                           (self._arrays, list(self.handles)))
        self._finalizer.atexit = False
        self.build_seconds = time.perf_counter() - t0

    def _attach(self, esc, kind, geom_id, buffers):
        L = self._lib
        g = L.rtcNewGeometry(L.device, kind)
        for btype, fmt, arr, stride, count in buffers:
            self._arrays.append(arr)
            self.nbytes += arr.nbytes
            L.rtcSetSharedGeometryBuffer(g, btype, 0, fmt, arr.ctypes.data, 0, stride, count)
        L.rtcCommitGeometry(g)
        L.rtcAttachGeometryByID(esc, g, geom_id)
        L.rtcReleaseGeometry(g)

    @classmethod
    def from_params(cls, scene, p: AccelParams) -> EmbreeAccel:
        """The registry's constructor (:mod:`drpt.accel.registry`)."""
        return cls(scene)

    # ---------------------------------------------------------------- queries
    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                  coherent: Bool | bool = False) -> Hit:
        """Closest hit with ``0 < t < tmax``; ``coherent`` (lanes of camera rays) selects
        Embree's coherent traversal for their packets (Dr.Jit's ``jit_llvm_ray_trace``
        input, Mitsuba's ``ray_intersect(..., coherent)``): the same hits, faster for
        rays that share an origin and nearby directions."""
        o, d, active, bt, bj, bu, bv = self.geo.begin_query(o, d, tmax, active, False)
        if self.geo.N:
            valid, t, u, v, prim, geom = self._query(o, d, bt, active, shadow=False, coherent=coherent)[:6]
            prim = dr.select(geom == 0, prim, prim + self.geo.F)
            tri = valid & (geom == 0)
            bt = dr.select(valid, t, bt)
            bj = dr.select(valid, prim, bj)
            bu = dr.select(tri, u, bu)
            bv = dr.select(tri, v, bv)
        return self.geo.hit(bt, bj, bu, bv)

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                 coherent: Bool | bool = False) -> Bool:
        """Whether anything is hit with ``0 < t < tmax`` (any-hit); ``coherent`` as
        :meth:`intersect`'s."""
        o, d, active, bt, bj, _, _ = self.geo.begin_query(o, d, tmax, active, True)
        hit = bj != INVALID
        if self.geo.N:
            hit |= self._query(o, d, Float(tmax), active, shadow=True, coherent=coherent)[0]
        return hit

    def _query(self, o: Array3f, d: Array3f, tfar: Float, active: Bool, shadow: bool,
               coherent: Bool | bool = False):
        """Embree's packet query: ``(hit,)`` for shadow rays, else ``(valid, t, u, v,
        primID, geomID, instID, hit_inst)``."""
        L = self._lib
        args = (Bool(coherent), Bool(active), o.x, o.y, o.z, Float(TNEAR), d.x, d.y, d.z,
                Float(0.0), Float(tfar), UInt32(0xFFFFFFFF), UInt32(0), UInt32(0))
        widths = {dr.width(a) for a in args} - {1}
        if len(widths) > 1:  # Dr.Jit would raise in C++, which aborts through ctypes
            raise ValueError(f"ray query over arrays of incompatible sizes {sorted(widths)}")
        n_out = 1 if shadow else 8
        inputs = (ctypes.c_uint32 * 14)(*(a.index for a in args))
        outputs = (ctypes.c_uint32 * 8)()
        L.ray_trace(self._f_occ if shadow else self._f_int, self._scene, int(shadow),
                    inputs, outputs)
        kinds = (Bool(),) if shadow else (Bool(), Float(), Float(), Float(), UInt32(),
                                           UInt32(), UInt32(), Bool())
        out = dr.detail.update_indices(kinds, list(outputs[:n_out]))  # borrows the references
        for i in outputs[:n_out]:
            L.dec_ref(i)
        return out
