"""Ray-scene intersection accelerators.

:func:`build_accel` returns an object with

* ``intersect(o, d, tmax, active=True) -> Hit`` -- closest hit with
  ``0 < t < tmax`` (:class:`~drpt.accel.bvh.Hit`: ``t`` = inf and
  ``prim`` = 0xFFFFFFFF on a miss, ``u, v`` triangle barycentrics, ``valid``);
* ``occluded(o, d, tmax, active=True) -> Bool`` -- any hit with ``0 < t < tmax``;
* ``build_seconds``, ``nbytes`` (device bytes) and ``stats`` (``nodes``,
  ``leaves``, ``max_depth``, ...).

Global primitive ids: triangles ``0..F-1``, spheres ``F..F+S-1``, planes
``F+S..F+S+P-1``, in the scene's original order.
"""

from __future__ import annotations

from .brute import BruteForce
from .bvh import BVH, INVALID, Hit

__all__ = ["BVH", "BruteForce", "Hit", "INVALID", "build_accel"]


def build_accel(scene, kind: str = "bvh", method: str = "sah", leaf_size: int = 4,
                bins: int = 16):
    """Build the accelerator for ``scene``.

    Args:
        scene: a :class:`~drpt.scene.model.Scene`.
        kind: ``"bvh"`` or ``"brute"``.
        method: BVH split rule, ``"sah"`` or ``"median"`` (ignored for brute).
        leaf_size: maximum primitives per BVH leaf.
        bins: SAH bins per axis.
    """
    if kind == "bvh":
        return BVH(scene, method=method, leaf_size=leaf_size, bins=bins)
    if kind == "brute":
        return BruteForce(scene)
    raise ValueError(f"unknown accelerator kind {kind!r}; expected 'bvh' or 'brute'")
