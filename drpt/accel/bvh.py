"""4-wide BVH ray traversal in Dr.Jit (one symbolic loop, per-lane stack).

:class:`BVH` holds the triangles and spheres of a :class:`~drpt.scene.model.Scene`
in one bounding volume hierarchy (built by :mod:`drpt.accel.bvh_build`);
planes are unbounded and are tested by brute force for every ray, before the
traversal, so that a near plane already shortens it.

Primitive ids
-------------
One global id space, in the *original* order of the scene arrays: triangles
``0 .. F-1``, spheres ``F .. F+S-1``, planes ``F+S .. F+S+P-1``.

Results
-------
:class:`Hit` fields: ``t`` (``inf`` when there is no hit), ``prim``
(``0xFFFFFFFF`` when there is no hit), ``u, v`` (triangle barycentrics with
``p = p0 + u (p1 - p0) + v (p2 - p0)``, zero for spheres, planes and misses)
and ``valid``. Only hits with ``0 < t < tmax`` count (strictly positive, so a
ray starting exactly on a surface does not report ``t == 0``; rounding may
still give tiny positive ``t`` there, so callers offset spawned rays).

Traversal
---------
The binary tree from :mod:`drpt.accel.bvh_build` is collapsed into a 4-wide
tree (:func:`~drpt.accel.bvh_build.collapse_bvh4`). Everything happens in one
``dr.while_loop`` (symbolic by default; it also runs in evaluated mode,
following :py:attr:`drjit.JitFlag.SymbolicLoops`). The root box is tested
before the loop. Each iteration of a lane does, in this order:

1. *node phase* (when the lane is not inside a leaf): pop an entry from the
   lane's stack (two ``dr.alloc_local`` arrays, node reference and entry
   distance, ``3 * depth4 + 4`` entries: at most three pushes per level)
   unless one is current; drop it if its entry distance exceeds the closest
   hit. For an inner node, fetch the four child boxes with six 16-byte packet
   gathers and the four child references with one, slab-test all four,
   sort the hits by entry distance (5-comparator network, misses last),
   push the farther hits (farthest first) and continue with the nearest.
   If the entry in hand is a leaf (popped, or the nearest child just found),
   load its primitive range right away;
2. *primitive phase* (when inside a leaf): test one primitive (the first one
   in the same iteration that found the leaf).

Device data (float32, in BVH order for coherent gathers, 64-byte aligned so
that packet gathers are used): per 4-wide node, 24 floats of child boxes in
SoA order ``lo.x[4], lo.y[4], lo.z[4], hi.x[4], hi.y[4], hi.z[4]`` and 4 uint32
child references (an inner child's node index; a leaf's
``1 << 31 | (count - 1) << 27 | first``; ``0xFFFFFFFF`` for an unused slot);
triangle vertices ``p0, p1, p2`` padded to 4 floats, ``12 * F`` floats read
with three packet gathers and permuted to the ray's axes with selects
(vertices, not edges, because the watertight test needs bitwise identical
shared vertices, see :mod:`drpt.geometry.triangle`); spheres as ``4 * S``
floats ``[c.xyz, r]``. When the scene mixes triangles and spheres, a
per-position uint32 code ``local | is_sphere << 31`` selects the test. Code
for absent primitive kinds is not traced at all. Leaves hold at most 16
primitives (``leaf_size`` is capped there) and BVH positions need 27 bits
(< 134M primitives).
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.llvm import Array3f, Array4f, Array4u, Bool, Float, UInt32

from ..geometry.plane import intersect_plane
from ..geometry.sphere import intersect_sphere
from ..geometry.triangle import RayPrep, watertight_permuted
from .bvh_build import (EMPTY_REF, LEAF_COUNT_SHIFT, LEAF_FLAG, LEAF_MAX_COUNT, LEAF_START_MASK,
                        build_bvh, collapse_bvh4, round_down_f32, round_up_f32)

INVALID = 0xFFFFFFFF
STACK_SIZE = 64  # binary-tree depth cap passed to the builder (the stack is sized per BVH)
_SLAB_EPS = 1.0 + 4.0 * 2.0**-24  # robust slab test (Ize 2013): widen t_far
_INF = float("inf")
_FLT_MAX = 3.4028234663852886e38


class Hit:
    """Closest-hit record (a Dr.Jit PyTree: works with ``dr.select``, loops...)."""

    DRJIT_STRUCT = {"t": Float, "prim": UInt32, "u": Float, "v": Float, "valid": Bool}

    def __init__(self, t=None, prim=None, u=None, v=None, valid=None):
        self.t = t if t is not None else Float(float("inf"))
        self.prim = prim if prim is not None else UInt32(INVALID)
        self.u = u if u is not None else Float(0)
        self.v = v if v is not None else Float(0)
        self.valid = valid if valid is not None else Bool(False)

    def __repr__(self):
        return f"Hit(t={self.t}, prim={self.prim}, u={self.u}, v={self.v}, valid={self.valid})"


def _nbytes(*arrays) -> int:
    n = 0
    for a in arrays:
        if a is not None:
            n += dr.width(a) * (8 if "64" in type(a).__name__ else 4)
    return n


class SceneGeometry:
    """Device copies shared by the accelerators: counts and plane arrays."""

    def __init__(self, scene):
        self.F = len(scene.triangles)
        self.S = len(scene.spheres)
        self.P = len(scene.planes)
        self.N = self.F + self.S
        if self.P:
            n = np.asarray(scene.planes.normal, np.float32)
            self.plane_n = Array3f(n[:, 0], n[:, 1], n[:, 2])
            self.plane_o = Float(np.asarray(scene.planes.offset, np.float32))
        else:
            self.plane_n = self.plane_o = None

    def plane_nbytes(self) -> int:
        return 16 * self.P

    def intersect_planes(self, o, d, bt, bj, any_hit: bool):
        """Test all planes; return updated ``(bt, bj)`` with ``bj = N + k``."""
        if not self.P:
            return bt, bj
        pn, po, N, P = self.plane_n, self.plane_o, self.N, self.P

        def cond(k, bt, bj):
            return k < P

        def body(k, bt, bj):
            n = dr.gather(Array3f, pn, k)
            off = dr.gather(Float, po, k)
            t, h = intersect_plane(o, d, n, off, bt)
            bt = dr.select(h, t, bt)
            bj = dr.select(h, N + k, bj)
            return k + 1, bt, bj

        _, bt, bj = dr.while_loop((UInt32(0), bt, bj), cond, body, label="drpt_planes")
        return bt, bj


def _device(cls, a: np.ndarray):
    """Device array of a numpy array, built from 64-byte aligned host memory.

    Dr.Jit marks an array created from numpy memory that is not suitably
    aligned as *unaligned* (and copies keep that mark); packet gathers
    (``dr.gather(Array4f, ...)``) from it silently fall back to one gather per
    component. numpy only guarantees 16-byte alignment, so the data is first
    placed at a 64-byte boundary.
    """
    a = np.ascontiguousarray(a)
    raw = np.empty(a.nbytes + 64, np.uint8)
    off = (-raw.ctypes.data) % 64
    host = raw[off:off + a.nbytes].view(a.dtype)
    host[:] = a.reshape(-1)
    v = cls(host)
    dr.eval(v)
    return v


def triangle_buffer(positions: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` positions -> flat float32 ``[p0, 0, p1, 0, p2, 0]`` per triangle
    (three 16-byte packets)."""
    p = np.zeros((len(positions), 3, 4), np.float32)
    p[:, :, :3] = np.asarray(positions, np.float32)
    return p.reshape(-1)


