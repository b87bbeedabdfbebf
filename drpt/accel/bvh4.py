"""4-wide BVH, drpt's default accelerator: collapse of the binary BVH and its
traversal in Dr.Jit.

:class:`BVH4` has the interface of :class:`~drpt.accel.bvh.BVH` (same
primitive ids, :class:`~drpt.accel.bvh.Hit` results, planes tested brute force
before the traversal) and the same builder (:func:`~drpt.accel.build.build_bvh`
with all its split rules); the binary tree is collapsed into a 4-wide one
(:func:`collapse_bvh4`), which halves the number of loop iterations spent in
inner nodes and tests four child boxes per iteration from six packet gathers.

Traversal
---------
Everything happens in one ``dr.while_loop`` (symbolic by default; it also
runs in evaluated mode, following :py:attr:`drjit.JitFlag.SymbolicLoops`).
The root box is tested before the loop. Each iteration of a lane does, in
this order:

1. *node phase* (when the lane is not inside a leaf): pop a node reference
   from the lane's stack unless one is current. The stack's newest entry is
   kept in a register (``top``), the older ones in ``dr.alloc_local``
   arrays, so a node with one or two hit children beyond the nearest pushes
   and later pops one entry fewer through memory (same process, ``bench``
   rays, three rounds: Cornell box 1.00-1.09x / 1.02-1.18x / 1.11-1.13x
   primary / incoherent / shadow, dining room 1.00-1.04x / 1.00-1.03x /
   1.02-1.06x, newscene 0.94-1.08x / 1.02-1.05x / 0.98-1.03x).
   For an inner node, fetch the four child boxes with six 16-byte packet
   gathers and the four child references with one, slab-test
   all four, sort the hits by entry distance (5-comparator network, misses
   last), push the farther hits (farthest first) and continue with the
   nearest. If the entry in hand is a leaf (popped, or the nearest child just
   found), load its primitive range right away;
2. *primitive phase* (when inside a leaf): test one primitive.

Children are only pushed when their box starts before the closest hit so
far; popped entries are not checked again against a closer hit found since
(which would need their entry distances on a second stack). Keeping those
distances and skipping such entries was slower, measured in one process on
``bench``'s 1M rays: dropping them made closest-hit queries 1.02-1.04x faster
on the Cornell box, 0.96-1.03x on newscene and 1.31-1.33x on the dining room,
and shadow rays (which end at their first hit, so never skip) 1.07-1.35x.

Each phase is a symbolic ``dr.if_stmt``, which the LLVM backend compiles to a
real branch taken when any lane of the SIMD packet needs it: a packet whose
lanes are all inside leaves skips the node phase (the costlier one: seven
packet gathers, four slab tests, a sort and pushes), and one with no lane in a
leaf skips the primitive test. Against both phases always executed under
masks, measured in one process on ``bench``'s 1M rays (``intersect`` /
``occluded``, best of 3): Cornell box 1.25x / 1.07x / 1.14x (primary /
incoherent / shadow), newscene 1.33x / 1.09x / 1.05x, dining room 1.08x /
1.16x / 1.15x.

Stack size: a lane at a node of depth ``k`` (root = 0) holds at most three
entries per ancestor level, and a push round adds at most three, so
``3 * (depth4 + 1)`` entries suffice; :func:`stack_entries` adds one spare.
The stack is split into ``dr.alloc_local`` arrays of at most ``LOCAL_CHUNK``
(16) entries (the Cornell box needs one, 100k identical triangles two: 16 +
9, the dining room three or four). Every read and write of a local array with
per-lane indices is a masked packet gather or scatter, paid even when its
mask is empty; each one is therefore a symbolic if, taken only when some lane
of the packet uses that array (:func:`_push`, :func:`_pop`). Against
unconditional reads and writes, measured in one process on ``bench``'s rays
(best of 3, three rounds; primary / incoherent / shadow): dining room
1.35-1.43x / 1.19-1.28x / 1.17-1.31x (three arrays; with ``--bvh sah``, four:
1.48-1.56x / 1.31-1.41x / 1.21-1.42x), and with one array, where only the
pushes of third and fourth children (which few packets need) are skipped,
Cornell box 1.19-1.21x / 1.08-1.16x / 1.08-1.14x, newscene 1.12-1.17x /
1.09-1.10x / 0.96-1.15x. ``BVH4.track_stack``
records the largest stack pointer of each query (tests).

The crash of the first 4-wide BVH (commit ``bc77154``, reverted)
-----------------------------------------------------------------
Reproduced (100k copies of one triangle, 1000 rays along -z, closest hit
then occlusion, 2 repetitions per process): about 1 process in 8-10 dies
with SIGSEGV in a packet gather of the JIT kernel on a Dr.Jit worker thread
(seen under gdb), at a wild address (a node index around 2**31 / 6, i.e. a
garbage ``cur``), in the closest-hit or the occlusion query. Ruled out,
with evidence:

* stack overflow: with ``track_stack`` the deepest stack was 29 entries of
  43 (depth4 = 13 with bc77154's collapse); the bound above holds;
* dangling host memory: Dr.Jit maps numpy memory without copying but keeps
  a reference to the array; uploads copied into Dr.Jit-owned memory crashed
  just as often (2 of 9 runs);
* masked packet gathers: masked lanes read a static zero packet (checked in
  the generated IR); packets past the end: uploads are padded by 64 bytes;
* the Dr.Jit 1.5 local-array hazard below (bc77154 widened ``sp`` first).

Not understood: it matches Dr.Jit issues #532
(``dr.alloc_local`` stacks larger than 128 bytes per lane crash the LLVM
backend, DFS/BVH kernels) and #446 (LLVM-only garbage indices in a
``dr.Local`` BVH stack). Changed here without effect on it: ties between
equal child areas now go to the shallower child (bc77154's collapse gave a
lopsided tree on identical boxes: depth4 13, 43-entry stack; now depth4 7,
25 entries, one local array of 100 bytes per lane), all loop state starts
full width, uploads are padded. The reproducer still crashed 2 processes in
18. With ``dr.set_thread_count(0)`` it did not crash in 22 processes. What
changed it is the size of the local arrays: in two concurrent process loops
(24 processes each), the 25-entry stack in one array (100 bytes per lane)
crashed 4 times, split into arrays of at most 16 entries (64 bytes) never.
Hence ``LOCAL_CHUNK = 16``. With it, no crash since: 72 processes of the
reproducer in the session that found it, then 171 processes (3 builds and 6
closest-hit + occlusion query pairs each; 78 of them with the final
traversal: symbolic-if phases, no distance stack) and the whole test suite
with this BVH as the default, in the session that made it the default
(``build_accel(kind="bvh")``), then 153 processes after the stack's reads
and writes became symbolic ifs (50 with the register ``top`` as well). At
the old rate (1 process in 6), no crash in 396 processes has probability
~4e-32. The mechanism inside Dr.Jit is
still not known; the binary BVH (``"bvh2"``, 64-entry arrays) never
crashed. ``DRPT_STRESS=1 pytest tests/test_bvh4.py`` runs the reproducer.

Dr.Jit 1.5 hazard (avoided): in a symbolic loop, ``Local.write(value, index,
mask)`` whose ``index`` variable has size 1 is rendered as one uniform row
store at the largest index of the active lanes, even when the lanes' values
differ; a stack pointer created as ``UInt32(0)`` and written before being
widened loses entries (44 of 64 lanes in ``tests/test_bvh4.py``). Every loop
variable here starts full width (``dr.zeros(T, n)``).

Device data (float32 or uint32, in BVH order, 64-byte aligned so that Dr.Jit
emits packet gathers, see :func:`device_array`): per 4-wide node, 24 floats of
child boxes in SoA order ``lo.x[4], lo.y[4], lo.z[4], hi.x[4], hi.y[4],
hi.z[4]`` and 4 uint32 child references (an inner child's node index; a
leaf's ``1 << 31 | (count - 1) << 27 | first``; ``0xFFFFFFFF`` for an unused
slot); triangle vertices ``p0, p1, p2`` padded to 4 floats, ``12 * F`` floats
read with three packet gathers and permuted to the ray's axes with selects
(vertices, not edges: the watertight test needs bitwise identical shared
vertices, see :mod:`drpt.geometry.triangle`); spheres as ``4 * S`` floats
``[c.xyz, r]``; for mixed scenes a per-position uint32 code
``local | is_sphere << 31``. Leaves hold at most 16 primitives and BVH
positions need 27 bits (< 134M primitives).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Array4f, Array4u, Float, UInt32

from ..geometry.triangle import RayPrep, watertight_permuted
from .bvh import (BVH, INVALID, STACK_SIZE, SceneGeometry, _nbytes, leaf_orders,
                  leaf_primitive, nearest_primitive, primitive_bounds, sphere_buffer)
from .build import build_bvh
from .tree import BVHArrays, box_area

_SLAB_EPS = 1.0 + 4.0 * 2.0**-24  # robust slab test (Ize 2013): widen t_far
_INF = float("inf")
_FLT_MAX = 3.4028234663852886e38

LEAF_FLAG = 0x80000000
LEAF_COUNT_SHIFT = 27
LEAF_MAX_COUNT = 16  # count - 1 is stored in 4 bits
LEAF_START_MASK = (1 << LEAF_COUNT_SHIFT) - 1
EMPTY_REF = 0xFFFFFFFF
PAD_BYTES = 64  # every upload is followed by (at least) one 64-byte packet of zeros


# ------------------------------------------------------------------ uploads
def device_array(cls, a: np.ndarray):
    """Device copy of ``a`` (flattened), 64-byte aligned and zero padded.

    Dr.Jit (LLVM) maps host memory without copying and marks a buffer that is
    not 64-byte aligned as *unaligned*; packet gathers (``dr.gather(Array4f,
    ...)``) from such a buffer silently fall back to one gather per component.
    numpy only guarantees 16 bytes, so the data is placed at a 64-byte
    boundary inside a larger numpy buffer (Dr.Jit keeps a reference to it),
    followed by at least ``PAD_BYTES`` zero bytes so that no packet can end
    past the allocation. Returns the device array (padding included) and
    ``a.size``.
    """
    a = np.ascontiguousarray(a).reshape(-1)
    nb = a.nbytes
    raw = np.zeros(nb + PAD_BYTES + 64, np.uint8)
    off = (-raw.ctypes.data) % 64
    host = raw[off:off + nb + PAD_BYTES].view(a.dtype)
    host[:a.size] = a
    v = cls(host)
    dr.eval(v)
    return v, a.size


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


# ------------------------------------------------------------------ collapse
@dataclass
class BVH4Arrays:
    """A binary :class:`~drpt.accel.tree.BVHArrays` collapsed to a 4-wide
    tree (layout in :func:`collapse_bvh4`)."""

    box: np.ndarray  # (K, 24) float32: lo.x[4], lo.y[4], lo.z[4], hi.x[4], hi.y[4], hi.z[4]
    ref: np.ndarray  # (K, 4) uint32 child references
    root_lo: np.ndarray  # (3,) float32
    root_hi: np.ndarray  # (3,) float32
    depth: int  # max depth of the 4-wide tree (root = 0)


def stack_entries(depth4: int) -> int:
    """Per-lane stack entries that a 4-wide tree of depth ``depth4`` needs
    (see the module docstring), plus one spare."""
    return 3 * (int(depth4) + 1) + 1


def collapse_bvh4(b: BVHArrays) -> BVH4Arrays:
    """Collapse a binary BVH into a 4-wide one (vectorized, level by level).

    Every 4-wide node starts from an inner binary node with its two children
    and, twice, replaces the inner child of largest surface area (on ties:
    the shallower one) by its two children, so it gets up to 4 children. Nodes are numbered breadth-first,
    root = 0. Per node ``k``: ``box[k]`` holds the four child boxes in SoA
    order (six 16-byte packets); ``ref[k]`` the four child references (an inner
    child is its node index, bit 31 clear; a leaf is
    ``LEAF_FLAG | (count - 1) << 27 | start``; an unused slot is ``EMPTY_REF``
    with an empty box, lo = +inf, hi = -inf). A binary root that is a leaf
    becomes a root with one leaf child.
    """
    a = b.node_a.astype(np.int64)
    cnt = b.node_count.astype(np.int64)
    M = a.size
    if cnt.max(initial=0) > LEAF_MAX_COUNT:
        raise ValueError(f"leaves hold at most {LEAF_MAX_COUNT} primitives")
    if b.prim_order.size > LEAF_START_MASK + 1:
        raise ValueError("too many primitives for the 4-wide BVH encoding")
    area = box_area(b.node_lo, b.node_hi)
    root_leaf = bool(cnt[0] > 0 or M == 1)
    boxes, refs = [], []
    frontier = np.zeros(1, np.int64)
    next_id = 1
    depth = 0
    while True:
        if root_leaf:
            C = np.full((1, 4), -1, np.int64)
            C[0, 0] = 0
        else:
            K = frontier.size
            C = np.full((K, 4), -1, np.int64)
            C[:, 0] = a[frontier]
            C[:, 1] = a[frontier] + 1
            rows = np.arange(K)
            lvl = np.ones((K, 4))  # binary levels below the 4-wide node
            for slot in (2, 3):
                valid = C >= 0
                inner = valid & (cnt[np.maximum(C, 0)] == 0)
                # largest area first; on ties (e.g. identical boxes) the
                # shallower child, so degenerate trees stay balanced
                ar = np.where(inner, area[np.maximum(C, 0)] * (1.0 - 1e-7 * lvl), -1.0)
                j = np.argmax(ar, axis=1)
                ok = ar[rows, j] >= 0
                r, jj = rows[ok], j[ok]
                x = C[r, jj]
                C[r, jj] = a[x]
                C[r, slot] = a[x] + 1
                lvl[r, jj] += 1
                lvl[r, slot] = lvl[r, jj]
        K = C.shape[0]
        valid = C >= 0
        Cs = np.maximum(C, 0)
        is_leaf = valid & (cnt[Cs] > 0)
        is_inner = valid & ~is_leaf
        ref = np.full((K, 4), EMPTY_REF, np.int64)
        n_inner = int(is_inner.sum())
        ref[is_inner] = next_id + np.arange(n_inner)  # row-major = breadth-first
        next_id += n_inner
        ref[is_leaf] = LEAF_FLAG | ((cnt[Cs][is_leaf] - 1) << LEAF_COUNT_SHIFT) | a[Cs][is_leaf]
        lo = np.where(valid[..., None], b.node_lo[Cs], np.float32(np.inf))
        hi = np.where(valid[..., None], b.node_hi[Cs], np.float32(-np.inf))
        box = np.concatenate([lo.transpose(0, 2, 1).reshape(K, 12),
                              hi.transpose(0, 2, 1).reshape(K, 12)], 1)
        boxes.append(box.astype(np.float32))
        refs.append(ref.astype(np.uint32))
        if root_leaf or n_inner == 0:
            break
        frontier = C[is_inner]
        depth += 1
    return BVH4Arrays(box=np.concatenate(boxes), ref=np.concatenate(refs),
                      root_lo=b.node_lo[0].astype(np.float32),
                      root_hi=b.node_hi[0].astype(np.float32), depth=depth)


# ------------------------------------------------------------------ stack
LOCAL_CHUNK = 16  # entries per dr.alloc_local array (64 bytes of 32-bit values)


def _chunk_index(sp, m, c, n_chunks):
    if n_chunks == 1:
        return sp, m
    mc = m & ((sp // LOCAL_CHUNK) == c)
    return dr.select(mc, sp - c * LOCAL_CHUNK, 0), mc


def _pop(stk, sp, m):
    """Entry ``sp`` (lanes ``m``) of a stack split into ``LOCAL_CHUNK``-entry
    local arrays. A read with per-lane indices is a masked packet gather whose
    cost is paid even when no lane is in the mask, so each array is read in a
    symbolic if, taken only when some lane of the packet pops from it."""
    out = dr.zeros(UInt32, dr.width(sp))
    for c, arr in enumerate(stk):
        i, mc = _chunk_index(sp, m, c, len(stk))

        def read(arr, i, mc, out):
            return dr.select(mc, arr.read(i, mc), out)

        out = dr.if_stmt((arr, i, mc, out), mc, read, lambda arr, i, mc, out: out,
                         label="drpt_bvh4_pop")
    return out


def _push(stk, value, sp, m):
    """Write entry ``sp`` (lanes ``m``) of a split stack; returns the arrays.
    Each write (a masked packet scatter) is a symbolic if, taken only when
    some lane of the packet pushes to that array: most packets skip the
    arrays above the first, and the pushes of third and fourth children."""
    out = []
    for c, arr in enumerate(stk):
        i, mc = _chunk_index(sp, m, c, len(stk))

        def write(arr, value, i, mc):
            arr.write(value, i, mc)
            return arr

        out.append(dr.if_stmt((arr, value, i, mc), mc, write, lambda arr, value, i, mc: arr,
                              label="drpt_bvh4_push"))
    return tuple(out)


# ------------------------------------------------------------------ BVH4
class BVH4(BVH):
    """Triangles and spheres of a scene in a 4-wide BVH; planes brute force.

    Args: as :class:`~drpt.accel.bvh.BVH` (``leaf_size`` is capped at 16).

    Attributes:
        build_seconds: host build time (bounds, BVH build, collapse, upload).
        nbytes: bytes of device arrays.
        stats: the builder's (binary tree) plus ``nodes4``, ``depth4`` and
            ``stack`` (per-lane stack entries).
        max_stack: after a query with ``track_stack = True``, the largest
            stack pointer any lane reached (a UInt32 of size 1).
    """

    track_stack = False

    def __init__(self, scene, method: str = "auto", leaf_size: int = 4, bins: int = 16,
                 min_leaf: int = 1, sah_threshold: int | None = None):
        t0 = time.perf_counter()
        self.geo = geo = SceneGeometry(scene)
        F, S, N = geo.F, geo.S, geo.N
        self.has_tris, self.has_spheres = F > 0, S > 0
        self.tri_buf = self.sph_buf = self.codes = None
        self.node_box = self.node_ref = self.prim_ids = None
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
            order = b.prim_order
            w = collapse_bvh4(b)
            self.stack_size = stack_entries(w.depth)
            self.stats.update(nodes4=int(w.ref.shape[0]), depth4=int(w.depth),
                              stack=self.stack_size)
            self.root_lo, self.root_hi = w.root_lo, w.root_hi
            self.node_box = self._up("node_box", Float, w.box)
            self.node_ref = self._up("node_ref", UInt32, w.ref)
            self.prim_ids = self._up("prim_ids", UInt32, order.astype(np.uint32))
            tri_order, sph_order, codes = leaf_orders(order, F)
            if F:
                self.tri_buf = self._up("tri_buf", Float, triangle_buffer4(
                    scene.triangles.positions[tri_order]))
            if S:
                self.sph_buf = self._up("sph_buf", Float, sphere_buffer(
                    scene.spheres.center[sph_order], scene.spheres.radius[sph_order]))
            if codes is not None:
                self.codes = self._up("codes", UInt32, codes)
        self.nbytes = _nbytes(self.node_box, self.node_ref, self.prim_ids, self.tri_buf,
                              self.sph_buf, self.codes) + geo.plane_nbytes()
        self.build_seconds = time.perf_counter() - t0

    def _up(self, name, cls, a):
        v, n = device_array(cls, a)
        self.host_sizes[name] = n
        return v

    # intersect() and occluded() are BVH's, around this class's _trace()
    # ------------------------------------------------------------- internals
    def _trace(self, o, d, tmax, active, any_hit: bool):
        o, d, active, bt, bj, bu, bv = self._begin(o, d, tmax, active, any_hit)
        if not self.geo.N:
            return bt, bj, bu, bv
        n = max(dr.width(o), dr.width(d), dr.width(tmax), dr.width(active))

        inv_d = dr.rcp(d)
        prep = RayPrep(o, d) if self.has_tris else None
        node_box, node_ref = self.node_box, self.node_ref
        tri_buf, sph_buf, codes = self.tri_buf, self.sph_buf, self.codes
        track = bool(self.track_stack)

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

        # Every loop variable starts full width: a size-1 (Python scalar)
        # stack pointer would make Dr.Jit 1.5 render the stack writes as
        # uniform row stores (module docstring), the crash of bc77154.
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
        sizes = [min(LOCAL_CHUNK, self.stack_size - c) for c in
                 range(0, self.stack_size, LOCAL_CHUNK)]
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
                            dr.select(from_mem, _pop(stk_n, sp, from_mem), cur))
            top = dr.select(from_top, UInt32(INVALID), top)
            node_on = ~in_leaf & (cur != INVALID)
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
            # (the newest entry stays in the register ``top``; a push moves the
            # previous one to the local arrays)
            for k in (3, 2, 1):
                m = inner & (key[k] < _INF)
                spill = m & (top != INVALID)
                stk_n = _push(stk_n, top, sp, spill)
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
            # ---- primitive phase: one primitive of the current leaf
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
