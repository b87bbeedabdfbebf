"""The binary BVH's node layout and the pieces every BVH builder shares.

The builders (:mod:`~drpt.accel.build_topdown`, :mod:`~drpt.accel.build_morton`,
:mod:`~drpt.accel.build_ploc`, chosen by :func:`~drpt.accel.build.build_bvh`)
all return a :class:`BVHArrays` in the layout below, written one tree level
at a time by :func:`emit_level` into the storage of :func:`node_arrays`.

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

Depth
-----
Top-down builders bound the depth with :func:`depth_guard`: when the split
rule would make the tree deeper than ``max_depth`` allows, the node switches
to index-median splits, which need at most ``ceil(log2(N / max_leaf))``
further levels; hence ``depth <= max_depth``, which bounds the traversal
stack.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class BVHArrays:
    """A binary BVH in the layout of the module docstring."""

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


def box_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Surface area (halved: ``xy + yz + zx``) of boxes, in float64; empty
    boxes (``hi < lo``) have area 0."""
    e = np.maximum(hi.astype(np.float64) - lo.astype(np.float64), 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


# ------------------------------------------------------------------ Morton codes
def morton30(cent: np.ndarray) -> np.ndarray:
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


# ------------------------------------------------------------------ node arrays
def node_arrays(N: int):
    """Node storage for ``N`` primitives (at most ``2N + 2`` nodes, layout in
    the module docstring): boxes, ``node_a``, ``node_count``; node 1 is the
    pad, an empty box that no ray can hit."""
    cap = 2 * N + 2
    node_lo = np.zeros((cap, 3), np.float32)
    node_hi = np.zeros((cap, 3), np.float32)
    node_lo[1] = np.inf
    node_hi[1] = -np.inf
    return node_lo, node_hi, np.zeros(cap, np.uint32), np.zeros(cap, np.uint32)


def depth_guard(s_n, s_depth, leaf, k, max_leaf: int, max_depth: int):
    """Index-median splits (``k = n // 2``) for the split nodes that would
    otherwise leave too few levels below them to stay within ``max_depth``
    (module docstring, "Depth"). Returns the new ``k`` and
    the guarded nodes."""
    need = np.ceil(np.log2(np.maximum(s_n / max_leaf, 1.0))).astype(np.int64)
    guard = ~leaf & (s_depth + need + 1 >= max_depth)
    return np.where(guard, s_n // 2, k), guard


def emit_level(node_a, node_count, s_start, s_n, s_node, leaf, next_free: int):
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


