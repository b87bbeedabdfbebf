"""Bottom-up BVH construction by parallel locally-ordered clustering (PLOC):
the ``"ploc"`` rule of :func:`~drpt.accel.build.build_bvh`.

Meister and Bittner's agglomerative build (IEEE TVCG 2018). Primitives are
sorted along a Morton curve and become clusters; then, until one cluster is
left, every round

1. finds each cluster's nearest neighbour among the ``radius`` clusters before
   and after it in that order, the distance of two clusters being the surface
   area of their merged box (:func:`_nearest`: one Dr.Jit kernel, a lane per
   cluster and a symbolic loop over the candidates, so a round is traced in
   well under a millisecond whatever the radius);
2. merges every *mutual* pair (each the other's nearest) into a new node,
   which takes the place of the left one of the pair (numpy);
3. compacts the list (numpy).

The merge order is greedy on surface area in a neighbourhood, which gives
trees that trace about as fast as a full binned SAH build's, for a fraction
of its build time; Morton order only decides who is compared with whom.
The dining room (510k triangles) takes 68 rounds.

Ties (identical boxes: a million copies of one triangle) are broken by a
strict total order on pairs: distance, then index gap, then the parity of the
pair's first index, then that index. The globally smallest pair is then
always mutual, so every round merges at least once; the parity rule makes
a run of identical clusters merge in pairs (halving it per round) rather
than one pair at a time. Inputs that still merge slowly (nested boxes merge
one pair per round) are given up on (``MAX_ROUNDS``, ``MIN_RATE_DIV``), and
:func:`~drpt.accel.build.build_bvh` builds them by the Morton rule
(:mod:`~drpt.accel.build_morton`).

The binary tree has one primitive per leaf. Subtrees of at most ``max_leaf``
primitives become leaves where the SAH says a leaf is cheaper
(``C_i N A <= C_t A + cost(left) + cost(right)``, bottom up), and the tree is
laid out breadth-first as :class:`~drpt.accel.tree.BVHArrays` (sibling
pairs at even indices, each subtree's primitives contiguous). There is no
``min_leaf``.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np
from drjit.auto import Array4f, Float, UInt32, UInt64

from .tree import BVHArrays, box_area, emit_level, morton30, node_arrays

PLOC_RADIUS = 16  # neighbours searched on each side (the paper's r)
# Give up (the caller falls back to another builder) on inputs that merge
# slowly, e.g. nested boxes, where every round merges one pair: after
# MAX_ROUNDS rounds, or on a round that merges fewer than 1/MIN_RATE_DIV of
# more than SLOW_MIN_CLUSTERS clusters. The dining room takes 68 rounds and
# merges 16-46% of the clusters per round while more than 1000 remain.
MAX_ROUNDS = 256
MIN_RATE_DIV = 64
SLOW_MIN_CLUSTERS = 1024


def _minf(a, b):
    return dr.select(a < b, a, b)  # boxes hold no NaN: no need for dr.minimum's NaN rule


def _maxf(a, b):
    return dr.select(a > b, a, b)


def _nearest(box8: np.ndarray, radius: int) -> np.ndarray:
    """Index of each cluster's nearest neighbour (module docstring), in one
    Dr.Jit kernel: a lane per cluster tests its ``2 radius`` neighbours, each
    box fetched by two 16-byte packet gathers from ``box8`` (``(n, 8)``
    float32 rows ``lo.xyz, 0, hi.xyz, 0``)."""
    n = box8.shape[0]
    buf = Float(box8.ravel())
    i = dr.arange(UInt32, n)
    n_op = dr.opaque(UInt32, n)
    lo = dr.gather(Array4f, buf, 2 * i)
    hi = dr.gather(Array4f, buf, 2 * i + 1)
    wide = n >= 1 << 26  # tie keys (g << 26 | first index) need 64 bits
    Key = UInt64 if wide else UInt32
    shift = 32 if wide else 26
    best = dr.full(Float, dr.inf, n)
    best_key = dr.full(Key, 0xFFFFFFFFFFFFFFFF if wide else 0xFFFFFFFF, n)
    best_j = dr.zeros(UInt32, n)

    def candidate(j, ok, first, best, best_key, best_j, d):
        lo2 = dr.gather(Array4f, buf, 2 * j, ok)
        hi2 = dr.gather(Array4f, buf, 2 * j + 1, ok)
        ex = _maxf(hi.x, hi2.x) - _minf(lo.x, lo2.x)
        ey = _maxf(hi.y, hi2.y) - _minf(lo.y, lo2.y)
        ez = _maxf(hi.z, hi2.z) - _minf(lo.z, lo2.z)
        a = dr.fma(ex, ey, dr.fma(ey, ez, ez * ex))
        key = (Key(2 * d + (first & 1)) << shift) | Key(first)
        better = ok & ((a < best) | ((a == best) & (key < best_key)))
        return (dr.select(better, a, best), dr.select(better, key, best_key),
                dr.select(better, j, best_j))

    def body(d, best, best_key, best_j):
        best, best_key, best_j = candidate(i + d, i + d < n_op, i, best, best_key, best_j, d)
        best, best_key, best_j = candidate(i - d, i >= d, i - d, best, best_key, best_j, d)
        return d + 1, best, best_key, best_j

    d0 = dr.full(UInt32, 1, n)
    _, best, best_key, best_j = dr.while_loop(
        (d0, best, best_key, best_j), lambda d, *_: d <= radius, body,
        mode="symbolic", label="drpt_ploc_nearest")
    return best_j.numpy().astype(np.int64)


@dataclass
class ClusterTree:
    """The binary tree of PLOC's merges over ``N`` primitives (``2N - 1``
    nodes): node ``x < N`` is the leaf of primitive ``order[x]``; node
    ``x >= N`` is inner, with children ``left[x]``, ``right[x]`` (both smaller
    than ``x``); the root is the last node, ``2N - 2``."""

    left: np.ndarray  # (2N - 1,) int64, -1 for leaves
    right: np.ndarray  # (2N - 1,) int64, -1 for leaves
    lo: np.ndarray  # (2N - 1, 3) float32 boxes
    hi: np.ndarray  # (2N - 1, 3) float32
    batches: list  # (start, stop) node id ranges created by each round, in order


def ploc_tree(lo32: np.ndarray, hi32: np.ndarray, order: np.ndarray,
              radius: int = PLOC_RADIUS) -> ClusterTree | None:
    """Binary tree over ``N`` primitives merged by PLOC.

    Args:
        lo32, hi32: ``(N, 3)`` float32 primitive boxes.
        order: ``(N,)`` the primitives in Morton order.

    Returns:
        The :class:`ClusterTree`, or ``None`` when the input merges too
        slowly (``MAX_ROUNDS``, ``MIN_RATE_DIV``).
    """
    N = order.size
    M = 2 * N - 1
    left = np.full(M, -1, np.int64)
    right = np.full(M, -1, np.int64)
    lo = np.empty((M, 3), np.float32)
    hi = np.empty((M, 3), np.float32)
    lo[:N] = lo32[order]
    hi[:N] = hi32[order]
    # cluster boxes as (n, 8) float32 rows lo.xyz, 0, hi.xyz, 0; row gathers
    # and compactions go through a 1-D view of 32-byte records (numpy's
    # fancy indexing of (n, 8) rows is several times slower)
    row = np.dtype((np.void, 32))
    box8 = np.zeros((N, 8), np.float32)
    box8[:, :3] = lo[:N]
    box8[:, 4:7] = hi[:N]
    rec = box8.view(row).ravel()
    cid = np.arange(N, dtype=np.int64)
    next_id = N
    batches = []
    while cid.size > 1:
        if len(batches) >= MAX_ROUNDS:
            return None
        n = cid.size
        nn = _nearest(box8, radius)
        ar = np.arange(n, dtype=np.int64)
        mutual = nn[nn] == ar
        i = np.flatnonzero(mutual & (ar < nn))
        j = nn[i]
        if n > SLOW_MIN_CLUSTERS and i.size * MIN_RATE_DIV < n:
            return None
        new = slice(next_id, next_id + i.size)  # the new nodes' ids
        left[new] = cid[i]
        right[new] = cid[j]
        bi = rec[i].view(np.float32).reshape(-1, 8)
        bj = rec[j].view(np.float32).reshape(-1, 8)
        merged = np.empty_like(bi)
        np.minimum(bi[:, :4], bj[:, :4], out=merged[:, :4])
        np.maximum(bi[:, 4:], bj[:, 4:], out=merged[:, 4:])
        rec[i] = merged.view(row).ravel()
        lo[new] = merged[:, :3]
        hi[new] = merged[:, 4:7]
        cid[i] = np.arange(new.start, new.stop)
        batches.append((new.start, new.stop))
        next_id = new.stop
        keep = ~(mutual & (ar > nn))
        cid = cid[keep]
        rec = rec[keep]
        box8 = rec.view(np.float32).reshape(-1, 8)
    return ClusterTree(left=left, right=right, lo=lo, hi=hi, batches=batches)


def ploc_bvh(lo32: np.ndarray, hi32: np.ndarray, cent: np.ndarray, max_leaf: int,
             max_depth: int, ct: float, ci: float, radius: int | None = None) -> BVHArrays | None:
    """PLOC tree in the layout of :class:`~drpt.accel.tree.BVHArrays`
    (``stats``: ``leaves``), or ``None`` when the tree is deeper than
    ``max_depth`` or the input merges too slowly (:func:`ploc_tree`).
    """
    N = lo32.shape[0]
    order = np.argsort(morton30(cent), kind="stable")
    tree = ploc_tree(lo32, hi32, order, PLOC_RADIUS if radius is None else radius)
    if tree is None:
        return None
    left, right, lo, hi, batches = tree.left, tree.right, tree.lo, tree.hi, tree.batches
    M = 2 * N - 1
    count = np.ones(M, np.int64)
    area = box_area(lo, hi)
    cost = ci * area
    collapse = np.ones(M, bool)
    for s, e in batches:  # bottom up: children come from earlier batches
        L, R = left[s:e], right[s:e]
        count[s:e] = count[L] + count[R]
        split = ct * area[s:e] + cost[L] + cost[R]
        leafc = np.where(count[s:e] <= max_leaf, ci * count[s:e] * area[s:e], np.inf)
        collapse[s:e] = leafc <= split
        cost[s:e] = np.minimum(split, leafc)
    start = np.zeros(M, np.int64)
    depth = np.zeros(M, np.int64)
    covered = np.zeros(M, bool)
    for s, e in reversed(batches):  # top down
        L, R = left[s:e], right[s:e]
        start[L] = start[s:e]
        start[R] = start[s:e] + count[L]
        depth[L] = depth[R] = depth[s:e] + 1
        covered[L] = covered[R] = covered[s:e] | collapse[s:e]
    prim_order = np.empty(N, np.int64)
    prim_order[start[:N]] = order
    emitted = collapse & ~covered
    max_d = int(depth[emitted].max())
    if max_d > max_depth:
        return None
    node_lo, node_hi, node_a, node_count = node_arrays(N)
    frontier = np.array([M - 1], np.int64)  # tree ids, the root last
    out = np.zeros(1, np.int64)
    next_free = 2
    n_leaves = 0
    while frontier.size:
        node_lo[out] = lo[frontier]
        node_hi[out] = hi[frontier]
        lf, sp, pair, next_free = emit_level(node_a, node_count, start[frontier],
                                              count[frontier], out, emitted[frontier],
                                              next_free)
        n_leaves += lf.size
        inner = frontier[sp]
        frontier = np.stack([left[inner], right[inner]], 1).ravel()
        out = np.stack([pair, pair + 1], 1).ravel()
    Mo = next_free
    return BVHArrays(node_lo=node_lo[:Mo].copy(), node_hi=node_hi[:Mo].copy(),
                     node_a=node_a[:Mo].copy(), node_count=node_count[:Mo].copy(),
                     prim_order=prim_order, depth=max_d, stats={"leaves": n_leaves})
