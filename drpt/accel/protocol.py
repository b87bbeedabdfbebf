"""What every accelerator returns: :class:`Hit`.

Global primitive ids: triangles ``0..F-1``, spheres ``F..F+S-1``, planes
``F+S..F+S+P-1``, in the scene's original order. Only hits with
``0 < t < tmax`` count (strictly positive, so a ray starting exactly on a
surface does not report ``t == 0``; rounding may still give tiny positive
``t`` there, so callers offset spawned rays).
"""

from __future__ import annotations

from drjit.auto import Bool, Float, UInt32

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
