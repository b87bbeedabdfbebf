"""4-wide BVH, drpt's own accelerator (``--accel auto``'s choice on the CUDA
backend and where Embree is missing, :mod:`drpt.accel.embree`): the binary BVH
collapsed to four children per node, traversed in Dr.Jit.

:class:`BVH4` has the interface of every accelerator
(:class:`~drpt.accel.protocol.Accelerator`): ``intersect(o, d, tmax, active) -> Hit``
and ``occluded(o, d, tmax, active) -> Bool`` over the global primitive ids, planes
tested brute force before the traversal by its
:class:`~drpt.accel.primitives.SceneGeometry`. It builds the binary tree with
:func:`~drpt.accel.build.build_bvh` (all its split rules) and collapses it
(:func:`~drpt.accel.bvh4_nodes.collapse_bvh4`, node layout in
:mod:`drpt.accel.bvh4_nodes`), which halves the number of loop iterations spent in
inner nodes and tests four child boxes per iteration.

Traversal
---------
One ``dr.while_loop`` per query (symbolic by default; it also runs in evaluated
mode, following :py:attr:`drjit.JitFlag.SymbolicLoops`). The root box is tested
before the loop. Each iteration of a lane does, in this order:

1. *node phase* (when the lane is not inside a leaf): pop a node reference from
   the lane's stack unless one is current. For an inner node, fetch the four child
   boxes and the four child references with seven 16-byte packet gathers from the
   node's 128-byte record (:func:`~drpt.accel.bvh4_nodes.node_records`), slab-test
   all four, sort the hits by entry distance (5-comparator network, misses last),
   push the farther hits (farthest first) and continue with the nearest. If the
   entry in hand is a leaf (popped, or the nearest child just found), load its
   primitive range right away;
2. *primitive phase* (when inside a leaf): test the leaf's next ``LEAF_STEP`` (2)
   primitives, one after the other (a lane with fewer left tests them under a mask).

Why it is built this way (each choice measured against its alternative in one
process; the figures are in docs/performance.md, "4-wide BVH"):

* each phase is a symbolic ``dr.if_stmt``, which the LLVM backend compiles to a
  real branch taken when any lane of the SIMD packet needs it: a packet whose lanes
  are all inside leaves skips the node phase, one with no lane in a leaf skips the
  primitive test;
* two primitives per leaf iteration: fewer iterations than one, while three or
  four leave lanes in short leaves idle through the longer step;
* one 128-byte node record read, rather than boxes and references in separate
  arrays (two cache lines per node instead of three);
* children are pushed only when their box starts before the closest hit so far;
  popped entries are not checked again against a closer hit found since (that
  would need their entry distances on a second stack, which cost more than the
  nodes it skipped);
* the stack's newest entry is kept in a register (``top``), the older ones in
  ``dr.alloc_local`` arrays, so a node with one or two hit children beyond the
  nearest pushes and later pops one entry fewer through memory;
* every read and write of a local array with per-lane indices is a masked packet
  gather or scatter, paid even when its mask is empty; each one is therefore a
  symbolic if, taken only when some lane of the packet uses that array
  (:func:`_push`, :func:`_pop`).

Stack size: a lane at a node of depth ``k`` (root = 0) holds at most three
entries per ancestor level, and a push round adds at most three, so
``3 * (depth4 + 1)`` entries suffice; :func:`stack_entries` adds one spare. The
stack is split into ``dr.alloc_local`` arrays of at most ``local_chunk`` entries
(:class:`drpt.backend.Policy`, read at trace time; 16 on both backends): larger
per-lane local arrays crash Dr.Jit 1.5's LLVM backend sporadically (SIGSEGV at a
garbage node index in a worker thread; cf. Dr.Jit issues #532 and #446; the
evidence is in docs/performance.md), and ``DRPT_STRESS=1 pytest
tests/accel/test_bvh4.py`` runs the reproducer. ``BVH4.track_stack`` records the
largest stack pointer of each query (tests). Every loop variable starts full
width (``dr.zeros(T, n)``): Dr.Jit 1.5 renders ``Local.write`` with a size-1 index
in a symbolic loop as one uniform store, and a stack pointer created as
``UInt32(0)`` would lose entries (docs/architecture.md, "Dr.Jit 1.5 pitfalls").

Device data (float32 or uint32, in BVH order, uploaded 64-byte aligned and
zero padded by :func:`~drpt.accel.device.device_array` so that Dr.Jit emits
packet gathers): the node records of :mod:`drpt.accel.bvh4_nodes` (32 words
per node: 24 box floats, 4 references read as float bits and reinterpreted,
4 zero); triangle vertices ``p0, p1, p2`` padded
to 4 floats, ``12 * F`` floats read with three packet gathers and permuted
to the ray's axes with selects (:func:`triangle_buffer4`; vertices, not
edges: the watertight test needs bitwise identical shared vertices, see
:mod:`drpt.geometry.triangle`); the spheres and, for mixed scenes, the
per-position codes of :mod:`drpt.accel.primitives`.
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Array4f, Array4u, Bool, Float, UInt32

from .. import backend
from ..geometry.triangle import RayPrep, watertight_permuted
from .build import build_bvh
from .bvh import STACK_SIZE
from .bvh4_nodes import (
    EMPTY_REF,
    LEAF_COUNT_SHIFT,
    LEAF_FLAG,
    LEAF_MAX_COUNT,
    LEAF_START_MASK,
    RECORD_WORDS,
    collapse_bvh4,
    node_records,
)
from .device import SLAB_EPS, device_array, nbytes, slab
from .primitives import SceneGeometry, leaf_primitive, nearest_primitive, primitive_bounds
from .protocol import INVALID, AccelParams, Hit

_INF = float("inf")
LEAF_STEP = 2  # primitives tested per loop iteration inside a leaf (module docstring)
_FLT_MAX = 3.4028234663852886e38


# ------------------------------------------------------------------ triangles
def triangle_buffer4(positions: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` positions -> flat float32 ``[p0, 0, p1, 0, p2, 0]`` per
    triangle (three 16-byte packets)."""
    p = np.zeros((len(positions), 3, 4), np.float32)
    p[:, :, :3] = np.asarray(positions, np.float32)
    return p.reshape(-1)


