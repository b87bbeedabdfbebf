"""Binary BVH ray traversal in Dr.Jit (one symbolic loop, per-lane stack).

The default accelerator is the 4-wide BVH collapsed from this tree
(:mod:`drpt.accel.bvh4`, which reuses this module's queries and leaf step);
this one stays available as ``build_accel(kind="bvh2")`` / ``--accel bvh2``.

:class:`BVH` holds the triangles and spheres of a :class:`~drpt.scene.model.Scene`
in one bounding volume hierarchy (built by :func:`~drpt.accel.build.build_bvh`);
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
Everything happens in one ``dr.while_loop`` (symbolic by default; it also
runs in evaluated mode, following :py:attr:`drjit.JitFlag.SymbolicLoops`).
Each iteration of a lane does, in this order:

1. *node phase* (when the lane is not inside a leaf): pop a node from the
   lane's stack (``dr.alloc_local``, 64 entries; the builder caps the depth
   at 64, and ordered traversal pushes at most one entry per level) unless
   one is current; drop it if its entry distance exceeds the closest hit;
   for an inner node, intersect both children's boxes (adjacent records),
   continue with the nearer one and push the farther one; for a leaf, load
   its primitive range;
2. *primitive phase* (when inside a leaf): test one primitive.

Device data (float32, in BVH order for coherent gathers): node boxes as
``8 * M`` floats ``[lo.xyz, 0, hi.xyz, 0]`` read with two ``Array4f``
gathers; node links as ``2 * M`` uint32 ``[a, count]`` (layout of
:class:`~drpt.accel.tree.BVHArrays`); triangle vertices ``p0, p1, p2`` as
``9 * F`` floats (vertices, not edges, because the watertight test needs
bitwise identical shared vertices, see :mod:`drpt.geometry.triangle`);
spheres as ``4 * S`` floats ``[c.xyz, r]``. When the scene mixes triangles and
spheres, a per-position uint32 code ``local | is_sphere << 31`` selects the
test. Code for absent primitive kinds is not traced at all.
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Array4f, Bool, Float, UInt32

from ..geometry.plane import intersect_plane
from ..geometry.sphere import intersect_sphere
from ..geometry.triangle import RayPrep, watertight_permuted
from .build import build_bvh
from .tree import round_down_f32, round_up_f32

INVALID = 0xFFFFFFFF
STACK_SIZE = 64
_SLAB_EPS = 1.0 + 4.0 * 2.0**-24  # robust slab test (Ize 2013): widen t_far


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


def triangle_buffer(positions: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` positions -> flat float32 ``[p0, p1, p2]`` per triangle."""
    return np.ascontiguousarray(np.asarray(positions, np.float32).reshape(-1))


def sphere_buffer(center: np.ndarray, radius: np.ndarray) -> np.ndarray:
    c = np.asarray(center, np.float32)
    r = np.asarray(radius, np.float32)[:, None]
    return np.ascontiguousarray(np.concatenate([c, r], 1).reshape(-1))


def test_triangle(tri_buf, idx, prep: RayPrep, bt, active):
    """Watertight test of triangle ``idx`` of a flat vertex buffer."""
    base = idx * 9
    g = [
        dr.gather(Float, tri_buf, base + (3 * v) + k, active)
        for v in range(3)
        for k in (prep.kx, prep.ky, prep.kz)
    ]
    t, u, v, h = watertight_permuted(prep, *g, bt)
    return t, u, v, h & active


def test_sphere(sph_buf, idx, o, d, bt, active):
    s = dr.gather(Array4f, sph_buf, idx, active)
    t, h = intersect_sphere(o, d, Array3f(s.x, s.y, s.z), s.w, bt)
    return t, h & active


def nearest_primitive(tri_buf, sph_buf, tri_idx, sph_idx, prim, prep: RayPrep, o, d,
                      tri_on, sph_on, bt, bj, bu, bv, tri_test=None):
    """Test one triangle (lanes ``tri_on``) and/or one sphere (``sph_on``) and
    keep the nearer hit: returns the updated closest-hit record
    ``(bt, bj, bu, bv)`` (``bj = prim`` where a hit was kept) and ``hit_any``.
    Absent buffers trace no code. Shared by every accelerator's loop;
    ``tri_test`` reads the triangle buffer's layout (default
    :func:`test_triangle`, looked up at call time)."""
    hit_any = Bool(False)
    if tri_buf is not None:
        t, u, v, h = (tri_test or test_triangle)(tri_buf, tri_idx, prep, bt, tri_on)
        bt = dr.select(h, t, bt)
        bj = dr.select(h, prim, bj)
        bu = dr.select(h, u, bu)
        bv = dr.select(h, v, bv)
        hit_any |= h
    if sph_buf is not None:
        t, h = test_sphere(sph_buf, sph_idx, o, d, bt, sph_on)
        bt = dr.select(h, t, bt)
        bj = dr.select(h, prim, bj)
        bu = dr.select(h, 0.0, bu)
        bv = dr.select(h, 0.0, bv)
        hit_any |= h
    return bt, bj, bu, bv, hit_any


