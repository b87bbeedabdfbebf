"""Ray-scene intersection accelerators.

:func:`build_accel` (:mod:`~drpt.accel.registry`) returns an
:class:`~drpt.accel.protocol.Accelerator`:

* ``intersect(o, d, tmax, active=True) -> Hit`` -- closest hit with
  ``0 < t < tmax`` (:class:`~drpt.accel.protocol.Hit`: ``t`` = inf and
  ``prim`` = 0xFFFFFFFF on a miss, ``u, v`` triangle barycentrics, ``valid``);
* ``occluded(o, d, tmax, active=True) -> Bool`` -- any hit with ``0 < t < tmax``;
* ``build_seconds``, ``nbytes`` (device bytes) and ``stats`` (``nodes``,
  ``leaves``, ``max_depth``, ...).

Global primitive ids: triangles ``0..F-1``, spheres ``F..F+S-1``, planes
``F+S..F+S+P-1``, in the scene's original order.

Modules, one idea each:

* the kinds: :mod:`~drpt.accel.registry` (the kind table, ``"auto"``),
  :mod:`~drpt.accel.protocol` (the interface, ``Hit``, ``AccelParams``);
* the accelerators: :mod:`~drpt.accel.embree` (Embree 3's BVH queried from
  the kernels, the default above 64 primitives on the CPU; its bindings in
  :mod:`~drpt.accel.embree_lib`), :mod:`~drpt.accel.bvh4` (4-wide BVH, drpt's own),
  :mod:`~drpt.accel.bvh` (binary BVH), :mod:`~drpt.accel.grid`,
  :mod:`~drpt.accel.inline`, :mod:`~drpt.accel.brute`;
* what they share: :mod:`~drpt.accel.primitives` (primitive buffers, planes,
  primitive tests), :mod:`~drpt.accel.device` (uploads, slab test);
* the BVH build: :mod:`~drpt.accel.build` (``build_bvh``, the rule
  vocabulary), one module per rule (:mod:`~drpt.accel.build_topdown`:
  sah, median, threshold; :mod:`~drpt.accel.build_morton`;
  :mod:`~drpt.accel.build_ploc`), :mod:`~drpt.accel.tree` (the binary node
  layout and the builders' shared pieces), :mod:`~drpt.accel.bvh4_nodes`
  (the 4-wide layout and the collapse).
"""

from __future__ import annotations

from . import embree_lib
from .brute import BruteForce
from .build import AUTO_SAH_MAX, METHODS, NO_MIN_LEAF, SEED_SAH_THRESHOLD, build_bvh
from .bvh import BVH
from .bvh4 import BVH4
from .embree import EmbreeAccel
from .grid import UniformGrid
from .inline import InlineList
from .protocol import INVALID, Accelerator, AccelParams, Hit
from .registry import ACCELERATORS, KINDS, build_accel, resolve_kind

__all__ = ["ACCELERATORS", "AUTO_SAH_MAX", "BVH", "BVH4", "INVALID", "KINDS", "METHODS",
           "NO_MIN_LEAF", "SEED_SAH_THRESHOLD", "AccelParams", "Accelerator", "BruteForce",
           "EmbreeAccel", "Hit", "InlineList", "UniformGrid", "build_accel", "build_bvh",
           "embree_lib", "resolve_kind"]
