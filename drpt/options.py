"""Render options: what every command that renders passes to the renderer.

:class:`RenderOptions` is built in one place from command-line flags
(:mod:`drpt.cli`) and used by render and by every tool.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class PathOptions:
    max_depth: int = -1
    rr_depth: int = 5
    rr_prob: float | None = None  # fixed continuation probability, or adaptive


@dataclass
class RenderOptions:
    width: int = 256
    height: int = 256
    spp: int = 16
    seed: int = 0
    accel: str = "auto"  # drpt.accel.build_accel kind ("auto": inline for tiny scenes, else bvh)
    grid_resolution: int | None = None  # cells per axis for accel="grid" (None: automatic)
    bvh_method: str = "auto"  # BVH split rule, drpt.accel.METHODS (accel="bvh")
    sah_threshold: int | None = None  # K of bvh_method="threshold" (None: the seed's 2000)
    bvh_min_leaf: int = 1  # minimum primitives per BVH leaf (the seed's -resolution)
    bsdf: str = "phong"  # how MTL materials are read, see drpt.shading
    integrator: str = "path"  # "path" (MIS path tracing) or "whitted"
    env_sampling: str = "luminance"  # or "uniform" (for comparison only)
    path: PathOptions = field(default_factory=PathOptions)
    max_lanes: int = 1 << 21
    progress: bool = True
