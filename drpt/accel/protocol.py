"""What every accelerator provides (:class:`Accelerator`), what it returns
(:class:`Hit`) and what it is built from (:class:`AccelParams`).

Global primitive ids: triangles ``0..F-1``, spheres ``F..F+S-1``, planes
``F+S..F+S+P-1``, in the scene's original order. Only hits with
``0 < t < tmax`` count (strictly positive, so a ray starting exactly on a
surface does not report ``t == 0``; rounding may still give tiny positive
``t`` there, so callers offset spawned rays).

An accelerator is a class with a ``from_params(scene, params)`` constructor,
registered under its kind name in :data:`drpt.accel.registry.ACCELERATORS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from drjit.auto import Array3f, Bool, Float, UInt32

INVALID = 0xFFFFFFFF  # Hit.prim of a miss


class Hit:
    """Closest-hit record (a Dr.Jit PyTree: works with ``dr.select``, loops...).

    ``t`` (``inf`` when there is no hit), ``prim`` (global id, ``0xFFFFFFFF``
    when there is no hit), ``u, v`` (triangle barycentrics with
    ``p = p0 + u (p1 - p0) + v (p2 - p0)``, zero for spheres, planes and
    misses) and ``valid``.
    """

    DRJIT_STRUCT = {"t": Float, "prim": UInt32, "u": Float, "v": Float, "valid": Bool}

    def __init__(self, t=None, prim=None, u=None, v=None, valid=None):
        self.t = t if t is not None else Float(float("inf"))
        self.prim = prim if prim is not None else UInt32(INVALID)
        self.u = u if u is not None else Float(0)
        self.v = v if v is not None else Float(0)
        self.valid = valid if valid is not None else Bool(False)

    def __repr__(self):
        return f"Hit(t={self.t}, prim={self.prim}, u={self.u}, v={self.v}, valid={self.valid})"


@dataclass(frozen=True)
class AccelParams:
    """Build options of :func:`~drpt.accel.registry.build_accel`; each
    accelerator reads the ones that apply to it."""

    method: str = "auto"  # BVH split rule (drpt.accel.build.METHODS)
    leaf_size: int = 4  # maximum primitives per BVH leaf
    bins: int = 16  # SAH bins per axis
    resolution: int | None = None  # grid cells per axis (None: automatic)
    min_leaf: int = 1  # minimum primitives per BVH leaf
    sah_threshold: int | None = None  # K of the "threshold" rule


@runtime_checkable
class Accelerator(Protocol):
    """Ray queries over one scene's primitives.

    Attributes:
        build_seconds: host build time (bounds, structure, upload).
        nbytes: bytes of device arrays.
        stats: ``nodes``, ``leaves``, ``max_depth``, ``prims`` and the
            accelerator's own counts.
        coherent_gain: whether a SIMD packet of coherent rays (one pixel's camera rays)
            costs less than a packet of scattered ones: True for a traversal of a tree or
            grid, whose lanes then visit the same nodes; False where every ray costs the same
            (every primitive tested). The renderer gives each camera sample its own lane where
            it is True (:meth:`~drpt.render.renderer.Renderer._pass_lanes_per_pixel`).
    """

    build_seconds: float
    nbytes: int
    stats: dict
    coherent_gain: bool

    def intersect(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                  coherent: Bool | bool = False) -> Hit:
        """Closest hit with ``0 < t < tmax``. ``coherent`` marks the lanes whose rays are
        coherent (camera rays): a hint an accelerator may use (Embree's coherent
        traversal, as Mitsuba asks it for camera rays); the hits are the same."""
        ...

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool | bool = True,
                 coherent: Bool | bool = False) -> Bool:
        """Whether anything is hit with ``0 < t < tmax``. ``coherent``: as :meth:`intersect`'s
        (the shadow rays of camera-ray hits toward one light start at nearby points and share
        their direction); the answer is the same."""
        ...