def leaf_primitive(codes, pi, pa):
    """Buffer index and lane masks (triangle, sphere) of BVH position ``pi``
    (lanes ``pa``): the position itself when the scene has one primitive kind,
    else decoded from ``codes`` (``local index | sphere << 31``,
    :func:`leaf_orders`)."""
    if codes is None:
        return pi, pa, pa
    code = dr.gather(UInt32, codes, pi, pa)
    sph = (code >> 31) != 0
    return code & 0x7FFFFFFF, pa & ~sph, pa & sph


def primitive_bounds(scene, F: int, S: int) -> tuple[np.ndarray, np.ndarray]:
    """Float32 boxes, rounded outward, of a scene's ``F`` triangles then ``S``
    spheres (BVH primitive ids ``0..F+S-1``); spheres padded against round-off."""
    los, his = [], []
    if F:
        p32 = np.asarray(scene.triangles.positions, np.float32)
        # elementwise over the three vertices (a reduction over the middle
        # axis of (F, 3, 3) is ~10x slower); min/max of float32 are exact
        los.append(np.minimum(np.minimum(p32[:, 0], p32[:, 1]), p32[:, 2]).astype(np.float64))
        his.append(np.maximum(np.maximum(p32[:, 0], p32[:, 1]), p32[:, 2]).astype(np.float64))
    if S:
        c = np.asarray(scene.spheres.center, np.float64)
        r = np.abs(np.asarray(scene.spheres.radius, np.float64))[:, None]
        pad = r * 1e-5 + np.abs(c) * 1e-6
        los.append(c - r - pad)
        his.append(c + r + pad)
    return round_down_f32(np.concatenate(los)), round_up_f32(np.concatenate(his))


def leaf_orders(order: np.ndarray, F: int):
    """From the BVH's primitive order (position -> primitive id): the order of
    the triangle buffer, of the sphere buffer, and for scenes with both, the
    per-position code ``local index | sphere << 31`` (else None)."""
    is_sph = order >= F
    tri_order = order[~is_sph]
    sph_order = order[is_sph] - F
    codes = None
    if tri_order.size and sph_order.size:
        local = np.empty(order.size, np.int64)
        local[~is_sph] = np.arange(tri_order.size)
        local[is_sph] = np.arange(sph_order.size)
        codes = (local | (is_sph.astype(np.int64) << 31)).astype(np.uint32)
    return tri_order, sph_order, codes


