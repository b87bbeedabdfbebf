"""Uniform grid with 3D-DDA traversal (the seed renderer's "3DDDA" accelerator).

An :class:`~drpt.accel.protocol.Accelerator` like the BVHs: ``intersect(o, d,
tmax, active) -> Hit``, ``occluded(o, d, tmax, active) -> Bool``,
``build_seconds``, ``nbytes`` and ``stats``, with the same global primitive ids
(triangles ``0..F-1``, spheres ``F..F+S-1``, planes ``F+S..``) and the same
primitive tests (watertight triangles on ``[p0, p1, p2]`` buffers,
precision-improved spheres, :mod:`drpt.accel.primitives`), so closest hits
agree with :class:`~drpt.accel.brute.BruteForce` up to ties at equal ``t``.
Planes are unbounded and tested by brute force before the grid.

Grid
----
The bounding box of the triangles and spheres is cut into ``nx * ny * nz``
equal cells. ``resolution=N`` gives ``N`` cells on every axis (the seed's
``-resolution N``); ``resolution=None`` (automatic) targets
``cells_per_prim * N`` cells in total, with cubic-ish cells: the cell side is
``cbrt(volume / (cells_per_prim * N))`` and each axis gets
``round(extent / side)`` cells, clamped to ``[1, MAX_RES]`` (``MAX_RES = 256``).
A flat box (e.g. a single triangle in a plane) is first given a minimum
thickness of ``1e-3`` of its largest extent.

Build (vectorized numpy, no per-primitive Python loop): every primitive is
registered in every cell its bounding box overlaps, conservatively: the box is
widened by ``1/256`` of a cell plus a few float32 ulps of the coordinates, so
that the float32 rounding of the traversal (cell boundaries, entry point,
axis order at corner crossings) never skips a primitive. Triangles are then
dropped from the cells (widened the same way) that their plane does not cut
(a plane/box test, not the full triangle/box SAT test): this cuts the
references of large slanted triangles from ``O(res^3)`` to ``O(res^2)``. The
result is a CSR layout: ``offsets[nx*ny*nz + 1]`` (uint32) and ``refs`` (uint32 global ids,
ascending within a cell). If the box-overlap count exceeds ``MAX_REFS`` the
automatic resolution is lowered (an explicit one raises ``ValueError``).

Memory (``nbytes``): ``4 * (cells + 1)`` offsets + ``4 * refs`` + primitive
data (the scene-order buffers of :class:`~drpt.accel.primitives.SceneGeometry`:
``36 * F`` triangles, ``16 * S`` spheres, ``16 * P`` planes). Uploads are
64-byte aligned (:func:`~drpt.accel.device.device_array`).

Traversal
---------
One ``dr.while_loop`` (symbolic or evaluated, following
:py:attr:`drjit.JitFlag.SymbolicLoops`) per query. Before the loop: planes,
then the ray's entry ``tn`` into the grid box (robust slab test,
:func:`~drpt.accel.device.slab`, and ``tn`` before the closest plane hit), the entry
point ``p = o + tn d`` and its cell (clamped to the grid). Amanatides & Woo
3D-DDA: each iteration tests *one* primitive of the current cell (the
reference at ``pi``); when the cell is exhausted, the lane stops if the closest
hit so far lies inside the cell (``t <= t_exit``, with a relative slack of
``2^-19`` so that rounding of ``t_exit`` cannot stop it early), otherwise it
steps to the neighbour across the nearest face and loads that cell's
reference range, in the same iteration. With ``skip_empty`` (class attribute,
default on) this stepping is a small nested ``dr.while_loop`` that walks over
empty cells without running the primitive test code (faster on sparse meshes,
neutral on the Cornell box: docs/performance.md, "Uniform grid"). Primitives are
tested one per outer iteration (as in the BVH), so lanes of a SIMD packet share
iterations whatever the primitive counts of their cells; an inner per-cell
primitive loop was not measured. Hits beyond the current cell's exit never
stop the walk (a primitive can span cells; a primitive met again in a later
cell is just retested). Face distances are recomputed from the integer cell
coordinates relative to the entry point (``tn + (B - p) / d``) rather than
accumulated, so there is no drift and the error is bounded by the box size,
not by the origin's distance. Axis-parallel rays (``1/d = inf``) never step
on that axis. ``occluded`` stops a lane at its first hit.
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float, Int32, UInt32

from ..geometry.triangle import RayPrep
from .device import device_array, nbytes, slab
from .primitives import SceneGeometry, nearest_primitive
from .protocol import INVALID, AccelParams, Hit

MAX_RES = 256  # cells per axis (automatic and explicit resolutions)
MAX_REFS = 1 << 26  # cap on primitive references (256 MB of uint32)
CELLS_PER_PRIM = 2.0  # automatic resolution: target cells per primitive
MIN_THICKNESS = 1e-3  # flat boxes: minimum extent relative to the largest extent
PAD_CELLS = 2.0**-8  # conservative registration: widen prim boxes by this many cells
_STOP_SLACK = 1.0 - 2.0**-19
_INF = float("inf")


def prim_bounds(scene) -> tuple[np.ndarray, np.ndarray]:
    """Float64 ``(lo, hi)`` boxes of triangles (float32 vertices) then spheres."""
    los, his = [], []
    if len(scene.triangles):
        p = np.asarray(scene.triangles.positions, np.float32).astype(np.float64)
        los.append(p.min(1))
        his.append(p.max(1))
    if len(scene.spheres):
        c = np.asarray(scene.spheres.center, np.float32).astype(np.float64)
        r = np.abs(np.asarray(scene.spheres.radius, np.float32).astype(np.float64))[:, None]
        pad = r * 1e-5 + np.abs(c) * 1e-6
        los.append(c - r - pad)
        his.append(c + r + pad)
    if not los:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate(los), np.concatenate(his)


def grid_box(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scene box with a minimum thickness, slightly padded, rounded outward to float32."""
    glo, ghi = lo.min(0), hi.max(0)
    ext = ghi - glo
    m = ext.max()
    if not m > 0:
        m = max(np.abs(glo).max(), 1.0) * 1e-3
    thick = np.maximum(ext, MIN_THICKNESS * m)
    c = (glo + ghi) / 2
    glo = np.minimum(glo, c - thick / 2)
    ghi = np.maximum(ghi, c + thick / 2)
    pad = (ghi - glo) * 1e-5 + np.maximum(np.abs(glo), np.abs(ghi)) * 1e-6
    glo = np.nextafter((glo - pad).astype(np.float32), np.float32(-np.inf)).astype(np.float64)
    ghi = np.nextafter((ghi + pad).astype(np.float32), np.float32(np.inf)).astype(np.float64)
    return glo, ghi


