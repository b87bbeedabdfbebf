"""The binary BVH build: :func:`build_bvh` validates the options, rounds the
primitive boxes outward to float32 and runs one split rule.

Rules (``method``, :data:`METHODS`), each in the module of its name:

``"auto"`` (default)
    ``"sah"`` for up to ``AUTO_SAH_MAX`` (100k) primitives, ``"ploc"``
    above (and ``"sah"`` whenever ``min_leaf > 1``, which ``"ploc"`` does
    not support). Full SAH is single-threaded numpy and the slowest build;
    PLOC builds several times faster, trees that trace about as fast, and the
    Morton build about as fast, trees that trace slower (build times and trace
    rates: docs/performance.md, "BVH builders"). Up to 100k primitives the SAH
    build stays short. ``BVHArrays.stats["method"]`` is the rule that ran.
``"sah"``, ``"median"``, ``"threshold"``
    Top-down splits (binned SAH, object median, and the seed's rule: SAH in
    nodes of at most ``2 * sah_threshold`` primitives, median above),
    :mod:`~drpt.accel.build_topdown`.
``"morton"``
    Morton-ordered binned SAH (fast build), :mod:`~drpt.accel.build_morton`.
``"ploc"``
    Bottom-up clustering (fast build, trees close to SAH's),
    :mod:`~drpt.accel.build_ploc`. Inputs that merge too slowly or give a
    tree deeper than ``max_depth`` (only contrived ones, e.g. nested boxes)
    are built by ``"morton"`` instead, and ``stats["method"]`` says so.

``min_leaf`` (the seed's ``-resolution`` with its BVH) applies to the top-down
rules; ``"morton"`` and ``"ploc"`` (:data:`NO_MIN_LEAF`) require 1.

Statistics
----------
``BVHArrays.stats`` holds, for every rule: ``nodes`` (without the pad),
``leaves``, ``max_depth``, ``prims``, ``method`` (the rule that ran),
``max_leaf`` (effective), ``min_leaf``, ``min_leaf_prims`` /
``max_leaf_prims`` (leaf sizes) and ``build_seconds``; the top-down rules
add their split counts (:mod:`~drpt.accel.build_topdown`, "Statistics").
"""

from __future__ import annotations

import math
import time

import numpy as np

from .build_morton import morton_bvh
from .build_ploc import ploc_bvh
from .build_topdown import topdown_bvh
from .tree import BVHArrays, round_down_f32, round_up_f32

METHODS = ("auto", "sah", "median", "threshold", "morton", "ploc")
AUTO_SAH_MAX = 100_000  # "auto": full SAH up to this many primitives, PLOC above
SEED_SAH_THRESHOLD = 2000  # the seed's default -SAHeuristic
NO_MIN_LEAF = ("morton", "ploc")  # rules that take no min_leaf (it must be 1)


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
            ``"morton"`` or ``"ploc"`` (module docstring and the rule modules).
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
        :class:`BVHArrays` (layout in :mod:`~drpt.accel.tree`).
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
    if method == "ploc":
        b = ploc_bvh(lo32, hi32, cent, max_leaf, max_depth, traversal_cost, intersection_cost)
        if b is None:  # merged too slowly, or deeper than max_depth
            method = "morton"
    if method == "morton":
        b = morton_bvh(lo32, hi32, cent, max_leaf, max_depth, traversal_cost, intersection_cost)
    elif method != "ploc":
        b = topdown_bvh(lo32, hi32, cent, method, max_leaf, min_leaf, sah_threshold, bins,
                        max_depth, traversal_cost, intersection_cost)
    rule_stats = dict(b.stats)
    M = b.node_a.size
    counts = b.node_count[b.node_count > 0]
    b.stats = {
        "nodes": M - 1 if M > 1 else M,
        "leaves": rule_stats.pop("leaves"),
        "max_depth": b.depth,
        "prims": N,
        "method": method,
        "max_leaf": max_leaf,
        "min_leaf": min_leaf,
        **rule_stats,
        "min_leaf_prims": int(counts.min()),
        "max_leaf_prims": int(counts.max()),
        "build_seconds": time.perf_counter() - t0,
    }
    return b
