"""The 4-wide BVH's node layout and the collapse of a binary BVH into it.

:func:`collapse_bvh4` turns a binary :class:`~drpt.accel.tree.BVHArrays`
(any split rule of :func:`~drpt.accel.build.build_bvh`) into a
:class:`BVH4Arrays`, the node data that :mod:`drpt.accel.bvh4` traverses: a
4-wide tree halves the number of loop iterations spent in inner nodes and
tests four child boxes per iteration from seven packet gathers.

Layout: per 4-wide node, 24 floats of child boxes in SoA order ``lo.x[4],
lo.y[4], lo.z[4], hi.x[4], hi.y[4], hi.z[4]`` (six 16-byte packets) and 4
uint32 child references: an inner child's node index (bit 31 clear); a
leaf's ``LEAF_FLAG | (count - 1) << LEAF_COUNT_SHIFT | first``; ``EMPTY_REF``
for an unused slot, with an empty box (lo = +inf, hi = -inf). Leaves hold at
most ``LEAF_MAX_COUNT`` (16) primitives and BVH positions need 27 bits
(< 134M primitives).

On the device both are one record per node (:func:`node_records`): 32
words, the 24 box floats, the 4 references (their bits stored as float32)
and 4 zero words, 128 bytes, so that a node read touches two 64-byte cache
lines (boxes and references in separate arrays touched three).

Collapse: every 4-wide node starts from an inner binary node with its two
children and, twice, replaces the inner child of largest surface area by its
two children. Ties between equal areas (identical boxes, e.g. 100k copies of
one triangle) go to the shallower child: taking the first of them gave a
lopsided tree on such input (depth4 13, a 43-entry stack, against depth4 7
and 25 entries).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tree import BVHArrays, box_area

LEAF_FLAG = 0x80000000
LEAF_COUNT_SHIFT = 27
LEAF_MAX_COUNT = 16  # count - 1 is stored in 4 bits
LEAF_START_MASK = (1 << LEAF_COUNT_SHIFT) - 1
EMPTY_REF = 0xFFFFFFFF


@dataclass
class BVH4Arrays:
    """A binary :class:`~drpt.accel.tree.BVHArrays` collapsed to a 4-wide
    tree (layout in :func:`collapse_bvh4`)."""

    box: np.ndarray  # (K, 24) float32: lo.x[4], lo.y[4], lo.z[4], hi.x[4], hi.y[4], hi.z[4]
    ref: np.ndarray  # (K, 4) uint32 child references
    root_lo: np.ndarray  # (3,) float32
    root_hi: np.ndarray  # (3,) float32
    depth: int  # max depth of the 4-wide tree (root = 0)


RECORD_WORDS = 32  # words per device node record (node_records)


def node_records(w: BVH4Arrays) -> np.ndarray:
    """``(K, RECORD_WORDS)`` float32 device records of ``w``'s nodes: words
    0-23 the child boxes, 24-27 the child references (uint32 bits viewed as
    float32), 28-31 zero."""
    rec = np.zeros((w.ref.shape[0], RECORD_WORDS), np.float32)
    rec[:, :24] = w.box
    rec[:, 24:28] = np.ascontiguousarray(w.ref, np.uint32).view(np.float32)
    return rec


def collapse_bvh4(b: BVHArrays) -> BVH4Arrays:
    """Collapse a binary BVH into a 4-wide one (vectorized, level by level).

    Every 4-wide node starts from an inner binary node with its two children
    and, twice, replaces the inner child of largest surface area (on ties:
    the shallower one) by its two children, so it gets up to 4 children.
    Nodes are numbered breadth-first, root = 0. Per node ``k``: ``box[k]``
    holds the four child boxes in SoA order (six 16-byte packets); ``ref[k]``
    the four child references (an inner child is its node index, bit 31
    clear; a leaf is ``LEAF_FLAG | (count - 1) << 27 | start``; an unused
    slot is ``EMPTY_REF`` with an empty box, lo = +inf, hi = -inf). A binary
    root that is a leaf becomes a root with one leaf child.
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


