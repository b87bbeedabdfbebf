"""A light BVH: an emitter chosen by its importance at the shading point.

Modelled on pbrt-v4's ``BVHLightSampler`` and Cycles' light tree: every node of a
binary tree over the emitters bounds its emitters' positions (a bounding sphere),
the directions they emit in (a cone: axis ``w``, spread ``theta_o`` of the normals
and ``theta_e`` of the emission about a normal) and their total power ``phi``. From
a reference point ``p`` (with, optionally, its surface normal ``n``) a node's
*importance* is an upper estimate of what its emitters send there::

    phi * cos(theta') / d^2   (times cos(theta_i') when n is given)

with ``d`` the distance to the node's center (at least its radius), ``theta'`` the
smallest angle between the node's cone and the direction toward ``p`` (the cone
widened by the angle the node's sphere subtends from ``p``; 0 beyond ``theta_e``)
and ``theta_i'`` the same for ``n``. :meth:`LightBVH.sample` walks from the root to
a leaf, choosing each child with probability proportional to its importance and
rescaling ``u`` to the chosen interval; the product of those probabilities is the
emitter's probability ``pmf``. :meth:`LightBVH.pmf` recomputes it for a given
emitter by following its *bit trail* (its leaf's path: bit ``l`` is the branch at
depth ``l``), so that MIS can weigh an emitter that a BSDF sample hit. An emitter
whose importance is zero at ``p`` (behind it, outside its emission cone) is never
chosen there and has ``pmf`` 0; where every emitter's is zero, sampling fails
(index 0, ``pmf`` 0).

The tree is built on the host (numpy) and is *balanced*: each node splits its
emitters at the median of their centers along the longest axis of their bounds,
``ceil(c/2)`` to the left, so every leaf is at depth ``D = ceil(log2 N)``, the
nodes are stored level by level in heap order (node ``k``'s children are ``2k + 1``
and ``2k + 2``; leaf slot ``s`` is node ``2^D - 1 + s``) and a leaf's slot is its
bit trail. Slots a level has no emitter for are empty nodes of zero power
(importance 0). On the device both walks are one ``dr.while_loop`` of exactly
``D`` steps over the flattened node arrays. The split is by count rather than by
pbrt's surface-area-orientation cost: it keeps the layout implicit and the build
vectorized (one sort per level), and the importance at each node, not the tree's
shape, decides the probabilities.

The device API: ``sample(u, p, n, active) -> (index, pmf)`` and ``pmf(index, p, n,
active)``, ``index`` being the emitter's position in the arrays given to the
constructor.

:class:`BVHSelection` is ``--light-sampler bvh``: a spatially varying
:class:`~drpt.render.lights.selection.LightSelection` (``static`` False) whose BVH
covers the slots of the area family (:func:`area_light_bvh`: emissive triangles and
spheres). The other slots (delta lights, the sky, further families) keep the
probabilities the ``mixed`` rule gives them over all slots, and the area slots share
the rest, ``P_area``, by the BVH: ``P(k | p) = P_area * pmf_BVH(k | p)``. pbrt-v4
instead gives each infinite light the probability of one light and the whole BVH the
probability of one more; the ``mixed`` rule keeps what ``mixed`` and ``bvh`` render
alike where the BVH does not enter (delta lights, the sky) and lets a bright sky
or sun take more than that share. No surface normal enters the importance:
:meth:`~drpt.render.scene.DeviceScene.pdf_emitter` evaluates the probability at the
path's previous vertex, where next-event estimation sampled from (path, wavefront, volpath
pass it; without it, the point the ray left from, ``si.p - d * si.t``), and the path state
carries no normal there.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Array4f, Bool, Float, UInt32

from ...accel.device import device_array
from .selection import LightSelection

ONE_MINUS_EPS = 0.99999994


# ------------------------------------------------------------------ host side
def union_cones(wa: np.ndarray, ca: np.ndarray, wb: np.ndarray, cb: np.ndarray):
    """The smallest cone (as pbrt's ``DirectionCone::Union``, vectorized) holding the
    cones of axes ``wa``, ``wb`` (unit, ``(m, 3)``) and cosines of half-angles ``ca``,
    ``cb``: ``(w, cos)``; ``cos = -1`` is the whole sphere."""
    ta = np.arccos(np.clip(ca, -1.0, 1.0))
    tb = np.arccos(np.clip(cb, -1.0, 1.0))
    dot = np.clip(np.einsum("ij,ij->i", wa, wb), -1.0, 1.0)
    td = np.arccos(dot)
    a_holds = np.minimum(td + tb, np.pi) <= ta
    b_holds = ~a_holds & (np.minimum(td + ta, np.pi) <= tb)
    to = 0.5 * (ta + td + tb)
    perp = wb - dot[:, None] * wa
    plen = np.linalg.norm(perp, axis=1)
    whole = (to >= np.pi) | (plen < 1e-12)
    tr = to - ta
    w = (np.cos(tr)[:, None] * wa
         + np.sin(tr)[:, None] * perp / np.where(plen > 0, plen, 1.0)[:, None])
    w = w / np.maximum(np.linalg.norm(w, axis=1), 1e-300)[:, None]
    c = np.where(whole, -1.0, np.cos(np.minimum(to, np.pi)))
    w = np.where(whole[:, None], wa, w)
    w = np.where(a_holds[:, None], wa, np.where(b_holds[:, None], wb, w))
    c = np.where(a_holds, ca, np.where(b_holds, cb, c))
    return w, c


def leaf_slots(centers: np.ndarray) -> tuple[int, np.ndarray]:
    """``(D, slot)``: the depth of the balanced tree over ``m`` points and each
    point's leaf slot in ``[0, 2^D)``, by median splits along the longest axis of
    each node's bounds of the points (``ceil(c/2)`` to the left child)."""
    m = len(centers)
    depth = max(0, math.ceil(math.log2(m))) if m > 1 else 0
    seg = np.zeros(m, np.int64)  # each point's node at the current level
    order = np.arange(m)  # the points sorted by node (kept so from level to level)
    idx = np.arange(m)
    for level in range(depth):
        nseg = 1 << level
        s_sorted = seg[order]
        counts = np.bincount(s_sorted, minlength=nseg)
        starts = np.cumsum(counts) - counts
        nonempty = counts > 0
        c_sorted = centers[order]
        lo = np.zeros((nseg, 3))
        hi = np.zeros((nseg, 3))
        lo[nonempty] = np.minimum.reduceat(c_sorted, starts[nonempty], axis=0)
        hi[nonempty] = np.maximum.reduceat(c_sorted, starts[nonempty], axis=0)
        axis = np.argmax(hi - lo, axis=1)
        # within each node by the coordinate along its longest axis, scaled into [0, 0.5]:
        # one sort of node + that fraction orders by node, then by coordinate
        a = axis[s_sorted]
        lo_a, ext = lo[s_sorted, a], (hi - lo)[s_sorted, a]
        frac = 0.5 * (c_sorted[idx, a] - lo_a) / np.where(ext > 0, ext, 1.0)
        order = order[np.argsort(s_sorted + frac, kind="stable")]
        s_sorted = seg[order]
        rank = idx - starts[s_sorted]
        left = (counts + 1) // 2
        seg[order] = 2 * s_sorted + (rank >= left[s_sorted])
    return depth, seg


class LightBVH:
    """The tree over ``m`` emitters, each given by its bounds ``lo``, ``hi`` (``(m, 3)``),
    the axis ``w`` (unit, ``(m, 3)``) and cosine ``cos_o`` of the cone of its normals,
    the cosine ``cos_e`` of its emission's spread about a normal (0: a one-sided
    Lambertian emitter) and its power ``phi`` (any common unit; > 0)."""

    def __init__(self, lo, hi, w, cos_o, cos_e, phi):
        lo, hi = np.asarray(lo, float).reshape(-1, 3), np.asarray(hi, float).reshape(-1, 3)
        m = len(lo)
        if m == 0:
            raise ValueError("a light BVH needs at least one emitter")
        self.count = m
        self.depth, slot = leaf_slots(0.5 * (lo + hi))
        n_leaf = 1 << self.depth
        # level D: the emitters in their slots (empty slots: no power, inverted bounds)
        L_lo = np.full((n_leaf, 3), np.inf)
        L_hi = np.full((n_leaf, 3), -np.inf)
        L_w = np.tile([0.0, 0.0, 1.0], (n_leaf, 1))
        L_co = np.ones(n_leaf)
        L_ce = np.ones(n_leaf)
        L_phi = np.zeros(n_leaf)
        L_lo[slot], L_hi[slot] = lo, hi
        L_w[slot] = np.asarray(w, float).reshape(-1, 3)
        L_co[slot] = np.asarray(cos_o, float)
        L_ce[slot] = np.asarray(cos_e, float)
        L_phi[slot] = np.asarray(phi, float)
        levels = [(L_lo, L_hi, L_w, L_co, L_ce, L_phi)]
        while len(levels[-1][0]) > 1:  # up to the root: children 2i, 2i+1 of level l+1
            b_lo, b_hi, b_w, b_co, b_ce, b_phi = levels[-1]
            a, b = slice(0, None, 2), slice(1, None, 2)
            ea, eb = b_phi[a] <= 0, b_phi[b] <= 0
            w_u, c_u = union_cones(b_w[a], b_co[a], b_w[b], b_co[b])
            w_u = np.where(ea[:, None], b_w[b], np.where(eb[:, None], b_w[a], w_u))
            c_u = np.where(ea, b_co[b], np.where(eb, b_co[a], c_u))
            ce = np.where(ea, b_ce[b], np.where(eb, b_ce[a], np.minimum(b_ce[a], b_ce[b])))
            levels.append((np.minimum(b_lo[a], b_lo[b]), np.maximum(b_hi[a], b_hi[b]),
                           w_u, c_u, ce, b_phi[a] + b_phi[b]))
        levels.reverse()  # root first: heap order
        N_lo, N_hi, N_w, N_co, N_ce, N_phi = (np.concatenate(x) for x in zip(*levels))
        empty = N_phi <= 0
        N_lo[empty], N_hi[empty] = 0.0, 0.0
        center = 0.5 * (N_lo + N_hi)
        radius = 0.5 * np.linalg.norm(N_hi - N_lo, axis=1)
        self.nodes = len(N_phi)
        #: per emitter: its leaf slot (the bit trail, most significant bit = the root's branch)
        self.slot = slot

        # one record of 12 floats per node, read with three packet gathers:
        # (center, radius), (cone axis, cos theta_o), (cos theta_e, power, sin theta_o, 0); the
        # radius rounded up so that float32 bounds still hold the emitters, the power
        # relative to the root's, so that importances stay in float32's range
        rec = np.zeros((self.nodes, 12))
        rec[:, 0:3] = center
        rec[:, 3] = radius * (1 + 1e-6) + 1e-7 * np.abs(center).max(axis=1)
        rec[:, 4:7] = N_w
        rec[:, 7] = N_co
        rec[:, 8] = N_ce
        rec[:, 9] = N_phi / max(N_phi[0], 1e-300)
        rec[:, 10] = np.sqrt(np.maximum(1.0 - N_co * N_co, 0.0))
        # aligned: Dr.Jit reads an unaligned array's Array4f gathers one float at a time
        self._rec = device_array(Float, rec.astype(np.float32))
        item = np.zeros(n_leaf, np.uint32)
        item[slot] = np.arange(m, dtype=np.uint32)
        self._item = UInt32(item)
        self._slot = UInt32(slot.astype(np.uint32))

    # -------------------------------------------------------------- device side
    def importance(self, node: UInt32, p: Array3f, n: Array3f | None, active: Bool) -> Float:
        """The importance of ``node`` seen from ``p`` (normal ``n`` or None)."""
        a = dr.gather(Array4f, self._rec, 3 * node, active)
        b = dr.gather(Array4f, self._rec, 3 * node + 1, active)
        e = dr.gather(Array4f, self._rec, 3 * node + 2, active)
        c, r = Array3f(a.x, a.y, a.z), a.w
        w, cos_o = Array3f(b.x, b.y, b.z), b.w
        cos_e, phi, sin_o = e.x, e.y, e.z
        dv = p - c
        d2 = dr.squared_norm(dv)
        r2 = r * r
        wi = dv * dr.rsqrt(dr.maximum(d2, 1e-30))
        cos_w = dr.dot(w, wi)
        sin_w = dr.safe_sqrt(1.0 - cos_w * cos_w)
        # the cone of directions toward the node's sphere (the whole sphere from inside)
        inside = d2 <= r2
        sin2_b = dr.minimum(r2 / dr.maximum(d2, 1e-30), 1.0)
        cos_b = dr.select(inside, -1.0, dr.safe_sqrt(1.0 - sin2_b))
        sin_b = dr.select(inside, 0.0, dr.sqrt(sin2_b))
        # theta' = max(0, theta_w - theta_o - theta_b), as cosines and sines
        within_o = cos_w > cos_o
        cos_x = dr.select(within_o, 1.0, cos_w * cos_o + sin_w * sin_o)
        sin_x = dr.select(within_o, 0.0, sin_w * cos_o - cos_w * sin_o)
        cos_p = dr.select(cos_x > cos_b, 1.0, cos_x * cos_b + sin_x * sin_b)
        imp = phi * cos_p / dr.maximum(d2, r2)
        if n is not None:
            cos_i = dr.abs(dr.dot(wi, n))
            sin_i = dr.safe_sqrt(1.0 - cos_i * cos_i)
            imp *= dr.select(cos_i > cos_b, 1.0, cos_i * cos_b + sin_i * sin_b)
        ok = active & (phi > 0.0) & (cos_p > cos_e)
        return dr.select(ok, dr.maximum(imp, 0.0), 0.0)

    def _children(self, node: UInt32, p: Array3f, n, active: Bool):
        left = 2 * node + 1
        i0 = self.importance(left, p, n, active)
        i1 = self.importance(left + 1, p, n, active)
        return left, i0, i1

    def sample(self, u: Float, p: Array3f, n: Array3f | None = None,
               active: Bool | None = None) -> tuple[UInt32, Float]:
        """An emitter chosen from ``u`` in [0, 1) by importance at ``p`` (normal ``n``):
        ``(index, pmf)``; ``pmf`` 0 where no emitter has importance."""
        width = max(dr.width(u), dr.width(p))
        if active is None:
            active = dr.full(Bool, True, width)
        node = dr.zeros(UInt32, width)
        pmf = dr.full(Float, 1.0, width)
        ok = Bool(active) | dr.zeros(Bool, width)
        u = Float(u) + dr.zeros(Float, width)
        if self.depth:
            def body(step, node, u, pmf, ok):
                left, i0, i1 = self._children(node, p, n, ok)
                total = i0 + i1
                ok = ok & (total > 0.0)
                p0 = i0 / dr.maximum(total, 1e-38)
                go_left = u < p0
                u = dr.select(go_left, u / dr.maximum(p0, 1e-38),
                              (u - p0) / dr.maximum(1.0 - p0, 1e-38))
                u = dr.clip(u, 0.0, ONE_MINUS_EPS)
                pmf *= dr.select(go_left, i0, i1) / dr.maximum(total, 1e-38)
                node = dr.select(go_left, left, left + 1)
                return step + 1, node, u, pmf, ok

            depth = self.depth
            _, node, u, pmf, ok = dr.while_loop(
                (dr.zeros(UInt32, width), node, u, pmf, ok),
                lambda step, node, u, pmf, ok: (step < depth) & ok, body,
                label="drpt_light_bvh_sample")
        slot = node - ((1 << self.depth) - 1)
        index = dr.gather(UInt32, self._item, slot, ok)
        return dr.select(ok, index, 0), dr.select(ok, pmf, 0.0)

    def pmf(self, index: UInt32, p: Array3f, n: Array3f | None = None,
            active: Bool | None = None) -> Float:
        """The probability with which :meth:`sample` at ``p`` (normal ``n``) picks
        emitter ``index``."""
        width = max(dr.width(index), dr.width(p))
        if active is None:
            active = dr.full(Bool, True, width)
        ok = Bool(active) | dr.zeros(Bool, width)
        slot = dr.gather(UInt32, self._slot, index, ok)
        pmf = dr.select(ok, 1.0, 0.0) + dr.zeros(Float, width)
        if self.depth:
            top = self.depth - 1

            def body(step, node, pmf):
                left, i0, i1 = self._children(node, p, n, ok)
                total = i0 + i1
                right = ((slot >> (top - step)) & 1) == 1
                pmf *= dr.select(total > 0.0, dr.select(right, i1, i0) / dr.maximum(total, 1e-38), 0.0)
                return step + 1, dr.select(right, left + 1, left), pmf

            depth = self.depth
            _, _, pmf = dr.while_loop(
                (dr.zeros(UInt32, width), dr.zeros(UInt32, width), pmf),
                lambda step, *_: (step < depth) & ok, body, label="drpt_light_bvh_pmf")
        return dr.select(ok, pmf, 0.0)


# ------------------------------------------------------------------ area emitters
def area_light_bvh(scene, ids: np.ndarray, n_tri: int, area: np.ndarray, lum: np.ndarray) -> LightBVH:
    """The light BVH over the primitives ``ids`` of ``scene`` (triangles, then spheres
    from ``n_tri``; item ``k`` is ``ids[k]``; ``area`` and luminance ``lum`` per
    primitive): a triangle's bounds, the cone of its normals (geometric and shading)
    and power ``area * lum``; a sphere's bounds, every direction, and the power of its
    cross-section ``pi r^2 lum`` (what any direction sees of it)."""
    tris, sph = scene.triangles, scene.spheres
    m = len(ids)
    lo, hi = np.zeros((m, 3)), np.zeros((m, 3))
    w = np.tile([0.0, 0.0, 1.0], (m, 1))
    cos_o = np.full(m, -1.0)
    phi = area[ids] * lum[ids]
    is_tri = ids < n_tri
    t = ids[is_tri]
    if t.size:
        p = tris.positions[t]
        lo[is_tri], hi[is_tri] = p.min(axis=1), p.max(axis=1)
        ng = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        ng /= np.maximum(np.linalg.norm(ng, axis=1), 1e-300)[:, None]
        dirs = ng[:, None, :]
        if tris.normals is not None:
            sn = tris.normals[t]
            sn = sn / np.maximum(np.linalg.norm(sn, axis=2), 1e-300)[:, :, None]
            dirs = np.concatenate([dirs, sn], axis=1)
        axis = dirs.sum(axis=1)
        alen = np.linalg.norm(axis, axis=1)
        axis = np.where(alen[:, None] > 1e-9, axis / np.maximum(alen, 1e-300)[:, None], ng)
        c = np.einsum("fkj,fj->fk", dirs, axis).min(axis=1)
        w[is_tri] = axis
        # a cone of half-angle >= 90 degrees would not hold the normals between them
        cos_o[is_tri] = np.where((alen > 1e-9) & (c > 1e-3), np.clip(c, -1.0, 1.0) * (1 - 1e-6), -1.0)
    s = ids[~is_tri] - n_tri
    if s.size:
        ctr, r = np.asarray(sph.center, float)[s], np.asarray(sph.radius, float)[s]
        lo[~is_tri], hi[~is_tri] = ctr - r[:, None], ctr + r[:, None]
        phi[~is_tri] = np.pi * r * r * lum[ids[~is_tri]]
    return LightBVH(lo, hi, w, cos_o, np.zeros(m), phi)


# ------------------------------------------------------------------ the selection
class BVHSelection:
    """``--light-sampler bvh``: the slots of ``families`` (as
    :class:`~drpt.render.lights.selection.LightSelection` numbers them), those of the
    family ``area`` chosen by ``bvh`` (item ``k``: the family's slot ``k``) at the
    reference point, the others by the ``mixed`` rule (module docstring)."""

    static = False
    rule = "bvh"

    def __init__(self, families: list, area, bvh: LightBVH):
        base = LightSelection(families, "mixed")
        self.families, self.offsets, self.count = base.families, base.offsets, base.count
        self.bvh = bvh
        i = next(j for j, f in enumerate(self.families) if f is area)
        self.area_offset, self.area_count = self.offsets[i], area.count
        lo, n = self.area_offset, self.area_count
        #: each slot's probability without a reference point: the area slots' are
        #: ``P_area`` times their ``mixed`` share (for tests and tools)
        self.probabilities = base.probabilities
        self.p_area = float(base.probabilities[lo:lo + n].sum())
        # the groups the first choice is among: the other slots and one for the BVH
        group_w = np.concatenate([base.probabilities[:lo], [self.p_area], base.probabilities[lo + n:]])
        self.groups = len(group_w)
        if self.groups > 1:
            cdf = np.cumsum(group_w) / group_w.sum()
            cdf[-1] = 1.0
            self._cdf = Float(cdf.astype(np.float32))
            # per slot: its probability, P_area for the area slots (times the BVH's pmf)
            slot_p = base.probabilities.copy()
            slot_p[lo:lo + n] = self.p_area
            self._pmf = Float(slot_p.astype(np.float32))

    def family_probabilities(self, i: int) -> np.ndarray:
        """The probabilities of family ``i``'s slots without a reference point."""
        o = self.offsets[i]
        return self.probabilities[o:o + self.families[i].count]

    def sample(self, u: Float, ref: Array3f, active=True) -> tuple[UInt32, Float]:
        """A slot for each lane from ``u`` in [0, 1) at ``ref``, and its probability
        (0 where the BVH finds no area emitter with importance at ``ref``)."""
        if self.groups == 1:
            return self.bvh.sample(u, ref, None, Bool(active))
        cdf, n, lo = self._cdf, self.groups, self.area_offset
        g = dr.binary_search(0, n - 1, lambda i: dr.gather(Float, cdf, i) <= u)
        g = dr.minimum(g, n - 1)
        in_area = Bool(active) & (g == lo)
        c_hi = dr.gather(Float, cdf, g, active)
        c_lo = dr.select(g > 0, dr.gather(Float, cdf, dr.maximum(g, 1) - 1, Bool(active) & (g > 0)), 0.0)
        u_area = dr.clip((u - c_lo) / dr.maximum(c_hi - c_lo, 1e-30), 0.0, ONE_MINUS_EPS)
        kb, pb = self.bvh.sample(u_area, ref, None, in_area)
        k = dr.select(g > lo, g + (self.area_count - 1), g)
        k = dr.select(in_area, kb + lo, k)
        pmf = dr.gather(Float, self._pmf, k, active)
        return k, dr.select(in_area, pmf * pb, pmf)

    def pmf(self, index: UInt32, ref: Array3f, active=True) -> Float:
        """The probability that :meth:`sample` at ``ref`` returns slot ``index``."""
        lo = self.area_offset
        if self.groups == 1:
            return self.bvh.pmf(index, ref, None, Bool(active) & (index < self.area_count))
        active = Bool(active) & (index < self.count)
        in_area = active & (index >= lo) & (index < lo + self.area_count)
        pb = self.bvh.pmf(dr.select(in_area, index - lo, 0), ref, None, in_area)
        pmf = dr.gather(Float, self._pmf, index, active)
        return dr.select(in_area, pmf * pb, pmf)