def sphere_buffer(center: np.ndarray, radius: np.ndarray) -> np.ndarray:
    c = np.asarray(center, np.float32)
    r = np.asarray(radius, np.float32)[:, None]
    return np.ascontiguousarray(np.concatenate([c, r], 1).reshape(-1))


def triangle_buffer4(positions: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` positions -> flat float32 ``[p0, 0, p1, 0, p2, 0]`` per triangle."""
    p = np.zeros((len(positions), 3, 4), np.float32)
    p[:, :, :3] = np.asarray(positions, np.float32)
    return p.reshape(-1)


def _pick(v, k):
    return dr.select(k == 0, v.x, dr.select(k == 1, v.y, v.z))


def test_triangle(tri_buf, idx, prep: RayPrep, bt, active):
    """Watertight test of triangle ``idx`` of a :func:`triangle_buffer`: three
    packet gathers (one per vertex), permuted to ``prep``'s axes by selects."""
    base = idx * 3
    p = [dr.gather(Array4f, tri_buf, base + k, active) for k in range(3)]
    g = [_pick(q, k) for q in p for k in (prep.kx, prep.ky, prep.kz)]
    t, u, v, h = watertight_permuted(prep, *g, bt)
    return t, u, v, h & active


def test_sphere(sph_buf, idx, o, d, bt, active):
    s = dr.gather(Array4f, sph_buf, idx, active)
    t, h = intersect_sphere(o, d, Array3f(s.x, s.y, s.z), s.w, bt)
    return t, h & active


class BVH:
    """Triangles and spheres of a scene in one BVH; planes tested brute force.

    Args:
        scene: the :class:`~drpt.scene.model.Scene`.
        method: builder split rule (``"sah"``, ``"sah_full"``, ``"median"``).
        leaf_size: maximum primitives per leaf (at most 16).
        bins: SAH bins.

    Attributes:
        build_seconds: host build time (bounds, BVH build and upload).
        nbytes: bytes of device arrays.
        stats: ``nodes``, ``leaves``, ``max_depth``, ... from the builder
            (binary tree), plus ``nodes4`` and ``depth4`` of the 4-wide tree.

    Class attributes: ``traversal_cost`` and ``intersection_cost`` are the SAH
    constants passed to the builder; ``prims_per_iter`` (default 1) is how
    many primitives of the current leaf one loop iteration tests (2 and 3
    measured slower or no faster on the benchmarks, kept for experiments).
    """

    traversal_cost = 1.0
    prims_per_iter = 1
    intersection_cost = 1.0

    def __init__(self, scene, method: str = "sah", leaf_size: int = 4, bins: int = 16):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        F, S, N = geo.F, geo.S, geo.N
        self.has_tris, self.has_spheres = F > 0, S > 0
        self.tri_buf = self.sph_buf = self.codes = None
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": 0}
        if N:
            los, his = [], []
            if F:
                p32 = np.asarray(scene.triangles.positions, np.float32).astype(np.float64)
                los.append(p32.min(1))
                his.append(p32.max(1))
            if S:
                c = np.asarray(scene.spheres.center, np.float64)
                r = np.abs(np.asarray(scene.spheres.radius, np.float64))[:, None]
                pad = r * 1e-5 + np.abs(c) * 1e-6
                los.append(c - r - pad)
                his.append(c + r + pad)
            lo = np.concatenate(los)
            hi = np.concatenate(his)
            b = build_bvh(round_down_f32(lo), round_up_f32(hi), method=method,
                          max_leaf=min(leaf_size, LEAF_MAX_COUNT), bins=bins,
                          max_depth=STACK_SIZE, traversal_cost=self.traversal_cost,
                          intersection_cost=self.intersection_cost)
            self.stats = dict(b.stats)
            order = b.prim_order
            w = collapse_bvh4(b)
            self.stats["nodes4"] = int(w.ref.shape[0])
            self.stats["depth4"] = int(w.depth)
            self.node_box = _device(Float, w.box.reshape(-1))
            self.node_ref = _device(UInt32, w.ref.reshape(-1))
            self.root_lo, self.root_hi = w.root_lo, w.root_hi
            self.stack_size = 3 * w.depth + 4
            self.prim_ids = _device(UInt32, order.astype(np.uint32))
            is_sph = order >= F
            tri_order = order[~is_sph]
            sph_order = order[is_sph] - F
            if F:
                self.tri_buf = _device(Float, triangle_buffer(scene.triangles.positions[tri_order]))
            if S:
                self.sph_buf = _device(Float, sphere_buffer(scene.spheres.center[sph_order],
                                                            scene.spheres.radius[sph_order]))
            if F and S:
                local = np.empty(N, np.int64)
                local[~is_sph] = np.arange(tri_order.size)
                local[is_sph] = np.arange(sph_order.size)
                self.codes = _device(UInt32, (local | (is_sph.astype(np.int64) << 31)).astype(np.uint32))
        else:
            self.node_box = self.node_ref = self.prim_ids = None
        dr.eval(self.node_box, self.node_ref, self.prim_ids, self.tri_buf, self.sph_buf, self.codes)
        self.nbytes = _nbytes(self.node_box, self.node_ref, self.prim_ids, self.tri_buf,
                              self.sph_buf, self.codes) + geo.plane_nbytes()
        self.build_seconds = time.perf_counter() - t0

    # ---------------------------------------------------------------- queries
    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True) -> Hit:
        """Closest hit with ``0 < t < tmax`` (see module docstring)."""
        bt, bj, bu, bv = self._trace(o, d, tmax, active, any_hit=False)
        geo = self.geo
        valid = bj != INVALID
        if geo.N:
            in_bvh = valid & (bj < geo.N)
            prim = dr.select(in_bvh, dr.gather(UInt32, self.prim_ids, bj, in_bvh), bj)
        else:
            prim = bj
        return Hit(dr.select(valid, bt, float("inf")), prim, bu, bv, valid)

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True) -> Bool:
        """Whether anything is hit with ``0 < t < tmax`` (any-hit, early exit)."""
        _, bj, _, _ = self._trace(o, d, tmax, active, any_hit=True)
        return bj != INVALID

    # ------------------------------------------------------------- internals
    def _trace(self, o, d, tmax, active, any_hit: bool):
        o = Array3f(o)
        d = Array3f(d)
        active = Bool(active)
        bt = dr.select(active, Float(tmax), 0.0)
        bj = UInt32(INVALID)
        bu = Float(0)
        bv = Float(0)
        bt, bj = self.geo.intersect_planes(o, d, bt, bj, any_hit)
        if not self.geo.N:
            return bt, bj, bu, bv
        if any_hit:
            active &= bj == INVALID

        inv_d = dr.rcp(d)
        prep = RayPrep(o, d) if self.has_tris else None
        node_box, node_ref = self.node_box, self.node_ref
        tri_buf, sph_buf, codes = self.tri_buf, self.sph_buf, self.codes
        mixed = codes is not None
        ppi = int(self.prims_per_iter)

        # root box (host constants)
        rlo, rhi = self.root_lo, self.root_hi
        ax = (float(rlo[0]) - o.x) * inv_d.x
        bx = (float(rhi[0]) - o.x) * inv_d.x
        ay = (float(rlo[1]) - o.y) * inv_d.y
        by = (float(rhi[1]) - o.y) * inv_d.y
        az = (float(rlo[2]) - o.z) * inv_d.z
        bz = (float(rhi[2]) - o.z) * inv_d.z
        tn = dr.fmax(dr.fmax(dr.fmax(dr.fmin(ax, bx), dr.fmin(ay, by)), dr.fmin(az, bz)), 0.0)
        tf = dr.fmin(dr.fmin(dr.fmax(ax, bx), dr.fmax(ay, by)), dr.fmax(az, bz)) * _SLAB_EPS
        h_root = active & (tn <= tf) & (tn <= bt * _SLAB_EPS)

        cur = dr.select(h_root, UInt32(0), UInt32(INVALID))
        cur_t = Float(0)
        sp = UInt32(0)
        stk_n = dr.alloc_local(UInt32, self.stack_size)
        stk_t = dr.alloc_local(Float, self.stack_size)
        pi = UInt32(0)
        pe = UInt32(0)

        def cond(cur, cur_t, sp, stk_n, stk_t, pi, pe, bt, bj, bu, bv):
            return (pi < pe) | (cur != INVALID) | (sp > 0)

        def body(cur, cur_t, sp, stk_n, stk_t, pi, pe, bt, bj, bu, bv):
            # ---- node phase
            in_leaf = pi < pe
            need_pop = ~in_leaf & (cur == INVALID) & (sp > 0)
            sp = dr.select(need_pop, sp - 1, sp)
            cur = dr.select(need_pop, stk_n.read(sp, need_pop), cur)
            cur_t = dr.select(need_pop, stk_t.read(sp, need_pop), cur_t)
            node_on = ~in_leaf & (cur != INVALID)
            culled = node_on & (cur_t > bt * _SLAB_EPS)
            node_on &= ~culled
            inner = node_on & ((cur & LEAF_FLAG) == 0)
            # four child boxes: six packet gathers of 4 floats (SoA)
            b6 = cur * 6
            lx = dr.gather(Array4f, node_box, b6, inner)
            ly = dr.gather(Array4f, node_box, b6 + 1, inner)
            lz = dr.gather(Array4f, node_box, b6 + 2, inner)
            hx = dr.gather(Array4f, node_box, b6 + 3, inner)
            hy = dr.gather(Array4f, node_box, b6 + 4, inner)
            hz = dr.gather(Array4f, node_box, b6 + 5, inner)
            ref = dr.gather(Array4u, node_ref, cur, inner)
            lim = bt * _SLAB_EPS
            key, val = [], []
            for k in range(4):
                ax = (lx[k] - o.x) * inv_d.x
                bx = (hx[k] - o.x) * inv_d.x
                ay = (ly[k] - o.y) * inv_d.y
                by = (hy[k] - o.y) * inv_d.y
                az = (lz[k] - o.z) * inv_d.z
                bz = (hz[k] - o.z) * inv_d.z
                tn = dr.fmax(dr.fmax(dr.fmax(dr.fmin(ax, bx), dr.fmin(ay, by)),
                                     dr.fmin(az, bz)), 0.0)
                tf = dr.fmin(dr.fmin(dr.fmax(ax, bx), dr.fmax(ay, by)), dr.fmax(az, bz)) * _SLAB_EPS
                h = (tn <= tf) & (tn <= lim) & (ref[k] != EMPTY_REF)
                key.append(dr.select(h, dr.minimum(tn, _FLT_MAX), _INF))
                val.append(ref[k])
            # sorting network: ascending entry distance, misses (inf) last
            for i, j in ((0, 1), (2, 3), (0, 2), (1, 3), (1, 2)):
                sw = key[j] < key[i]
                key[i], key[j] = dr.select(sw, key[j], key[i]), dr.select(sw, key[i], key[j])
                val[i], val[j] = dr.select(sw, val[j], val[i]), dr.select(sw, val[i], val[j])
            # push the farther hits (farthest first), continue with the nearest
            for k in (3, 2, 1):
                m = inner & (key[k] < _INF)
                stk_n.write(val[k], sp, m)
                stk_t.write(key[k], sp, m)
                sp = dr.select(m, sp + 1, sp)
            h0 = key[0] < _INF
            cur = dr.select(inner, dr.select(h0, val[0], UInt32(INVALID)), cur)
            cur_t = dr.select(inner, key[0], cur_t)
            cur = dr.select(culled, UInt32(INVALID), cur)
            # a leaf (popped, or the nearest child just found): load its range
            leaf = node_on & (cur != INVALID) & ((cur & LEAF_FLAG) != 0)
            start = cur & LEAF_START_MASK
            pi = dr.select(leaf, start, pi)
            pe = dr.select(leaf, start + ((cur >> LEAF_COUNT_SHIFT) & 15) + 1, pe)
            cur = dr.select(leaf, UInt32(INVALID), cur)

            # ---- primitive phase: up to prims_per_iter primitives of the leaf
            hit_any = Bool(False)
            for r in range(ppi):
                q = pi + r if r else pi
                pa = q < pe
                if mixed:
                    code = dr.gather(UInt32, codes, q, pa)
                    sph = (code >> 31) != 0
                    idx = code & 0x7FFFFFFF
                    tri_on, sph_on = pa & ~sph, pa & sph
                else:
                    idx = q
                    tri_on = sph_on = pa
                if any_hit and r:
                    tri_on &= ~hit_any
                    sph_on &= ~hit_any
                if tri_buf is not None:
                    t, u, v, h = test_triangle(tri_buf, idx, prep, bt, tri_on)
                    bt = dr.select(h, t, bt)
                    bj = dr.select(h, q, bj)
                    bu = dr.select(h, u, bu)
                    bv = dr.select(h, v, bv)
                    hit_any |= h
                if sph_buf is not None:
                    t, h = test_sphere(sph_buf, idx, o, d, bt, sph_on)
                    bt = dr.select(h, t, bt)
                    bj = dr.select(h, q, bj)
                    bu = dr.select(h, 0.0, bu)
                    bv = dr.select(h, 0.0, bv)
                    hit_any |= h
            pi = dr.minimum(pi + ppi, pe) if ppi > 1 else dr.select(pi < pe, pi + 1, pi)
            if any_hit:
                pe = dr.select(hit_any, pi, pe)
                sp = dr.select(hit_any, 0, sp)
                cur = dr.select(hit_any, UInt32(INVALID), cur)
            return cur, cur_t, sp, stk_n, stk_t, pi, pe, bt, bj, bu, bv

        state = (cur, cur_t, sp, stk_n, stk_t, pi, pe, bt, bj, bu, bv)
        state = dr.while_loop(state, cond, body, label="drpt_bvh")
        bt, bj, bu, bv = state[7:]
        return bt, bj, bu, bv
