"""Top-down BVH construction in vectorized numpy: the ``"sah"``, ``"median"``
and ``"threshold"`` rules of :func:`~drpt.accel.build.build_bvh`.

The builder works top-down and **level by level**: all nodes of one tree level
are split at once with a handful of numpy calls on flat arrays, so the Python
overhead is O(depth), not O(nodes). The work per level is O(primitives not yet
in a leaf).

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

Split rules (``method``)
------------------------
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

New rules only have to return ``(axis, k, leaf)`` per segment (see
:func:`_choose_sah` / :func:`_choose_median`) and be added to :data:`RULES`.

Minimum leaf size
-----------------
``min_leaf`` (the seed's ``-resolution`` with its BVH: "the minimal number of
primitives in a box") applies to every rule here: no leaf holds fewer than
``min_leaf`` primitives (unless the whole input does). A node with fewer than
``2 * min_leaf`` primitives is therefore a leaf; a larger node is only split
so that both children hold at least ``min_leaf`` (SAH candidates outside that
range are dropped; median splits satisfy it), and leaves may then hold up to
``max(max_leaf, 2 * min_leaf - 1)`` primitives, which becomes the effective
``max_leaf`` (:func:`~drpt.accel.build.build_bvh` raises it). The default
``min_leaf = 1`` changes nothing.

Statistics
----------
Besides ``leaves``, ``BVHArrays.stats`` records ``sah_threshold`` (``None``
unless ``"threshold"``), ``sah_nodes`` (nodes in which the SAH search ran),
``median_nodes`` (nodes split at the object median by the rule),
``sah_max_prims`` (largest node searched by SAH, 0 if none) and
``median_min_prims`` (smallest node split by the median rule, 0 if none).
Forced and depth-guard splits (below) are not counted as rule splits.

Forced splits and depth
-----------------------
When no spatial split exists (all centroids identical, e.g. a million copies of
one triangle) but a node holds more than ``max_leaf`` primitives, it is split
at the index median: the tree always terminates and leaves never exceed
``max_leaf``. Near the depth limit, :func:`~drpt.accel.tree.depth_guard`
switches a node to index-median splits, so ``depth <= max_depth``.
"""

from __future__ import annotations

import numpy as np

from .tree import BVHArrays, box_area, depth_guard, emit_level, node_arrays


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
        cost = box_area(pc[:, :3], -pc[:, 3:]) * cnl + box_area(sc[:, :3], -sc[:, 3:]) * (n[cseg] - cnl)
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


RULES = {"sah": _choose_sah, "median": _choose_median, "threshold": _choose_threshold}


def topdown_bvh(lo32: np.ndarray, hi32: np.ndarray, cent: np.ndarray, method: str,
                max_leaf: int, min_leaf: int, sah_threshold: int, bins: int, max_depth: int,
                traversal_cost: float, intersection_cost: float) -> BVHArrays:
    """Top-down build with split rule ``method`` (a key of :data:`RULES`).

    Args:
        lo32, hi32: ``(N, 3)`` float32 primitive boxes, rounded outward.
        cent: ``(N, 3)`` float64 split positions.
        max_leaf: maximum primitives per leaf, at least ``2 * min_leaf - 1``.
        min_leaf, sah_threshold, bins: as :func:`~drpt.accel.build.build_bvh`.
        max_depth: depth limit (root = 0).
        traversal_cost, intersection_cost: SAH constants ``C_t`` and ``C_i``.

    Returns:
        :class:`~drpt.accel.tree.BVHArrays`; ``stats`` holds ``leaves`` and
        the rule statistics of the module docstring.
    """
    N = lo32.shape[0]
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

    node_lo, node_hi, node_a, node_count = node_arrays(N)
    next_free = 2
    n_leaves = 0
    max_d = 0

    s_start = np.zeros(1, np.int64)
    s_n = np.full(1, N, np.int64)
    s_node = np.zeros(1, np.int64)
    s_depth = np.zeros(1, np.int64)
    rule = RULES[method]
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
            area=box_area(slo, shi), bins=int(bins), big=big,
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
        k, guard = depth_guard(s_n, s_depth, leaf, k, max_leaf, max_depth)
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
        lf, sp, left, next_free = emit_level(node_a, node_count, s_start, s_n, s_node, leaf,
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
    out.stats = dict(
        leaves=n_leaves,
        sah_threshold=sah_threshold if method == "threshold" else None,
        sah_nodes=n_sah,
        median_nodes=n_median,
        sah_max_prims=sah_max,
        median_min_prims=median_min,
    )
    return out
