"""Ray/plane intersection on Dr.Jit arrays.

Planes are ``dot(n, x) == offset`` and two-sided. A ray parallel to the plane
(``dot(n, d) == 0``) misses, even when it lies in the plane. Pure and
branch-free; misses give ``t = inf`` and never NaN.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array3f, Bool, Float

_INF = float("inf")


def intersect_plane(o: Array3f, d: Array3f, n: Array3f, offset: Float,
                    tmax: Float) -> tuple[Float, Bool]:
    """Ray/plane hit with ``0 < t < tmax``.

    Args:
        o, d: ray origin and direction (``t`` in units of ``d``).
        n, offset: the plane ``dot(n, x) == offset`` (``n`` need not be unit).
        tmax: upper bound (exclusive).

    Returns:
        ``(t, hit)``; ``t = inf`` where ``hit`` is false.
    """
    denom = dr.dot(n, d)
    ok = denom != 0
    t = (offset - dr.dot(n, o)) / dr.select(ok, denom, 1.0)
    hit = ok & (t > 0) & (t < tmax)
    return dr.select(hit, t, _INF), hit
