"""Ray-scene intersection accelerators.

:func:`build_accel` returns an object with

* ``intersect(o, d, tmax, active=True) -> Hit`` -- closest hit with
  ``0 < t < tmax`` (:class:`~drpt.accel.protocol.Hit`: ``t`` = inf and
  ``prim`` = 0xFFFFFFFF on a miss, ``u, v`` triangle barycentrics, ``valid``);
* ``occluded(o, d, tmax, active=True) -> Bool`` -- any hit with ``0 < t < tmax``;
* ``build_seconds``, ``nbytes`` (device bytes) and ``stats`` (``nodes``,
  ``leaves``, ``max_depth``, ...).

Global primitive ids: triangles ``0..F-1``, spheres ``F..F+S-1``, planes
``F+S..F+S+P-1``, in the scene's original order.
"""

from __future__ import annotations

from .brute import BruteForce
from .bvh import BVH
from .bvh4 import BVH4
from .build import METHODS, NO_MIN_LEAF
from .grid import UniformGrid
from .inline import MAX_PRIMS as INLINE_MAX_PRIMS
from .inline import InlineList
from .protocol import INVALID, Hit

__all__ = ["BVH", "BVH4", "BruteForce", "Hit", "INVALID", "InlineList", "KINDS", "METHODS",
           "NO_MIN_LEAF", "UniformGrid", "build_accel", "resolve_kind"]

KINDS = ("auto", "bvh", "bvh2", "bvh4", "grid", "inline", "brute")


def resolve_kind(scene, kind: str = "auto") -> str:
    """The accelerator ``kind="auto"`` stands for: ``"inline"`` for scenes of at
    most :data:`~drpt.accel.inline.MAX_PRIMS` primitives, else ``"bvh"``.
    Other kinds are returned unchanged."""
    if kind != "auto":
        return kind
    n = len(scene.triangles) + len(scene.spheres) + len(scene.planes)
    return "inline" if n <= INLINE_MAX_PRIMS else "bvh"


def build_accel(scene, kind: str = "auto", method: str = "auto", leaf_size: int = 4,
                bins: int = 16, resolution: int | None = None, min_leaf: int = 1,
                sah_threshold: int | None = None):
    """Build the accelerator for ``scene``.

    Args:
        scene: a :class:`~drpt.scene.model.Scene`.
        kind: ``"auto"`` (the default: ``"inline"`` for tiny scenes, else
            ``"bvh"``, see :func:`resolve_kind`), ``"inline"`` (every
            primitive's test compiled into the kernel with its data as
            constants, :mod:`drpt.accel.inline`), ``"bvh"`` (the 4-wide BVH,
            :mod:`drpt.accel.bvh4`; alias ``"bvh4"``), ``"bvh2"`` (the binary
            BVH it is collapsed from, :mod:`drpt.accel.bvh`: 2-3x slower to
            trace, kept for comparison), ``"grid"`` (uniform grid, 3D-DDA) or
            ``"brute"``.
        method: BVH split rule (:mod:`drpt.accel.build`): ``"auto"``
            (default: ``"sah"`` up to 100k primitives, ``"ploc"`` above),
            ``"sah"`` (binned SAH), ``"median"`` (object median),
            ``"threshold"`` (the seed's rule: SAH in nodes of at most
            ``2 * sah_threshold`` primitives, median above), ``"morton"``
            (Morton-ordered binned SAH, fast build) or ``"ploc"`` (bottom-up
            clustering, fast build, trees close to SAH's).
        leaf_size: maximum primitives per BVH leaf.
        bins: SAH bins per axis.
        resolution: grid cells per axis (the seed's ``-resolution``); ``None``
            picks about two cells per primitive.
        min_leaf: minimum primitives per BVH leaf (the seed's ``-resolution``
            with its BVH).
        sah_threshold: ``K`` of ``method="threshold"`` (the seed's
            ``-SAHeuristic``; ``None``: its default 2000).
    """
    kind = resolve_kind(scene, kind)
    if kind in ("bvh", "bvh4"):
        return BVH4(scene, method=method, leaf_size=leaf_size, bins=bins, min_leaf=min_leaf,
                    sah_threshold=sah_threshold)
    if kind == "bvh2":
        return BVH(scene, method=method, leaf_size=leaf_size, bins=bins, min_leaf=min_leaf,
                   sah_threshold=sah_threshold)
    if kind == "grid":
        return UniformGrid(scene, resolution=resolution)
    if kind == "inline":
        return InlineList(scene)
    if kind == "brute":
        return BruteForce(scene)
    raise ValueError(f"unknown accelerator kind {kind!r}; expected one of {', '.join(KINDS)}")
