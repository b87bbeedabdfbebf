"""Ray/sphere intersection on Dr.Jit arrays.

Solves ``|o + t d - c|^2 = r^2`` with the numerically careful formulation of
Haines et al., "Precision Improvements for Ray/Sphere Intersection" (Ray
Tracing Gems, ch. 7):

* the discriminant is computed as ``a (r^2 - |f - (b/a) d|^2)`` with
  ``f = o - c``, ``b = dot(f, d)``, ``a = dot(d, d)``, which avoids the
  catastrophic cancellation of ``b^2 - a c`` for distant spheres;
* the roots use the stable pair ``q = -(b + sign(b) sqrt(disc))``,
  ``t0 = c/q``, ``t1 = q/a``.

The nearest root in ``(tmin, tmax)`` is returned: from outside this is the
entry point, from inside (``|f| < r``) the exit point. Pure and branch-free;
misses (including tangent-miss, ``q == 0`` and ``d == 0``) give ``t = inf``
and never NaN.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array3f, Bool, Float

_INF = float("inf")


def intersect_sphere(o: Array3f, d: Array3f, center: Array3f, radius: Float,
                     tmax: Float, tmin: Float | float = 0.0) -> tuple[Float, Bool]:
    """Nearest ray/sphere hit with ``tmin < t < tmax``.

    Args:
        o, d: ray origin and direction (``t`` in units of ``d``).
        center, radius: the sphere.
        tmax: upper bound (exclusive).
        tmin: lower bound (exclusive), default 0.

    Returns:
        ``(t, hit)``; ``t = inf`` where ``hit`` is false.
    """
    f = o - center
    a = dr.squared_norm(d)
    b = dr.dot(f, d)
    c = dr.squared_norm(f) - radius * radius
    a_ok = a > 0
    ra = dr.rcp(dr.select(a_ok, a, 1.0))
    g = f - (b * ra) * d
    disc = a * (radius * radius - dr.squared_norm(g))
    ok = a_ok & (disc >= 0)
    sq = dr.sqrt(dr.maximum(disc, 0.0))
    q = -(b + dr.copysign(sq, b))
    q_ok = q != 0
    t0 = dr.select(q_ok, c / dr.select(q_ok, q, 1.0), 0.0)
    t1 = q * ra
    lo = dr.minimum(t0, t1)
    hi = dr.maximum(t0, t1)
    use_lo = lo > tmin
    t = dr.select(use_lo, lo, hi)
    hit = ok & q_ok & (t > tmin) & (t < tmax)
    return dr.select(hit, t, _INF), hit