def _pick(v, k):
    return dr.select(k == 0, v.x, dr.select(k == 1, v.y, v.z))


def test_triangle4(tri_buf, idx, prep: RayPrep, bt, active):
    """Watertight test of triangle ``idx`` of a :func:`triangle_buffer4`:
    three packet gathers (one per vertex), permuted to ``prep``'s axes."""
    base = idx * 3
    p = [dr.gather(Array4f, tri_buf, base + k, active) for k in range(3)]
    g = [_pick(q, k) for q in p for k in (prep.kx, prep.ky, prep.kz)]
    t, u, v, h = watertight_permuted(prep, *g, bt)
    return t, u, v, h & active


# ------------------------------------------------------------------ stack
def stack_entries(depth4: int) -> int:
    """Per-lane stack entries that a 4-wide tree of depth ``depth4`` needs
    (see the module docstring), plus one spare."""
    return 3 * (int(depth4) + 1) + 1


def _chunk_index(sp, m, c, n_chunks, chunk):
    if n_chunks == 1:
        return sp, m
    mc = m & ((sp // chunk) == c)
    return dr.select(mc, sp - c * chunk, 0), mc


def _pop(stk, sp, m, chunk):
    """Entry ``sp`` (lanes ``m``) of a stack split into ``chunk``-entry
    local arrays. A read with per-lane indices is a masked packet gather whose
    cost is paid even when no lane is in the mask, so each array is read in a
    symbolic if, taken only when some lane of the packet pops from it."""
    out = dr.zeros(UInt32, dr.width(sp))
    for c, arr in enumerate(stk):
        i, mc = _chunk_index(sp, m, c, len(stk), chunk)

        def read(arr, i, mc, out):
            return dr.select(mc, arr.read(i, mc), out)

        out = dr.if_stmt((arr, i, mc, out), mc, read, lambda arr, i, mc, out: out,
                         label="drpt_bvh4_pop")
    return out


def _push(stk, value, sp, m, chunk):
    """Write entry ``sp`` (lanes ``m``) of a split stack; returns the arrays.
    Each write (a masked packet scatter) is a symbolic if, taken only when
    some lane of the packet pushes to that array: most packets skip the
    arrays above the first, and the pushes of third and fourth children."""
    out = []
    for c, arr in enumerate(stk):
        i, mc = _chunk_index(sp, m, c, len(stk), chunk)

        def write(arr, value, i, mc):
            arr.write(value, i, mc)
            return arr

        out.append(dr.if_stmt((arr, value, i, mc), mc, write, lambda arr, value, i, mc: arr,
                              label="drpt_bvh4_push"))
    return tuple(out)


# ------------------------------------------------------------------ BVH4
class BVH4:
    """Triangles and spheres of a scene in a 4-wide BVH; planes brute force.

    Args: as :class:`~drpt.accel.bvh.BVH` (``leaf_size`` is capped at 16).

    Attributes:
        build_seconds: host build time (bounds, BVH build, collapse, upload).
        nbytes: bytes of device arrays.
        stats: the builder's (binary tree) plus ``nodes4``, ``depth4`` and
            ``stack`` (per-lane stack entries).
        geo: the :class:`~drpt.accel.primitives.SceneGeometry` (planes and
            primitive buffers in BVH order, ``triangle_buffer4`` layout).
        node_rec: the node records of :mod:`drpt.accel.bvh4_nodes`
            (:func:`~drpt.accel.bvh4_nodes.node_records`).
        host_sizes: entries of each upload without its padding (nodes and
            ``geo``'s buffers).
        max_stack: after a query with ``track_stack = True``, the largest
            stack pointer any lane reached (a UInt32 of size 1).
    """

    coherent_gain = True  # (a traversal: protocol.Accelerator)

    track_stack = False

    def __init__(self, scene, method: str = "auto", leaf_size: int = 4, bins: int = 16,
                 min_leaf: int = 1, sah_threshold: int | None = None):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        F, S, N = geo.F, geo.S, geo.N
        self.has_tris, self.has_spheres = F > 0, S > 0
        self.node_rec = None
        self.host_sizes = {}
        self.max_stack = None
        self.stats = {"nodes": 0, "leaves": 0, "max_depth": 0, "prims": 0}
        self.stack_size = 0
        if N:
            lo, hi = primitive_bounds(scene, F, S)
            b = build_bvh(lo, hi, method=method,
                          max_leaf=min(int(leaf_size), LEAF_MAX_COUNT), bins=bins,
                          max_depth=STACK_SIZE, min_leaf=min_leaf,
                          sah_threshold=sah_threshold)
            self.stats = dict(b.stats)
            w = collapse_bvh4(b)
            self.stack_size = stack_entries(w.depth)
            self.stats.update(nodes4=int(w.ref.shape[0]), depth4=int(w.depth),
                              stack=self.stack_size)
            self.root_lo, self.root_hi = w.root_lo, w.root_hi
            rec = node_records(w)
            self.node_rec = device_array(Float, rec, padded=True)
            self.host_sizes.update(node_rec=rec.size)
            geo.upload_primitives(scene, b.prim_order, triangle_buffer4, padded=True)
            self.host_sizes.update(geo.host_sizes)
        self.nbytes = nbytes(self.node_rec) + geo.nbytes()
        self.build_seconds = time.perf_counter() - t0

    @classmethod
    def from_params(cls, scene, p: AccelParams) -> BVH4:
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
        n = max(dr.width(o), dr.width(d), dr.width(tmax), dr.width(active))

        inv_d = dr.rcp(d)
        prep = RayPrep(o, d) if self.has_tris else None
        node_rec = self.node_rec
        tri_buf, sph_buf, codes = self.geo.tri_buf, self.geo.sph_buf, self.geo.codes
        track = bool(self.track_stack)

        # root box (host constants)
        rlo = [float(x) for x in self.root_lo]
        rhi = [float(x) for x in self.root_hi]
        tn, tf = slab(rlo, rhi, o, inv_d)
        h_root = active & (tn <= tf) & (tn <= bt * SLAB_EPS)

        # Every loop variable starts full width: a size-1 (Python scalar)
        # stack pointer would make Dr.Jit 1.5 render the stack writes as
        # uniform row stores (module docstring).
        cur = dr.select(h_root, dr.zeros(UInt32, n), UInt32(INVALID))
        sp = dr.zeros(UInt32, n)
        pi = dr.zeros(UInt32, n)
        pe = dr.zeros(UInt32, n)
        bt = bt + dr.zeros(Float, n)
        bj = bj + dr.zeros(UInt32, n)
        bu = dr.zeros(Float, n)
        bv = dr.zeros(Float, n)
        msp = dr.zeros(UInt32, n)
        top = dr.full(UInt32, INVALID, n)  # the stack's top entry, in a register
        chunk = backend.policy().local_chunk
        sizes = [min(chunk, self.stack_size - c) for c in
                 range(0, self.stack_size, chunk)]
        stk_n = tuple(dr.alloc_local(UInt32, z) for z in sizes)

        def nodes_left(cur, sp, top):
            # a node in hand, or entries on the stack (register or arrays)
            return (cur != INVALID) | (top != INVALID) | (sp > 0)

        def cond(cur, sp, stk_n, pi, pe, bt, bj, bu, bv, msp, top):
            return (pi < pe) | nodes_left(cur, sp, top)

        def node_phase(cur, sp, stk_n, pi, pe, msp, bt, top):
            # ---- node phase
            in_leaf = pi < pe
            need_pop = ~in_leaf & (cur == INVALID)
            from_top = need_pop & (top != INVALID)
            from_mem = need_pop & (top == INVALID) & (sp > 0)
            sp = dr.select(from_mem, sp - 1, sp)
            cur = dr.select(from_top, top,
                            dr.select(from_mem, _pop(stk_n, sp, from_mem, chunk), cur))
            top = dr.select(from_top, UInt32(INVALID), top)
            node_on = ~in_leaf & (cur != INVALID)
            inner = node_on & ((cur & LEAF_FLAG) == 0)
            # four child boxes (SoA) and references: seven packet gathers
            # of 4 words from the node's 128-byte record
            b = cur * (RECORD_WORDS // 4)
            lx, ly, lz, hx, hy, hz, rf = (dr.gather(Array4f, node_rec, b + k, inner)
                                          for k in range(7))
            ref = dr.reinterpret_array(Array4u, rf)
            lim = bt * SLAB_EPS
            key, val = [], []
            for k in range(4):
                tn, tf = slab((lx[k], ly[k], lz[k]), (hx[k], hy[k], hz[k]), o, inv_d)
                h = (tn <= tf) & (tn <= lim) & (ref[k] != EMPTY_REF)
                key.append(dr.select(h, dr.minimum(tn, _FLT_MAX), _INF))
                val.append(ref[k])
            # sorting network: ascending entry distance, misses (inf) last
            for i, j in ((0, 1), (2, 3), (0, 2), (1, 3), (1, 2)):
                sw = key[j] < key[i]
                key[i], key[j] = dr.select(sw, key[j], key[i]), dr.select(sw, key[i], key[j])
                val[i], val[j] = dr.select(sw, val[j], val[i]), dr.select(sw, val[i], val[j])
            # push the farther hits (farthest first), continue with the nearest
            # (the newest entry stays in the register ``top``; a push moves the
            # previous one to the local arrays)
            for k in (3, 2, 1):
                m = inner & (key[k] < _INF)
                spill = m & (top != INVALID)
                stk_n = _push(stk_n, top, sp, spill, chunk)
                sp = dr.select(spill, sp + 1, sp)
                top = dr.select(m, val[k], top)
            if track:
                msp = dr.maximum(msp, sp + dr.select(top != INVALID, 1, 0))
            h0 = key[0] < _INF
            cur = dr.select(inner, dr.select(h0, val[0], UInt32(INVALID)), cur)
            # a leaf (popped, or the nearest child just found): load its range
            leaf = node_on & (cur != INVALID) & ((cur & LEAF_FLAG) != 0)
            start = cur & LEAF_START_MASK
            pi = dr.select(leaf, start, pi)
            pe = dr.select(leaf, start + ((cur >> LEAF_COUNT_SHIFT) & 15) + 1, pe)
            cur = dr.select(leaf, UInt32(INVALID), cur)

            return cur, sp, stk_n, pi, pe, msp, bt, top

        def prim_phase(cur, sp, pi, pe, bt, bj, bu, bv, top):
            # ---- primitive phase: the next LEAF_STEP primitives of the leaf
            for _ in range(LEAF_STEP):
                pa = pi < pe
                idx, tri_on, sph_on = leaf_primitive(codes, pi, pa)
                bt, bj, bu, bv, hit_any = nearest_primitive(
                    tri_buf, sph_buf, idx, idx, pi, prep, o, d, tri_on, sph_on, bt, bj, bu, bv,
                    tri_test=test_triangle4)
                pi = dr.select(pa, pi + 1, pi)
                if any_hit:
                    pe = dr.select(hit_any, pi, pe)
                    sp = dr.select(hit_any, 0, sp)
                    cur = dr.select(hit_any, UInt32(INVALID), cur)
                    top = dr.select(hit_any, UInt32(INVALID), top)
            return cur, sp, pi, pe, bt, bj, bu, bv, top

        def keep(*state):
            return state

        def body(cur, sp, stk_n, pi, pe, bt, bj, bu, bv, msp, top):
            # Each phase runs only when some lane of the SIMD packet needs it
            # (a symbolic if: a real branch in the LLVM kernel)
            go_node = (pi >= pe) & nodes_left(cur, sp, top)
            cur, sp, stk_n, pi, pe, msp, bt, top = dr.if_stmt(
                (cur, sp, stk_n, pi, pe, msp, bt, top), go_node, node_phase, keep,
                label="drpt_bvh4_node")
            cur, sp, pi, pe, bt, bj, bu, bv, top = dr.if_stmt(
                (cur, sp, pi, pe, bt, bj, bu, bv, top), pi < pe, prim_phase, keep,
                label="drpt_bvh4_leaf")
            return cur, sp, stk_n, pi, pe, bt, bj, bu, bv, msp, top

        state = (cur, sp, stk_n, pi, pe, bt, bj, bu, bv, msp, top)
        state = dr.while_loop(state, cond, body, label="drpt_bvh4")
        bt, bj, bu, bv, msp = state[5:10]
        if track:
            self.max_stack = dr.max(msp)
        return bt, bj, bu, bv