def auto_resolution(ext: np.ndarray, n_prims: int,
                    cells_per_prim: float = CELLS_PER_PRIM) -> np.ndarray:
    """Cells per axis: about ``cells_per_prim * n_prims`` cubic cells in total.

    Axes thinner than one cell get a single cell and the cell side is
    recomputed over the remaining axes (so a flat scene gets a 2D grid of the
    target size, not a cube's share of it); each axis is capped at ``MAX_RES``.
    """
    target = max(cells_per_prim * n_prims, 1.0)
    thin = np.zeros(3, bool)
    for _ in range(3):
        k = int((~thin).sum())
        side = (float(np.prod(ext[~thin])) / target) ** (1.0 / k)
        new_thin = thin | (ext / side < 1.0)
        if (new_thin == thin).all() or new_thin.all():
            break
        thin = new_thin
    n = np.where(thin, 1.0, np.round(ext / side))
    return np.clip(n, 1, MAX_RES).astype(np.int64)


def cell_pad(glo, w, res):
    """Registration margin per axis: ``PAD_CELLS`` cells + float32 ulps of the coordinates."""
    scale = np.maximum(np.abs(glo), np.abs(glo + w * res))
    return PAD_CELLS * w + 8.0 * scale * 2.0**-24


def cell_ranges(lo, hi, glo, w, res):
    """Conservative inclusive cell index ranges ``(i0, i1)`` of prim boxes."""
    pad = cell_pad(glo, w, res)
    i0 = np.floor((lo - pad - glo) / w)
    i1 = np.floor((hi + pad - glo) / w)
    i0 = np.clip(i0, 0, res - 1).astype(np.int64)
    i1 = np.clip(i1, 0, res - 1).astype(np.int64)
    return i0, i1


