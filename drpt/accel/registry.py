"""The accelerator kinds: one table from kind name to constructor, and the
``"auto"`` rule.

Adding an accelerator is one module (a class with the
:class:`~drpt.accel.protocol.Accelerator` queries and a
``from_params(scene, params)`` constructor) plus one entry in
:data:`ACCELERATORS`; :data:`KINDS` (the CLI's ``--accel`` choices) follows.
"""

from __future__ import annotations

from collections.abc import Callable

from .. import backend
from .brute import BruteForce
from .bvh import BVH
from .bvh4 import BVH4
from .embree import EmbreeAccel
from .embree_lib import reason as embree_unavailable
from .grid import UniformGrid
from .inline import InlineList
from .protocol import Accelerator, AccelParams

#: kind name -> constructor ``(scene, AccelParams) -> Accelerator``
ACCELERATORS: dict[str, Callable[..., Accelerator]] = {
    "bvh": BVH4.from_params,  # the 4-wide BVH, drpt.accel.bvh4
    "bvh2": BVH.from_params,  # the binary BVH it is collapsed from, drpt.accel.bvh
    "bvh4": BVH4.from_params,  # alias of "bvh"
    "embree": EmbreeAccel.from_params,  # Embree 3 queried from the kernels, drpt.accel.embree
    "grid": UniformGrid.from_params,  # uniform grid, 3D-DDA, drpt.accel.grid
    "inline": InlineList.from_params,  # primitives compiled into the kernel, drpt.accel.inline
    "brute": BruteForce.from_params,  # every ray against every primitive, drpt.accel.brute
}

KINDS = ("auto", *ACCELERATORS)


def resolve_kind(scene, kind: str = "auto", bvh_rule: bool = False) -> str:
    """The accelerator ``kind="auto"`` stands for: ``"inline"`` for scenes of at
    most ``inline_max_prims`` primitives (:func:`drpt.backend.policy`, read at
    each call); above, ``"embree"`` where it can run (the LLVM backend with
    Embree 3 installed, :func:`drpt.accel.embree_lib.reason`) unless
    ``bvh_rule`` (the caller asked for a BVH build rule, minimum leaf size or
    SAH threshold), else
    ``"bvh"``. Other kinds are returned unchanged."""
    if kind != "auto":
        return kind
    n = len(scene.triangles) + len(scene.spheres) + len(scene.planes)
    if n <= backend.policy().inline_max_prims:
        return "inline"
    if not bvh_rule and embree_unavailable() is None:
        return "embree"
    return "bvh"


def build_accel(scene, kind: str = "auto", method: str = "auto", leaf_size: int = 4,
                bins: int = 16, resolution: int | None = None, min_leaf: int = 1,
                sah_threshold: int | None = None) -> Accelerator:
    """Build the accelerator for ``scene``.

    Args:
        scene: a :class:`~drpt.scene.model.Scene`.
        kind: ``"auto"`` (the default: ``"inline"`` for tiny scenes, else
            ``"embree"`` where Embree 3 runs, else ``"bvh"``, see
            :func:`resolve_kind`), ``"embree"`` (Embree 3's BVH queried from
            the kernels, :mod:`drpt.accel.embree`), ``"inline"`` (every
            primitive's test compiled into the kernel with its data as
            constants, :mod:`drpt.accel.inline`), ``"bvh"`` (the 4-wide BVH,
            :mod:`drpt.accel.bvh4`; alias ``"bvh4"``), ``"bvh2"`` (the binary
            BVH it is collapsed from, :mod:`drpt.accel.bvh`: slower to
            trace, kept for comparison), ``"grid"`` (uniform grid, 3D-DDA) or
            ``"brute"`` (:data:`ACCELERATORS`).
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
    bvh_rule = method != "auto" or min_leaf != 1 or sah_threshold is not None
    kind = resolve_kind(scene, kind, bvh_rule)
    make = ACCELERATORS.get(kind)
    if make is None:
        raise ValueError(f"unknown accelerator kind {kind!r}; expected one of {', '.join(KINDS)}")
    return make(scene, AccelParams(method=method, leaf_size=leaf_size, bins=bins,
                                   resolution=resolution, min_leaf=min_leaf,
                                   sah_threshold=sah_threshold))
