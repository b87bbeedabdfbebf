"""Bounding volume hierarchy construction in vectorized numpy.

The builder works top-down and **level by level**: all nodes of one tree level
are split at once with a handful of numpy calls on flat arrays, so the Python
overhead is O(depth), not O(nodes). The work per level is O(primitives not yet
in a leaf); 510k triangles (the dining room) take ~8 s of CPU with ``"sah"``
and ~3 s with ``"median"``.

Algorithm
---------
The primitives of a node form a contiguous *segment* of three index arrays
``ids[0..2]`` (with their boxes and centroids alongside), each holding the
primitives sorted by centroid along one axis (within every segment). A split
is described uniformly as ``(axis, k)``: the first ``k`` primitives of the
segment in ``ids[axis]`` go to the left child. The partition is stable, so
both children stay sorted along all three axes and no re-sorting is ever
needed (the three ``argsort`` calls at the start are the only sorts). These
arrays hold only the *working set* (primitives not yet in a leaf), segment
after segment: each level's partition scatters them into a second set of
buffers, children in place of their parent, and drops the primitives of new
leaves, whose final order is written to ``prim_order`` then.

Split rules (``method``):

``"auto"`` (default)
    ``"sah"`` for up to ``AUTO_SAH_MAX`` (100k) primitives, ``"ploc"``
    above (and ``"sah"`` whenever ``min_leaf > 1``, which ``"ploc"`` does
    not support). Full SAH costs 13-19 us of single-threaded numpy per
    primitive here (6.7-9.6 s for the 510k-triangle dining room, 11-14x
    Mitsuba's whole scene load); PLOC ~2 us (1.0-1.2 s) for trees that trace
    about as fast, the Morton build about as long for trees that trace
    0.72-0.89x as fast (README, Performance); 100k primitives keep the SAH
    build under ~2 s. ``BVHArrays.stats["method"]`` is the rule that ran.
``"sah"``
    Binned surface area heuristic: per axis, centroids are put in ``bins``
    equal-width bins spanning the node's centroid extent; every boundary
    between non-empty bins is a candidate, scored
    ``C_t + C_i * (A_L N_L + A_R N_R) / A_P``. A node becomes a leaf when it
    holds one primitive, or at most ``max_leaf`` primitives and the leaf cost
    ``C_i * N`` does not exceed the best split cost.
``"median"``
    Object median on the axis of largest centroid extent (``k = N // 2``),
    leaves of at most ``max_leaf`` primitives. No cost is evaluated.
``"threshold"``
    The seed renderer's rule (its ``-SAHeuristic K``, report: "SAH is searched
    only when the node holds at most SAH_NUM primitives... otherwise the naive
    median split"; its pseudo-code searches when ``N / 2 <= SAH_NUM``): a node
    with ``N <= 2 * sah_threshold`` primitives is split by ``"sah"`` above,
    a larger one by ``"median"``. ``sah_threshold = 0`` is ``"median"``
    everywhere (the seed's ``SAH_NUM=0`` column), a threshold of at least
    ``N / 2`` is ``"sah"`` everywhere. The seed's default is 2000. Only the
    small nodes pay for the SAH search, which is the point of the rule: the
    large upper levels, where the search is most expensive, use the median.

``"morton"``: Morton-ordered binned SAH (fast build, for large scenes)
    Primitives are sorted once by the 30-bit Morton code of their centroid
    (10 bits per axis in the centroid bounding box), so every node is a
    contiguous segment of that one order. A segment of more than
    ``MORTON_SMALL`` (16) primitives is cut into up to ``2**MORTON_BITS`` (8)
    runs by the highest Morton bit in which its first and last codes differ
    and the two bits below it (``searchsorted``); the runs act as SAH bins
    (boxes from one ``np.minimum.reduceat`` per level, 7 candidates scored as
    above). Smaller segments split at their highest differing Morton bit (an
    LBVH split) down to leaves of at most ``min(max_leaf, MORTON_LEAF)`` (2)
    primitives. One sort and no per-axis partitions: several times faster
    to build than ``"sah"``, with slightly worse trees (measured in the
    README). ``min_leaf`` must be 1.

``"ploc"``: bottom-up clustering (fast build, SAH-quality trees)
    Parallel locally-ordered clustering (:mod:`drpt.accel.ploc`): Morton
    order, then rounds merging every pair of mutually nearest clusters
    (merged-box area) within 16 places in that order, leaves of up to
    ``max_leaf`` primitives where the SAH prefers them. ``min_leaf`` must be
    1. Inputs that merge too slowly or give a tree deeper than ``max_depth``
    (only contrived ones, e.g. nested boxes) are built by ``"morton"``
    instead, and ``stats["method"]`` says so.

Minimum leaf size (``min_leaf``, the seed's ``-resolution`` with its BVH:
"the minimal number of primitives in a box") applies to every rule: no leaf
holds fewer than ``min_leaf`` primitives (unless the whole input does). A node
with fewer than ``2 * min_leaf`` primitives is therefore a leaf; a larger node
is only split so that both children hold at least ``min_leaf`` (SAH
candidates outside that range are dropped; median splits satisfy it), and
leaves may then hold up to ``max(max_leaf, 2 * min_leaf - 1)`` primitives,
which becomes the effective ``max_leaf``. The default ``min_leaf = 1`` changes
nothing.

New rules only have to return ``(axis, k, leaf)`` per segment (see
:func:`_choose_sah` / :func:`_choose_median`).

Statistics
----------
``BVHArrays.stats`` records, besides the tree size: ``sah_nodes`` (nodes in
which the SAH search ran), ``median_nodes`` (nodes split at the object median
by the rule), ``sah_max_prims`` (largest node searched by SAH, 0 if none)
and ``median_min_prims`` (smallest node split by the median rule, 0 if
none), ``min_leaf_prims`` / ``max_leaf_prims`` (leaf sizes) and
``build_seconds``. Forced and depth-guard splits (below) are not counted as
rule splits.

Forced splits and depth
-----------------------
When no spatial split exists (all centroids identical, e.g. a million copies of
one triangle) but a node holds more than ``max_leaf`` primitives, it is split
at the index median: the tree always terminates and leaves never exceed
``max_leaf``. When the SAH would make the tree deeper than ``max_depth``
allows, the node switches to index-median splits, which need at most
``ceil(log2(N / max_leaf))`` further levels; hence ``depth <= max_depth``,
which bounds the traversal stack.

Output layout (:class:`BVHArrays`)
----------------------------------
Nodes are stored in breadth-first order with ``M`` entries:

* ``node_lo``, ``node_hi``: ``(M, 3) float32`` boxes, rounded **outward**
  from the input (``np.nextafter``) so float32 traversal never misses.
* ``node_a``, ``node_count``: ``(M,) uint32``. ``node_count == 0`` marks an
  inner node whose children are ``node_a`` and ``node_a + 1`` (siblings are
  always adjacent, and every pair starts at an even index: with 32-byte node
  records a sibling pair shares one 64-byte cache line). ``node_count > 0``
  marks a leaf holding ``prim_order[node_a : node_a + node_count]``.
* Node 0 is the root; node 1 is an unused pad (count 0, empty box) so that
  sibling pairs start at index 2.
* ``prim_order``: ``(N,) int64`` permutation, BVH position -> input primitive.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

METHODS = ("auto", "sah", "median", "threshold", "morton", "ploc")
AUTO_SAH_MAX = 100_000  # "auto": full SAH up to this many primitives, PLOC above
SEED_SAH_THRESHOLD = 2000  # the seed's default -SAHeuristic
NO_MIN_LEAF = ("morton", "ploc")  # rules that take no min_leaf (it must be 1)


@dataclass
class BVHArrays:
    node_lo: np.ndarray  # (M, 3) float32
    node_hi: np.ndarray  # (M, 3) float32
    node_a: np.ndarray  # (M,) uint32: left child, or first primitive of a leaf
    node_count: np.ndarray  # (M,) uint32: 0 for inner nodes
    prim_order: np.ndarray  # (N,) int64: BVH position -> input primitive
    depth: int  # max depth (root = 0)
    stats: dict = field(default_factory=dict)


# --------------------------------------------------------------- float32 rounding
def round_down_f32(x: np.ndarray) -> np.ndarray:
    """Largest float32 values <= ``x`` (elementwise)."""
    x = np.asarray(x, dtype=np.float64)
    y = x.astype(np.float32)
    bad = y.astype(np.float64) > x
    if bad.any():
        y[bad] = np.nextafter(y[bad], np.float32(-np.inf))
    return y


def round_up_f32(x: np.ndarray) -> np.ndarray:
    """Smallest float32 values >= ``x`` (elementwise)."""
    x = np.asarray(x, dtype=np.float64)
    y = x.astype(np.float32)
    bad = y.astype(np.float64) < x
    if bad.any():
        y[bad] = np.nextafter(y[bad], np.float32(np.inf))
    return y


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    e = np.maximum(hi.astype(np.float64) - lo.astype(np.float64), 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def _seg_min_scan(v: np.ndarray, gseg: np.ndarray, big: float, reverse: bool) -> np.ndarray:
    """Inclusive running minimum of the rows of ``v`` inside runs of equal ``gseg``.

    ``gseg`` is non-decreasing. Each run is shifted by ``-gseg * big`` (``big``
    exceeds twice the largest magnitude in ``v``) so that one global
    ``np.minimum.accumulate`` never carries a value across runs. The result
    is approximate (float64 rounding of the shifted values, relative error
    ~1e-16 * nseg); it only feeds SAH cost estimates, never node bounds.
    """
    off = (gseg.astype(np.float64) * big)[:, None]
    if reverse:
        w = (v + off)[::-1]
        return (np.minimum.accumulate(w, axis=0)[::-1]) - off
    w = v - off
    return np.minimum.accumulate(w, axis=0) + off


# -------------------------------------------------------------------- split rules
def _choose_median(ctx):
    """Object median on the longest centroid axis."""
    n = ctx["n"]
    axis = np.argmax(ctx["cext"], axis=1)
    leaf = n <= ctx["max_leaf"]
    ctx["median_mask"] = np.ones(ctx["nseg"], bool)
    return axis, n // 2, leaf


def _choose_sah(ctx):
    """Binned SAH over all three axes (see module docstring)."""
    n, nseg, bins, ml = ctx["n"], ctx["nseg"], ctx["bins"], ctx["min_leaf"]
    ctx["sah_mask"] = np.ones(nseg, bool)
    best = np.full(nseg, np.inf)
    best_axis = np.zeros(nseg, np.int64)
    best_k = n // 2
    for a in range(3):
        c, dat = ctx["cent"][a], ctx["dat"][a]
        cmin, ext = ctx["cmin"][:, a], ctx["cext"][:, a]
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(ext > 0, bins / ext, 0.0)
        seg = ctx["seg"]
        b = ((c - cmin[seg]) * scale[seg]).astype(np.int64)
        np.clip(b, 0, bins - 1, out=b)
        key = seg * bins + b
        start = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1])))
        g = np.minimum.reduceat(dat, start, axis=0)  # [lo, -hi] per group
        gcnt = np.diff(np.append(start, key.size))
        gseg = seg[start]
        g64 = g.astype(np.float64)
        pre = _seg_min_scan(g64, gseg, ctx["big"], False)
        suf = _seg_min_scan(g64, gseg, ctx["big"], True)
        cs = np.cumsum(gcnt)
        first = np.concatenate(([True], gseg[1:] != gseg[:-1]))
        base = (cs - gcnt)[first]  # count before each segment's first group
        segs_with_groups = gseg[first]
        seg_base = np.zeros(nseg, np.int64)
        seg_base[segs_with_groups] = base
        nl = cs - seg_base[gseg]
        cand = np.flatnonzero(gseg[:-1] == gseg[1:])
        if cand.size == 0:
            continue
        cseg = gseg[cand]
        cnl = nl[cand]
        if ml > 1:  # both children must keep at least min_leaf primitives
            ok = (cnl >= ml) & (n[cseg] - cnl >= ml)
            cand, cseg, cnl = cand[ok], cseg[ok], cnl[ok]
            if cand.size == 0:
                continue
        pc, sc = pre[cand], suf[cand + 1]
        cost = _area(pc[:, :3], -pc[:, 3:]) * cnl + _area(sc[:, :3], -sc[:, 3:]) * (n[cseg] - cnl)
        m = np.full(nseg, np.inf)
        np.minimum.at(m, cseg, cost)
        better = m < best
        win = better[cseg] & (cost == m[cseg])
        best_k = best_k.copy()
        best_k[cseg[win]] = cnl[win]
        best_axis[better] = a
        best[better] = m[better]
    area = ctx["area"]
    ct, ci = ctx["ct"], ctx["ci"]
    has = np.isfinite(best)
    with np.errstate(divide="ignore", invalid="ignore"):
        split_cost = ct + ci * np.where(area > 0, best / area, 0.0)
    leaf = (n <= 1) | ((n <= ctx["max_leaf"]) & (~has | (ci * n <= split_cost)))
    # no spatial candidate: index median on the longest axis
    longest = np.argmax(ctx["cext"], axis=1)
    axis = np.where(has, best_axis, longest)
    k = np.where(has, best_k, n // 2)
    return axis, k, leaf


def _sub_ctx(ctx, mask):
    """The rule context restricted to the segments where ``mask`` is true."""
    el = mask[ctx["seg"]]
    remap = np.cumsum(mask) - 1
    sub = dict(ctx)
    sub.update(
        n=ctx["n"][mask], nseg=int(mask.sum()), seg=remap[ctx["seg"][el]],
        dat=[d[el] for d in ctx["dat"]], cent=[c[el] for c in ctx["cent"]],
        cmin=ctx["cmin"][mask], cext=ctx["cext"][mask], area=ctx["area"][mask],
    )
    return sub


def _choose_threshold(ctx):
    """The seed's rule: SAH in nodes of at most ``2 * sah_threshold`` primitives,
    object median above (see module docstring)."""
    n = ctx["n"]
    small = n <= 2 * ctx["sah_threshold"]
    axis, k, leaf = _choose_median(ctx)
    if small.any():
        sub = ctx if small.all() else _sub_ctx(ctx, small)
        a2, k2, l2 = _choose_sah(sub)
        axis, k, leaf = axis.copy(), np.array(k, np.int64), leaf.copy()
        axis[small], k[small], leaf[small] = a2, k2, l2
    ctx["sah_mask"] = small
    ctx["median_mask"] = ~small
    return axis, k, leaf


_RULES = {"sah": _choose_sah, "median": _choose_median, "threshold": _choose_threshold}


# ------------------------------------------------------------------------ builder
def _node_arrays(N: int):
    """Node storage for ``N`` primitives (at most ``2N + 2`` nodes, layout in
    the module docstring): boxes, ``node_a``, ``node_count``; node 1 is the
    pad, an empty box that no ray can hit."""
    cap = 2 * N + 2
    node_lo = np.zeros((cap, 3), np.float32)
    node_hi = np.zeros((cap, 3), np.float32)
    node_lo[1] = np.inf
    node_hi[1] = -np.inf
    return node_lo, node_hi, np.zeros(cap, np.uint32), np.zeros(cap, np.uint32)


def _depth_guard(s_n, s_depth, leaf, k, max_leaf: int, max_depth: int):
    """Index-median splits (``k = n // 2``) for the split nodes that would
    otherwise leave too few levels below them to stay within ``max_depth``
    (module docstring, "Forced splits and depth"). Returns the new ``k`` and
    the guarded nodes."""
    need = np.ceil(np.log2(np.maximum(s_n / max_leaf, 1.0))).astype(np.int64)
    guard = ~leaf & (s_depth + need + 1 >= max_depth)
    return np.where(guard, s_n // 2, k), guard


def _emit_level(node_a, node_count, s_start, s_n, s_node, leaf, next_free: int):
    """Write one level's nodes: a leaf gets its primitive range, a split node
    the index of its first child, the pair being allocated at ``next_free``.
    Returns the leaf and split segment indices, the split nodes' first
    children and the new ``next_free``."""
    lf = np.flatnonzero(leaf)
    node_a[s_node[lf]] = s_start[lf]
    node_count[s_node[lf]] = s_n[lf]
    sp = np.flatnonzero(~leaf)
    left = next_free + 2 * np.arange(sp.size)
    node_a[s_node[sp]] = left
    node_count[s_node[sp]] = 0
    return lf, sp, left, next_free + 2 * sp.size


def build_bvh(
    lo: np.ndarray,
    hi: np.ndarray,
    centroids: np.ndarray | None = None,
    *,
    method: str = "auto",
    max_leaf: int = 4,
    min_leaf: int = 1,
    sah_threshold: int | None = None,
    bins: int = 16,
    max_depth: int = 64,
    traversal_cost: float = 1.0,
    intersection_cost: float = 1.0,
) -> BVHArrays:
    """Build a BVH over ``N >= 1`` primitives given their boxes.

    Args:
        lo, hi: ``(N, 3)`` primitive bounds (any float dtype; rounded outward
            to float32).
        centroids: ``(N, 3)`` split positions; default ``(lo + hi) / 2``.
        method: ``"auto"``, ``"sah"``, ``"median"``, ``"threshold"``,
            ``"morton"`` or ``"ploc"`` (module docstring).
        max_leaf: maximum primitives per leaf (>= 1); raised to
            ``2 * min_leaf - 1`` when smaller.
        min_leaf: minimum primitives per leaf (>= 1; the seed's BVH
            ``-resolution``).
        sah_threshold: ``K`` of ``"threshold"`` (>= 0; the seed's
            ``-SAHeuristic``): SAH in nodes of at most ``2K`` primitives.
            ``None`` is the seed's default 2000; only valid with
            ``"threshold"``.
        bins: SAH bins per axis.
        max_depth: hard depth limit (root = 0), must allow
            ``ceil(log2(N / max_leaf))`` levels.
        traversal_cost, intersection_cost: SAH constants ``C_t`` and ``C_i``.

    Returns:
        :class:`BVHArrays` (layout in the module docstring).
    """
    if method not in METHODS:
        raise ValueError(f"unknown BVH build method {method!r}; expected one of {METHODS}")
    if method in NO_MIN_LEAF and min_leaf != 1:
        raise ValueError(f"min_leaf applies to 'sah', 'median' and 'threshold', not {method!r}")
    if sah_threshold is not None and method != "threshold":
        raise ValueError(f"sah_threshold only applies to method 'threshold', not {method!r}")
    if sah_threshold is None:
        sah_threshold = SEED_SAH_THRESHOLD
    if int(sah_threshold) != sah_threshold or sah_threshold < 0:
        raise ValueError(f"sah_threshold must be an integer >= 0, got {sah_threshold!r}")
    if int(min_leaf) != min_leaf or min_leaf < 1:
        raise ValueError(f"min_leaf must be an integer >= 1, got {min_leaf!r}")
    sah_threshold, min_leaf = int(sah_threshold), int(min_leaf)
    t0 = time.perf_counter()
    lo = np.asarray(lo)
    hi = np.asarray(hi)
    N = lo.shape[0]
    if N == 0:
        raise ValueError("cannot build a BVH over zero primitives")
    if method == "auto":
        method = "sah" if (N <= AUTO_SAH_MAX or min_leaf > 1) else "ploc"
    max_leaf = max(int(max_leaf), 1, 2 * min_leaf - 1)
    if math.ceil(math.log2(max(N / max_leaf, 1.0))) + 1 > max_depth:
        raise ValueError(f"max_depth={max_depth} too small for {N} primitives")
    lo32 = round_down_f32(lo)
    hi32 = round_up_f32(hi)
    if centroids is None:
        cent = (lo32.astype(np.float64) + hi32) * 0.5
    else:
        cent = np.asarray(centroids, np.float64)
    built = None
    if method == "ploc":
        from .ploc import build_ploc

        built = build_ploc(lo32, hi32, cent, max_leaf, max_depth, traversal_cost,
                           intersection_cost)
        if built is None:  # merged too slowly, or deeper than max_depth
            method = "morton"
    if method == "morton":
        built = _build_morton_sah(
            lo32, hi32, cent, max_leaf, max_depth, traversal_cost, intersection_cost)
    if built is not None:
        nlo, nhi, na, nc, order, max_d, n_leaves = built
        out = BVHArrays(node_lo=nlo, node_hi=nhi, node_a=na, node_count=nc,
                        prim_order=order, depth=max_d)
        counts = nc[nc > 0]
        out.stats = dict(nodes=nlo.shape[0] - 1 if nlo.shape[0] > 1 else 1, leaves=n_leaves,
                         max_depth=max_d, prims=N, method=method, max_leaf=max_leaf,
                         min_leaf=1, min_leaf_prims=int(counts.min()),
                         max_leaf_prims=int(counts.max()),
                         build_seconds=time.perf_counter() - t0)
        return out
    # Working set, per axis in that axis' sorted order: primitive ids,
    # [lo, -hi] boxes and centroids of the primitives not yet in a leaf, the
    # segments of one level one after the other. Each level's partition
    # scatters them (segment-local moves) into the other of two buffers,
    # dropping the primitives that went into leaves.
    lohi = np.concatenate([lo32, -hi32], axis=1)
    ids, dd, cc = [], [], []
    for a in range(3):
        o = np.argsort(cent[:, a], kind="stable")
        ids.append(o)
        dd.append(np.ascontiguousarray(lohi[o]))
        cc.append(np.ascontiguousarray(cent[o, a]))
    big = 4.0 * float(np.abs(lohi).max()) + 1.0
    del lohi
    bufs = (ids, dd, cc)  # full-size buffers holding the working set
    spare = ([np.empty(N, np.int64) for _ in range(3)],
             [np.empty((N, 6), np.float32) for _ in range(3)],
             [np.empty(N, np.float64) for _ in range(3)])
    prim_order = np.empty(N, np.int64)

    node_lo, node_hi, node_a, node_count = _node_arrays(N)
    next_free = 2
    n_leaves = 0
    max_d = 0

    s_start = np.zeros(1, np.int64)
    s_n = np.full(1, N, np.int64)
    s_node = np.zeros(1, np.int64)
    s_depth = np.zeros(1, np.int64)
    rule = _RULES[method]
    is_left = np.zeros(N, bool)
    n_sah = n_median = 0
    sah_max = 0
    median_min = 0

    while s_start.size:
        nseg = s_start.size
        total = int(s_n.sum())
        seg = np.repeat(np.arange(nseg), s_n)
        off = np.cumsum(s_n) - s_n  # offset of each segment in the working set
        local = np.arange(total) - off[seg]
        last = off + s_n - 1
        cmin = np.stack([cc[a][off] for a in range(3)], 1)
        cmax = np.stack([cc[a][last] for a in range(3)], 1)
        cext = cmax - cmin
        sb = np.minimum.reduceat(dd[0], off, axis=0)
        slo, shi = sb[:, :3], -sb[:, 3:]
        node_lo[s_node] = slo
        node_hi[s_node] = shi
        max_d = max(max_d, int(s_depth.max()))

        ctx = dict(
            n=s_n, nseg=nseg, seg=seg, dat=dd, cent=cc, cmin=cmin, cext=cext,
            area=_area(slo, shi), bins=int(bins), big=big,
            max_leaf=max_leaf, min_leaf=min_leaf, sah_threshold=sah_threshold,
            ct=traversal_cost, ci=intersection_cost,
        )
        axis, k, leaf = rule(ctx)
        axis = np.asarray(axis, np.int64)
        k = np.asarray(k, np.int64)
        # min_leaf: a node that cannot give both children min_leaf is a leaf
        leaf = np.asarray(leaf, bool) | (s_n < 2 * min_leaf)
        # leaves larger than max_leaf are not allowed: force a split
        leaf &= s_n <= max_leaf
        # depth guard: switch to index-median splits near the depth limit
        k, guard = _depth_guard(s_n, s_depth, leaf, k, max_leaf, max_depth)
        bad = ~leaf & ((k < min_leaf) | (k > s_n - min_leaf))
        k = np.where(bad, s_n // 2, k)
        # statistics of the rule's choices
        if "sah_mask" in ctx:
            sm = ctx["sah_mask"] & (s_n >= 2 * min_leaf)
            if sm.any():
                n_sah += int(sm.sum())
                sah_max = max(sah_max, int(s_n[sm].max()))
        if "median_mask" in ctx:
            mm = ctx["median_mask"] & ~leaf & ~guard & ~bad
            if mm.any():
                n_median += int(mm.sum())
                mmin = int(s_n[mm].min())
                median_min = mmin if median_min == 0 else min(median_min, mmin)

        # leaves: their primitives reach their final positions
        lf, sp, left, next_free = _emit_level(node_a, node_count, s_start, s_n, s_node, leaf,
                                              next_free)
        n_leaves += lf.size
        if sp.size == 0:
            prim_order[s_start[seg] + local] = ids[0]
            break
        all_split = lf.size == 0
        if not all_split:
            em = (~leaf)[seg]  # elements of split segments
            lm = ~em
            prim_order[(s_start[seg] + local)[lm]] = ids[0][lm]

        # partition the split segments (stable, in all three orders) into the
        # spare buffers; leaf elements go past the end and are dropped
        ns = s_n[sp]
        total_split = int(ns.sum())
        new_off = np.zeros(nseg, np.int64)
        new_off[sp] = np.cumsum(ns) - ns
        ek = k[seg]
        goes_left = local < ek  # in the order of the segment's split axis
        eax = axis[seg]
        for a in range(3):
            sel = eax == a
            is_left[ids[a][sel]] = goes_left[sel]
        base = new_off[seg]
        if not all_split:
            trash = total_split + np.cumsum(lm) - 1
        nids, ndd, ncc = spare
        for a in range(3):
            lft = is_left[ids[a]]
            cl = np.cumsum(lft)
            before = (cl - lft)[off]  # lefts before each segment
            lrank = cl - before[seg]  # inclusive count of lefts in the segment so far
            newpos = base + np.where(lft, lrank - 1, ek + (local - lrank))
            if not all_split:
                newpos = np.where(em, newpos, trash)
            nids[a][newpos] = ids[a]
            ndd[a][newpos] = dd[a]
            ncc[a][newpos] = cc[a]
        bufs, spare = spare, bufs
        ids = [x[:total_split] for x in nids]
        dd = [x[:total_split] for x in ndd]
        cc = [x[:total_split] for x in ncc]

        # children, left then right, in the order of the working set
        st = s_start[sp]
        kk = k[sp]
        dd_ = s_depth[sp] + 1
        s_start = np.stack([st, st + kk], 1).ravel()
        s_n = np.stack([kk, ns - kk], 1).ravel()
        s_node = np.stack([left, left + 1], 1).ravel()
        s_depth = np.repeat(dd_, 2)

    M = next_free
    out = BVHArrays(
        node_lo=node_lo[:M].copy(),
        node_hi=node_hi[:M].copy(),
        node_a=node_a[:M].copy(),
        node_count=node_count[:M].copy(),
        prim_order=prim_order,
        depth=max_d,
    )
    counts = out.node_count[out.node_count > 0]
    out.stats = dict(
        nodes=M - 1 if M > 1 else M,
        leaves=n_leaves,
        max_depth=max_d,
        prims=N,
        method=method,
        max_leaf=max_leaf,
        min_leaf=min_leaf,
        sah_threshold=sah_threshold if method == "threshold" else None,
        sah_nodes=n_sah,
        median_nodes=n_median,
        sah_max_prims=sah_max,
        median_min_prims=median_min,
        min_leaf_prims=int(counts.min()),
        max_leaf_prims=int(counts.max()),
        build_seconds=time.perf_counter() - t0,
    )
    return out


def check_bvh(b: BVHArrays, lo: np.ndarray, hi: np.ndarray) -> None:
    """Assert the structural invariants of ``b`` (for tests; O(N) numpy)."""
    N = lo.shape[0]
    M = b.node_a.size
    assert np.array_equal(np.sort(b.prim_order), np.arange(N))
    inner = np.flatnonzero(b.node_count == 0)
    inner = inner[inner != 1] if M > 1 else inner
    if N == 1 or b.node_count[0] > 0:
        inner = inner[inner != 0]
    # children boxes inside parents
    for c in (0, 1):
        ch = b.node_a[inner].astype(np.int64) + c
        assert (ch >= 2).all() and (ch < M).all()
        assert (b.node_lo[ch] >= b.node_lo[inner]).all()
        assert (b.node_hi[ch] <= b.node_hi[inner]).all()
    leaves = np.flatnonzero(b.node_count > 0)
    cnt = b.node_count[leaves].astype(np.int64)
    assert cnt.sum() == N
    first = b.node_a[leaves].astype(np.int64)
    seg = np.repeat(np.arange(leaves.size), cnt)
    posn = np.repeat(first, cnt) + (np.arange(N) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    assert np.array_equal(np.sort(posn), np.arange(N))
    prim = b.prim_order[posn]
    assert (round_down_f32(lo[prim]) >= b.node_lo[leaves[seg]]).all()
    assert (round_up_f32(hi[prim]) <= b.node_hi[leaves[seg]]).all()


# ------------------------------------------------------- Morton-ordered SAH build
def _morton30(cent: np.ndarray) -> np.ndarray:
    """30-bit Morton codes (10 bits per axis) of points, in their bounding box."""
    code = np.zeros(len(cent), np.int64)
    for a in range(3):  # one contiguous axis at a time (column reductions are slow)
        c = np.ascontiguousarray(cent[:, a])
        lo, hi = c.min(), c.max()
        scale = 1023.0 / (hi - lo) if hi > lo else 0.0
        q = ((c - lo) * scale).astype(np.int64)
        np.clip(q, 0, 1023, out=q)
        code |= _spread3(q) << (2 - a)
    return code


def _spread3(v: np.ndarray) -> np.ndarray:
    """Bits 0..9 of ``v`` moved to bits 0, 3, 6, ..., 27 (bit interleaving by
    shifts and masks, four steps instead of a loop over the bits)."""
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


MORTON_BITS = 3  # Morton bits per SAH split: 2**3 = 8 groups, 7 candidates
MORTON_SMALL = 16  # segments this small split at their Morton midpoint (no SAH)
MORTON_LEAF = 2  # ... down to leaves of at most min(max_leaf, MORTON_LEAF) primitives


def _build_morton_sah(lo32, hi32, cent, max_leaf, max_depth, ct, ci):
    """Top-down binned SAH over Morton-ordered primitives (see build_bvh)."""
    N = lo32.shape[0]
    code = _morton30(cent)
    order = np.argsort(code, kind="stable")
    codes = code[order]
    lohi = np.concatenate([lo32, -hi32], axis=1)[order].astype(np.float32)
    lohi_x = np.concatenate([lohi, np.zeros((1, 6), np.float32)])  # reduceat pad row
    G = 1 << MORTON_BITS  # groups per split: the next MORTON_BITS Morton bits
    small_n = MORTON_SMALL

    node_lo, node_hi, node_a, node_count = _node_arrays(N)
    node_depth = np.zeros(node_a.size, np.int64)
    boxed = np.zeros(node_a.size, bool)  # box set by the SAH step (big segments)
    boxed[1] = True  # the pad keeps its empty box
    next_free = 2
    n_leaves = 0
    max_d = 0
    s_start = np.zeros(1, np.int64)
    s_n = np.full(1, N, np.int64)
    s_node = np.zeros(1, np.int64)
    s_depth = np.zeros(1, np.int64)
    while s_start.size:
        srt = np.argsort(s_start, kind="stable")
        s_start, s_n, s_node, s_depth = s_start[srt], s_n[srt], s_node[srt], s_depth[srt]
        nseg = s_start.size
        s_end = s_start + s_n
        # group boundaries from the highest differing Morton bit down 3 bits
        c0, c1 = codes[s_start], codes[s_end - 1]
        x = c0 ^ c1
        same = x == 0
        hb = np.zeros(nseg, np.int64)
        nz = ~same
        hb[nz] = np.floor(np.log2(x[nz].astype(np.float64))).astype(np.int64)
        # guard against float rounding of log2 near powers of two
        hb = np.where((x >> hb) > 1, hb + 1, hb)
        hb = np.where((x >> np.maximum(hb, 0)) == 0, hb - 1, hb)
        prefix = (c0 >> (hb + 1)) << (hb + 1)
        big = np.flatnonzero(s_n > small_n)
        sml = np.flatnonzero(s_n <= small_n)
        slo = np.empty((nseg, 3), np.float32)
        shi = np.empty((nseg, 3), np.float32)
        split_cost = np.full(nseg, np.inf)
        kk_all = s_n // 2
        has = np.zeros(nseg, bool)
        if big.size:
            nb = big.size
            bs, be, bn = s_start[big], s_end[big], s_n[big]
            hbb = hb[big]
            low = np.maximum(hbb - (MORTON_BITS - 1), 0)
            j = np.arange(1, G, dtype=np.int64)
            vals = prefix[big, None] | ((j[None, :] << low[:, None])
                                        & ((np.int64(2) << hbb[:, None]) - 1))
            pos = np.searchsorted(codes, vals.ravel(), side="left").reshape(nb, G - 1)
            pos = np.clip(pos, bs[:, None], be[:, None])
            pos = np.maximum.accumulate(pos, axis=1)
            B = np.concatenate([bs[:, None], pos, be[:, None]], axis=1)  # (nb, G+1)
            gcnt = np.diff(B, axis=1)  # (nb, G)
            gb = np.minimum.reduceat(lohi_x, B.ravel(), axis=0).reshape(nb, G + 1, 6)[:, :G]
            gb = np.where((gcnt > 0)[..., None], gb, np.float32(np.inf))
            # running min over the groups: explicit steps (an accumulate along
            # a short strided axis is slow in numpy)
            pre = np.empty_like(gb)
            suf = np.empty_like(gb)
            pre[:, 0] = gb[:, 0]
            suf[:, G - 1] = gb[:, G - 1]
            for g in range(1, G):
                np.minimum(pre[:, g - 1], gb[:, g], out=pre[:, g])
                np.minimum(suf[:, G - g], gb[:, G - 1 - g], out=suf[:, G - 1 - g])
            sb = pre[:, -1]
            slo[big], shi[big] = sb[:, :3], -sb[:, 3:]
            nl = np.cumsum(gcnt, axis=1)[:, :-1]  # left counts after groups 0..G-2
            cost = (_area(pre[:, :-1, :3], -pre[:, :-1, 3:]) * nl
                    + _area(suf[:, 1:, :3], -suf[:, 1:, 3:]) * (bn[:, None] - nl))
            ok = (nl > 0) & (nl < bn[:, None]) & ~same[big, None]
            cost = np.where(ok, cost, np.inf)
            jb = np.argmin(cost, axis=1)
            best = cost[np.arange(nb), jb]
            hb_ = np.isfinite(best)
            has[big] = hb_
            area = _area(slo[big], shi[big])
            with np.errstate(divide="ignore", invalid="ignore"):
                split_cost[big] = ct + ci * np.where(area > 0, best / area, 0.0)
            kk_all[big] = np.where(hb_, nl[np.arange(nb), jb], bn // 2)
        if sml.size:
            # small segments: LBVH split at the highest differing Morton bit
            ss = s_start[sml]
            mid = np.searchsorted(codes, prefix[sml] | (np.int64(1) << np.maximum(hb[sml], 0)))
            ks = mid - ss
            oks = ~same[sml] & (ks > 0) & (ks < s_n[sml])
            has[sml] = oks
            kk_all[sml] = np.where(oks, ks, s_n[sml] // 2)
            # small segments become leaves at min(max_leaf, MORTON_LEAF)
            # primitives (split_cost = inf so far: leaf whenever n <= max_leaf)
            split_cost[sml] = np.where(s_n[sml] > min(max_leaf, MORTON_LEAF), -np.inf, np.inf)
        # boxes: big segments here (their SAH needed them anyway), small
        # segments' subtrees bottom-up at the end (_refit_small)
        node_lo[s_node[big]] = slo[big]
        node_hi[s_node[big]] = shi[big]
        boxed[s_node[big]] = True
        node_depth[s_node] = s_depth
        max_d = max(max_d, int(s_depth.max()))
        leaf = (s_n <= 1) | ((s_n <= max_leaf) & (~has | (ci * s_n <= split_cost)))
        leaf &= s_n <= max_leaf
        k, _ = _depth_guard(s_n, s_depth, leaf, kk_all, max_leaf, max_depth)
        k = np.where(~leaf & ((k <= 0) | (k >= s_n)), s_n // 2, k)

        lf, sp, left, next_free = _emit_level(node_a, node_count, s_start, s_n, s_node, leaf,
                                              next_free)
        n_leaves += lf.size
        if sp.size == 0:
            break
        st, kk, d1 = s_start[sp], k[sp], s_depth[sp] + 1
        s_start = np.concatenate([st, st + kk])
        s_n = np.concatenate([kk, s_n[sp] - kk])
        s_node = np.concatenate([left, left + 1])
        s_depth = np.concatenate([d1, d1])
    M = next_free
    node_lo, node_hi, node_a, node_count = (node_lo[:M].copy(), node_hi[:M].copy(),
                                            node_a[:M].copy(), node_count[:M].copy())
    _refit_small(node_lo, node_hi, node_a, node_count, node_depth[:M], boxed[:M], lohi_x, max_d)
    return node_lo, node_hi, node_a, node_count, order, max_d, n_leaves


def _refit_small(node_lo, node_hi, node_a, node_count, depth, boxed, lohi_x, max_d):
    """Boxes of the nodes the Morton builder left without one (``~boxed``):
    leaves from their primitives (one ``reduceat``), inner nodes from their
    children, deepest level first."""
    leaves = np.flatnonzero((node_count > 0) & ~boxed)
    if leaves.size:
        # leaves are small: one row gather per slot (the last primitive
        # repeated in short leaves) beats reduceat's per-segment cost
        a = node_a[leaves].astype(np.int64)
        last = a + node_count[leaves].astype(np.int64) - 1
        sb = lohi_x[a]
        for j in range(1, int(node_count[leaves].max())):
            np.minimum(sb, lohi_x[np.minimum(a + j, last)], out=sb)
        node_lo[leaves], node_hi[leaves] = sb[:, :3], -sb[:, 3:]
    inner = np.flatnonzero((node_count == 0) & ~boxed)
    inner = inner[inner != 1]  # the pad
    d_in = depth[inner]
    for d in range(max_d, -1, -1):
        nodes = inner[d_in == d]
        if nodes.size:
            c = node_a[nodes].astype(np.int64)
            node_lo[nodes] = np.minimum(node_lo[c], node_lo[c + 1])
            node_hi[nodes] = np.maximum(node_hi[c], node_hi[c + 1])