def build_csr(i0, i1, res, planes=None) -> tuple[np.ndarray, np.ndarray]:
    """CSR ``(offsets, refs)`` of primitives over the cells of their ranges.

    ``planes = (n, nd, glo, w, pad)`` (optional): the first ``len(n)``
    primitives are triangles with plane ``dot(n, x) = nd``; their references
    are kept only in cells whose box, widened by ``pad``, meets that plane.
    """
    n = i1 - i0 + 1
    cnt = n.prod(1)
    total = int(cnt.sum())
    ncells = int(np.prod(res))
    if total == 0:
        return np.zeros(ncells + 1, np.uint32), np.zeros(0, np.uint32)
    prim = np.repeat(np.arange(len(cnt), dtype=np.int64), cnt)
    start = np.cumsum(cnt) - cnt
    local = np.arange(total, dtype=np.int64) - start[prim]
    nxp, nyp = n[prim, 0], n[prim, 1]
    dx = local % nxp
    local //= nxp
    dy = local % nyp
    dz = local // nyp
    del local
    ix, iy, iz = i0[prim, 0] + dx, i0[prim, 1] + dy, i0[prim, 2] + dz
    del dx, dy, dz
    if planes is not None:
        n, nd, glo, w, pad = planes
        tri = np.flatnonzero(prim < len(n))
        pt = prim[tri]
        nt = n[pt]
        c = glo + (np.stack([ix[tri], iy[tri], iz[tri]], 1) + 0.5) * w
        dist = np.abs((nt * c).sum(1) - nd[pt])
        reach = (np.abs(nt) * (w / 2 + pad)).sum(1)
        drop = tri[dist > reach * (1 + 1e-6)]
        if drop.size:
            keep = np.ones(total, bool)
            keep[drop] = False
            prim, ix, iy, iz = prim[keep], ix[keep], iy[keep], iz[keep]
    cell = ix + res[0] * (iy + res[1] * iz)
    del ix, iy, iz
    order = np.argsort(cell, kind="stable")
    refs = prim[order].astype(np.uint32)
    counts = np.bincount(cell, minlength=ncells)
    offsets = np.zeros(ncells + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets.astype(np.uint32), refs


class UniformGrid:
    """Triangles and spheres in a uniform grid; planes tested brute force.

    Args:
        scene: the :class:`~drpt.scene.model.Scene`.
        resolution: cells per axis (``int``), or ``None`` for automatic.
        cells_per_prim: target cells per primitive of the automatic resolution.

    Attributes:
        build_seconds: host build time (bounds, CSR build and upload).
        nbytes: bytes of device arrays (offsets, refs, primitive data, planes).
        stats: ``resolution`` (nx, ny, nz), ``cells``, ``refs``,
            ``refs_per_prim``, ``empty_cells``, ``max_refs_per_cell``, ``prims``
            (and ``nodes = 0``, ``leaves = cells``, ``max_depth = 0`` for
            interface parity with the BVH).
    """

    coherent_gain = True  # (a traversal: protocol.Accelerator)

    def __init__(self, scene, resolution: int | None = None,
                 cells_per_prim: float = CELLS_PER_PRIM):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        F, N = geo.F, geo.N
        self.offsets = self.refs = None
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": N,
                      "resolution": (0, 0, 0), "cells": 0, "refs": 0}
        if N:
            lo, hi = prim_bounds(scene)
            glo, ghi = grid_box(lo, hi)
            ext = ghi - glo
            if resolution is None:
                res = auto_resolution(ext, N, cells_per_prim)
            else:
                r = int(resolution)
                if not 1 <= r <= MAX_RES:
                    raise ValueError(f"grid resolution must be in [1, {MAX_RES}], got {resolution}")
                res = np.full(3, r, np.int64)
            while True:
                w = ext / res
                i0, i1 = cell_ranges(lo, hi, glo, w, res)
                total = int((i1 - i0 + 1).prod(1).sum())
                if total <= MAX_REFS:
                    break
                if resolution is not None:
                    raise ValueError(f"grid resolution {resolution} needs {total} primitive "
                                     f"references (limit {MAX_REFS}); use a lower resolution")
                res = np.maximum((res * 0.7).astype(np.int64), 1)
            planes = None
            if F:  # triangles: drop cells their plane misses (float64 from float32 vertices)
                q = np.asarray(scene.triangles.positions, np.float32).astype(np.float64)
                nrm = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
                planes = (nrm, (nrm * q[:, 0]).sum(1), glo, w, cell_pad(glo, w, res))
            offsets, refs = build_csr(i0, i1, res, planes)
            counts = np.diff(offsets.astype(np.int64))
            self.res = tuple(int(x) for x in res)
            self.lo = tuple(float(x) for x in glo.astype(np.float32))
            w32 = (ext / res).astype(np.float32)
            self.w = tuple(float(x) for x in w32)
            self.inv_w = tuple(float(np.float32(1.0) / x) for x in w32)
            self.box_lo = tuple(float(x) for x in glo.astype(np.float32))
            self.box_hi = tuple(float(x) for x in ghi.astype(np.float32))
            self.offsets = device_array(UInt32, offsets)
            self.refs = device_array(UInt32, refs if refs.size else np.zeros(1, np.uint32))
            geo.upload_primitives(scene)
            self.stats.update({
                "leaves": int(counts.size), "resolution": self.res, "cells": int(counts.size),
                "refs": int(refs.size), "refs_per_prim": float(refs.size / N),
                "empty_cells": int((counts == 0).sum()),
                "max_refs_per_cell": int(counts.max()) if counts.size else 0})
        self.nbytes = nbytes(self.offsets, self.refs) + geo.nbytes()
        self.build_seconds = time.perf_counter() - t0

    @classmethod
    def from_params(cls, scene, p: AccelParams) -> UniformGrid:
        """The registry's constructor (:mod:`drpt.accel.registry`)."""
        return cls(scene, resolution=p.resolution)

    # ---------------------------------------------------------------- queries
    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                  coherent: Bool | bool = False) -> Hit:
        """Closest hit with ``0 < t < tmax``."""
        return self.geo.hit(*self._trace(o, d, tmax, active, any_hit=False))

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                 coherent: Bool | bool = False) -> Bool:
        """Whether anything is hit with ``0 < t < tmax`` (stops at the first hit)."""
        _, bj, _, _ = self._trace(o, d, tmax, active, any_hit=True)
        return bj != INVALID

    # ------------------------------------------------------------- internals
    skip_empty = True  # walk over empty cells in a nested DDA loop (see module docstring)

    def _trace(self, o, d, tmax, active, any_hit: bool):
        skip_empty = self.skip_empty
        o, d, tmax = Array3f(o), Array3f(d), Float(tmax)
        n = max(dr.width(o), dr.width(d), dr.width(tmax), dr.width(active))
        active = Bool(active) & dr.full(Bool, True, n)
        geo = self.geo
        bt = dr.select(active, tmax, 0.0)
        bj, bu, bv = dr.full(UInt32, INVALID, n), dr.zeros(Float, n), dr.zeros(Float, n)
        bt, bj = geo.intersect_planes(o, d, bt, bj, any_hit)
        if not geo.N:
            return bt, bj, bu, bv
        if any_hit:
            active &= bj == INVALID

        F = geo.F
        tri_buf, sph_buf, offsets, refs = geo.tri_buf, geo.sph_buf, self.offsets, self.refs
        mixed = tri_buf is not None and sph_buf is not None
        prep = RayPrep(o, d) if tri_buf is not None else None
        inv_d = dr.rcp(d)
        res, lo, w, inv_w = self.res, self.lo, self.w, self.inv_w

        # entry into the grid box
        tn, tf = slab(self.box_lo, self.box_hi, o, inv_d)
        alive = active & (tn <= tf) & (tn < bt)
        tn = dr.select(alive, tn, 0.0)
        p = o + tn * d

        cell, step, pos, zero = [], [], [], []
        for a in range(3):
            c = dr.clip(dr.floor((p[a] - lo[a]) * inv_w[a]), 0.0, float(res[a] - 1))
            cell.append(Int32(dr.select(alive, c, 0.0)))
            pos.append(d[a] > 0)
            zero.append(d[a] == 0)
            step.append(dr.select(d[a] > 0, Int32(1), dr.select(d[a] < 0, Int32(-1), Int32(0))))
        nx, ny = res[0], res[1]

        def cell_index(cx, cy, cz):
            return UInt32(cx + nx * (cy + ny * cz))

        c0 = cell_index(*cell)
        pi = dr.gather(UInt32, offsets, c0, alive)
        pe = dr.gather(UInt32, offsets, c0 + 1, alive)

        def cond(cx, cy, cz, pi, pe, alive, bt, bj, bu, bv):
            return alive

        def body(cx, cy, cz, pi, pe, alive, bt, bj, bu, bv):
            # ---- test one primitive of the current cell
            pa = alive & (pi < pe)
            ref = dr.gather(UInt32, refs, pi, pa)
            if mixed:
                sph = ref >= F
                tri_on, sph_on = pa & ~sph, pa & sph
            else:
                tri_on = sph_on = pa
            bt, bj, bu, bv, hit_any = nearest_primitive(
                tri_buf, sph_buf, ref, ref - F, ref, prep, o, d, tri_on, sph_on, bt, bj, bu, bv)
            pi = dr.select(pa, pi + 1, pi)

            # ---- cell exhausted: stop, or step to the next cell (3D-DDA)
            if any_hit:
                alive &= ~hit_any
            if skip_empty:
                # step over empty cells in an inner loop (DDA only, no primitive test)
                cx, cy, cz, pi, pe, alive = dr.while_loop(
                    (cx, cy, cz, pi, pe, alive), lambda cx, cy, cz, pi, pe, alive: alive & (pi >= pe),
                    lambda cx, cy, cz, pi, pe, alive: advance(cx, cy, cz, pi, pe, alive, bt),
                    label="drpt_grid_dda")
            else:
                cx, cy, cz, pi, pe, alive = advance(cx, cy, cz, pi, pe, alive, bt)
            return cx, cy, cz, pi, pe, alive, bt, bj, bu, bv

        def advance(cx, cy, cz, pi, pe, alive, bt):
            """Exhausted cell: stop if the closest hit is inside it, else step (3D-DDA)."""
            cs = (cx, cy, cz)
            tx, ty, tz = [
                dr.select(zero[a], _INF,
                          tn + (lo[a] + Float(dr.select(pos[a], cs[a] + 1, cs[a])) * w[a] - p[a])
                          * inv_d[a])
                for a in range(3)]
            t_exit = dr.minimum(dr.minimum(tx, ty), tz)
            alive &= ~((pi >= pe) & (bt <= t_exit * _STOP_SLACK))
            adv = alive & (pi >= pe)
            mx = (tx <= ty) & (tx <= tz)
            my = ~mx & (ty <= tz)
            mz = ~mx & ~my
            cx = dr.select(adv & mx, cx + step[0], cx)
            cy = dr.select(adv & my, cy + step[1], cy)
            cz = dr.select(adv & mz, cz + step[2], cz)
            out = ((cx < 0) | (cx >= res[0]) | (cy < 0) | (cy >= res[1])
                   | (cz < 0) | (cz >= res[2]))
            alive &= ~(adv & out)
            ld = adv & ~out
            c = cell_index(cx, cy, cz)
            pi = dr.select(ld, dr.gather(UInt32, offsets, c, ld), pi)
            pe = dr.select(ld, dr.gather(UInt32, offsets, c + 1, ld), pe)
            return cx, cy, cz, pi, pe, alive

        state = (cell[0], cell[1], cell[2], pi, pe, alive, bt, bj, bu, bv)
        state = dr.while_loop(state, cond, body, label="drpt_grid")
        return state[6:]
