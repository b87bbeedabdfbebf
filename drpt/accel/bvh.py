"""Binary BVH ray traversal in Dr.Jit (one symbolic loop, per-lane stack).

drpt's own large-scene accelerator is the 4-wide BVH collapsed from the same binary tree
(:mod:`drpt.accel.bvh4`); this one stays available as
``build_accel(kind="bvh2")`` / ``--accel bvh2``.

:class:`BVH` holds the triangles and spheres of a :class:`~drpt.scene.model.Scene`
in one bounding volume hierarchy (built by :func:`~drpt.accel.build.build_bvh`,
any of its split rules); planes are unbounded and are tested by brute force
for every ray, before the traversal, so that a near plane already shortens it
(:class:`~drpt.accel.primitives.SceneGeometry`). Primitive ids and
:class:`~drpt.accel.protocol.Hit` results are those of
:mod:`drpt.accel.protocol`.

Traversal
---------
Everything happens in one ``dr.while_loop`` (symbolic by default; it also
runs in evaluated mode, following :py:attr:`drjit.JitFlag.SymbolicLoops`).
Each iteration of a lane does, in this order:

1. *node phase* (when the lane is not inside a leaf): pop a node from the
   lane's stack (``dr.alloc_local``, 64 entries; the builder caps the depth
   at 64, and ordered traversal pushes at most one entry per level) unless
   one is current; drop it if its entry distance exceeds the closest hit;
   for an inner node, intersect both children's boxes (adjacent records,
   :func:`~drpt.accel.device.slab`), continue with the nearer one and push
   the farther one; for a leaf, load its primitive range;
2. *primitive phase* (when inside a leaf): test one primitive
   (:func:`~drpt.accel.primitives.nearest_primitive`).

Device data (float32, in BVH order for coherent gathers; uploads by
:func:`~drpt.accel.device.device_array`): node boxes as ``8 * M`` floats
``[lo.xyz, 0, hi.xyz, 0]`` read with two ``Array4f`` gathers; node links as
``2 * M`` uint32 ``[a, count]`` (layout of
:class:`~drpt.accel.tree.BVHArrays`); the primitive buffers of
:mod:`drpt.accel.primitives` in BVH order.
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Array4f, Bool, Float, UInt32

from ..geometry.triangle import RayPrep
from .build import build_bvh
from .device import SLAB_EPS, device_array, nbytes
from .device import slab as box_slab
from .primitives import SceneGeometry, leaf_primitive, nearest_primitive, primitive_bounds
from .protocol import INVALID, AccelParams, Hit

STACK_SIZE = 64


class BVH:
    """Triangles and spheres of a scene in one binary BVH; planes tested brute force.

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
        geo: the :class:`~drpt.accel.primitives.SceneGeometry` (planes and
            primitive buffers in BVH order).
    """

    coherent_gain = True  # (a traversal: protocol.Accelerator)

    def __init__(self, scene, method: str = "auto", leaf_size: int = 4, bins: int = 16,
                 min_leaf: int = 1, sah_threshold: int | None = None):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        F, S, N = geo.F, geo.S, geo.N
        self.has_tris, self.has_spheres = F > 0, S > 0
        self.node_box = self.node_ac = None
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": 0}
        if N:
            lo, hi = primitive_bounds(scene, F, S)
            b = build_bvh(lo, hi, method=method,
                          max_leaf=leaf_size, bins=bins, max_depth=STACK_SIZE,
                          min_leaf=min_leaf, sah_threshold=sah_threshold)
            self.stats = dict(b.stats)
            M = b.node_a.size
            boxes = np.zeros((M, 8), np.float32)
            boxes[:, 0:3] = b.node_lo
            boxes[:, 4:7] = b.node_hi
            self.node_box = device_array(Float, boxes)
            self.node_ac = device_array(UInt32, np.stack([b.node_a, b.node_count], 1))
            geo.upload_primitives(scene, b.prim_order)
        self.nbytes = nbytes(self.node_box, self.node_ac) + geo.nbytes()
        self.build_seconds = time.perf_counter() - t0

    @classmethod
    def from_params(cls, scene, p: AccelParams) -> BVH:
        """The registry's constructor (:mod:`drpt.accel.registry`)."""
        return cls(scene, method=p.method, leaf_size=p.leaf_size, bins=p.bins,
                   min_leaf=p.min_leaf, sah_threshold=p.sah_threshold)

    # ---------------------------------------------------------------- queries
    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                  coherent: Bool | bool = False) -> Hit:
        """Closest hit with ``0 < t < tmax``."""
        return self.geo.hit(*self._trace(o, d, tmax, active, any_hit=False))

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                 coherent: Bool | bool = False) -> Bool:
        """Whether anything is hit with ``0 < t < tmax`` (any-hit, early exit)."""
        _, bj, _, _ = self._trace(o, d, tmax, active, any_hit=True)
        return bj != INVALID

    # ------------------------------------------------------------- internals
    def _trace(self, o, d, tmax, active, any_hit: bool):
        o, d, active, bt, bj, bu, bv = self.geo.begin_query(o, d, tmax, active, any_hit)
        if not self.geo.N:
            return bt, bj, bu, bv

        inv_d = dr.rcp(d)
        prep = RayPrep(o, d) if self.has_tris else None
        node_box, node_ac = self.node_box, self.node_ac
        tri_buf, sph_buf, codes = self.geo.tri_buf, self.geo.sph_buf, self.geo.codes

        def slab(node, bt, mask):
            lo = dr.gather(Array4f, node_box, node * 2, mask)
            hi = dr.gather(Array4f, node_box, node * 2 + 1, mask)
            tn, tf = box_slab(lo, hi, o, inv_d)
            return tn, mask & (tn <= tf) & (tn <= bt * SLAB_EPS)

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
            culled = node_on & (cur_t > bt * SLAB_EPS)
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