class BVH:
    """Triangles and spheres of a scene in one BVH; planes tested brute force.

    Args:
        scene: the :class:`~drpt.scene.model.Scene`.
        method: builder split rule (:data:`~drpt.accel.build.METHODS`;
            default ``"auto"``: full SAH, or PLOC above 100k primitives).
        leaf_size: maximum primitives per leaf.
        bins: SAH bins.
        min_leaf: minimum primitives per leaf (the seed's ``-resolution``).
        sah_threshold: ``K`` of ``"threshold"`` (the seed's ``-SAHeuristic``).

    Attributes:
        build_seconds: host build time (bounds, BVH build and upload).
        nbytes: bytes of device arrays.
        stats: ``nodes``, ``leaves``, ``max_depth``, ... from the builder.
    """

    def __init__(self, scene, method: str = "auto", leaf_size: int = 4, bins: int = 16,
                 min_leaf: int = 1, sah_threshold: int | None = None):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        F, S, N = geo.F, geo.S, geo.N
        self.has_tris, self.has_spheres = F > 0, S > 0
        self.tri_buf = self.sph_buf = self.codes = None
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": 0}
        if N:
            lo, hi = primitive_bounds(scene, F, S)
            b = build_bvh(lo, hi, method=method,
                          max_leaf=leaf_size, bins=bins, max_depth=STACK_SIZE,
                          min_leaf=min_leaf, sah_threshold=sah_threshold)
            self.stats = dict(b.stats)
            order = b.prim_order
            M = b.node_a.size
            boxes = np.zeros((M, 8), np.float32)
            boxes[:, 0:3] = b.node_lo
            boxes[:, 4:7] = b.node_hi
            self.node_box = Float(boxes.reshape(-1))
            self.node_ac = UInt32(np.stack([b.node_a, b.node_count], 1).reshape(-1))
            self.prim_ids = UInt32(order.astype(np.uint32))
            tri_order, sph_order, codes = leaf_orders(order, F)
            if F:
                self.tri_buf = Float(triangle_buffer(scene.triangles.positions[tri_order]))
            if S:
                self.sph_buf = Float(sphere_buffer(scene.spheres.center[sph_order],
                                                   scene.spheres.radius[sph_order]))
            if codes is not None:
                self.codes = UInt32(codes)
        else:
            self.node_box = self.node_ac = self.prim_ids = None
        dr.eval(self.node_box, self.node_ac, self.prim_ids, self.tri_buf, self.sph_buf, self.codes)
        self.nbytes = _nbytes(self.node_box, self.node_ac, self.prim_ids, self.tri_buf,
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
    def _begin(self, o, d, tmax, active, any_hit: bool):
        """Start of every query (shared with :class:`~drpt.accel.bvh4.BVH4`):
        the rays as arrays, the planes tested brute force, the best hit so
        far ``bt, bj, bu, bv``, and ``active`` without the rays an any-hit
        query has already answered."""
        o = Array3f(o)
        d = Array3f(d)
        active = Bool(active)
        bt = dr.select(active, Float(tmax), 0.0)
        bj = UInt32(INVALID)
        bt, bj = self.geo.intersect_planes(o, d, bt, bj, any_hit)
        if any_hit:
            active &= bj == INVALID
        return o, d, active, bt, bj, Float(0), Float(0)

    def _trace(self, o, d, tmax, active, any_hit: bool):
        o, d, active, bt, bj, bu, bv = self._begin(o, d, tmax, active, any_hit)
        if not self.geo.N:
            return bt, bj, bu, bv

        inv_d = dr.rcp(d)
        prep = RayPrep(o, d) if self.has_tris else None
        node_box, node_ac = self.node_box, self.node_ac
        tri_buf, sph_buf, codes = self.tri_buf, self.sph_buf, self.codes

        def slab(node, bt, mask):
            lo = dr.gather(Array4f, node_box, node * 2, mask)
            hi = dr.gather(Array4f, node_box, node * 2 + 1, mask)
            ax = (lo.x - o.x) * inv_d.x
            bx = (hi.x - o.x) * inv_d.x
            ay = (lo.y - o.y) * inv_d.y
            by = (hi.y - o.y) * inv_d.y
            az = (lo.z - o.z) * inv_d.z
            bz = (hi.z - o.z) * inv_d.z
            tn = dr.fmax(dr.fmax(dr.fmax(dr.fmin(ax, bx), dr.fmin(ay, by)), dr.fmin(az, bz)), 0.0)
            tf = dr.fmin(dr.fmin(dr.fmax(ax, bx), dr.fmax(ay, by)), dr.fmax(az, bz)) * _SLAB_EPS
            return tn, mask & (tn <= tf) & (tn <= bt * _SLAB_EPS)

        t_root, h_root = slab(UInt32(0), bt, active)
        cur = dr.select(h_root, UInt32(0), UInt32(INVALID))
        cur_t = Float(t_root)
        sp = UInt32(0)
        stk_n = dr.alloc_local(UInt32, STACK_SIZE)
        stk_t = dr.alloc_local(Float, STACK_SIZE)
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
            a = dr.gather(UInt32, node_ac, cur * 2, node_on)
            cnt = dr.gather(UInt32, node_ac, cur * 2 + 1, node_on)
            leaf = node_on & (cnt > 0)
            pi = dr.select(leaf, a, pi)
            pe = dr.select(leaf, a + cnt, pe)
            inner = node_on & (cnt == 0)
            tl, hl = slab(a, bt, inner)
            tr, hr = slab(a + 1, bt, inner)
            both = hl & hr
            l_first = tl <= tr
            far = dr.select(l_first, a + 1, a)
            far_t = dr.select(l_first, tr, tl)
            stk_n.write(far, sp, both)
            stk_t.write(far_t, sp, both)
            sp = dr.select(both, sp + 1, sp)
            go_l = hl & (l_first | ~hr)
            nxt = dr.select(go_l, a, a + 1)
            nxt_t = dr.select(go_l, tl, tr)
            descend = hl | hr
            cur = dr.select(descend, nxt, dr.select(node_on | culled, UInt32(INVALID), cur))
            cur_t = dr.select(descend, nxt_t, cur_t)

            # ---- primitive phase
            pa = pi < pe
            idx, tri_on, sph_on = leaf_primitive(codes, pi, pa)
            bt, bj, bu, bv, hit_any = nearest_primitive(
                tri_buf, sph_buf, idx, idx, pi, prep, o, d, tri_on, sph_on, bt, bj, bu, bv)
            pi = dr.select(pa, pi + 1, pi)
            if any_hit:
                pe = dr.select(hit_any, pi, pe)
                sp = dr.select(hit_any, 0, sp)
                cur = dr.select(hit_any, UInt32(INVALID), cur)
            return cur, cur_t, sp, stk_n, stk_t, pi, pe, bt, bj, bu, bv

        state = (cur, cur_t, sp, stk_n, stk_t, pi, pe, bt, bj, bu, bv)
        state = dr.while_loop(state, cond, body, label="drpt_bvh")
        bt, bj, bu, bv = state[7:]
        return bt, bj, bu, bv
