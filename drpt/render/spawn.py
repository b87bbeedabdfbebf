"""Ray origins that leave a surface without hitting it again.

A hit point ``p`` computed in float32 lies off the surface it belongs to by
rounding error. A new ray started at ``p`` can hit that surface again at a
tiny ``t > 0`` (shadow acne), or start behind it (light leaks). Each hit
therefore carries a conservative bound ``err`` on the distance of ``p`` from
its primitive's float32 surface along the unit geometric normal ``ng``, and
:func:`origin` moves ``p`` by ``err`` along ``ng``, to the side the new ray
leaves toward. The bounds follow Pharr, Jakob and Humphreys, *Physically
Based Rendering* 4th ed., ch. 6.8 ("Managing Rounding Error"): a
per-component error box of the computation that produced ``p``, projected
on the normal, ``dot(|ng|, p_error)``. They are computed where the hit point
is computed (:meth:`drpt.render.surface.SurfaceData.interaction`,
:meth:`drpt.render.lights.area.AreaLights.sample`) from the primitive's own
data, so an object elsewhere in the scene, or the scene's size, changes
nothing, and a scene scaled by 1e-4 or 1e4 behaves as at 1.

This is chosen over Wächter and Binder's integer-ulp offset (Ray Tracing
Gems, ch. 6), which moves ``p`` by up to 256 ulps of its own coordinates with
an absolute ``1/32 * 1/65536`` near the origin: its ulp count ignores how
``p`` was computed (a point near the origin on a large triangle carries
errors of the triangle's size, not of ``p``'s), and the absolute floor is in
world units, large for a scene at 1e-4 and useless at 1e4.

With ``gamma(n) = n u / (1 - n u)`` and ``u = 2**-24`` (float32 unit roundoff):

* triangles (:func:`triangle_point`), ``p = p0 + (u e1 + v e2)`` with the
  edges of the accelerators' float32 vertices: ``gamma(3) * dot(|ng|, |p|)``
  for the rounding of ``p`` and of :func:`origin`'s own ``p + ng * err``,
  plus ``gamma(5) * |e|^3 / |e1 x e2|`` (``|e|^2 = |e1|^2 + |e2|^2``) for the
  interpolation ``u e1 + v e2`` and for the watertight test of the next ray,
  whose ``t`` has an error of the order of the triangle's size over its
  aspect (the accelerators have no conservative ``t`` bound like pbrt's
  ``deltaT``: it would cost every triangle test); the constant is measured
  (random slivers, grazing rays: a fourth of it still suffices);
* spheres (:func:`sphere_error`), ``p`` reprojected onto the sphere as
  ``c + r * normalize(p_hit - c)``: ``gamma(3) * dot(|n|, |p|) + gamma(12) * r``,
  the normalization's relative error on the radius and the ray/sphere
  quadratic's cancellation in ``|o - c|^2 - r^2`` for the next ray;
* planes ``dot(n, x) = offset`` (:func:`plane_error`), ``p`` reprojected onto
  the plane (:func:`plane_project`): ``gamma(10) * (dot(|n|, |p|) + |offset|)``,
  the residual's and reprojection's rounding and the plane test's own
  ``offset - dot(n, o)`` for the next ray.

The cost per bounce is some 30 flops and one square root, on data the
interaction already gathers (a plane hit also gathers the plane's offset).
Shadow rays toward a point on an area light end at that point moved off the
light the same way (toward the shading point), and
:data:`drpt.render.integrators.common.SHADOW_SHRINK` stops them a relative
``2**-12`` short of it.

A ray from the moved origin meets the scene as a ray from a moved surface would: far from
the origin (two float32 spacings at 4096) a sizable fraction of a nearby light's distance.
Where that matters with nothing to weigh it against (light subpaths),
:meth:`drpt.render.scene.DeviceScene.intersect_from` takes the hit as the parallel ray from
the point itself meets the same primitive (:func:`plane_shift`, :func:`triangle_shift`), and
the connections to the camera are traced from the camera
(:func:`drpt.render.integrators.ptracer.camera_segment`).

Limits: the offset is along the normal only. Far from the origin, where the
float32 spacing is a sizable fraction of the geometry (0.0625 at 1e6), a hit
within half a spacing of an edge rounds onto the adjacent face's plane, and a
ray from there can pass through that face: a closed box a few hundred
spacings across leaks light visibly at its edges, one 30000 spacings across
still rarely. Offsets there are a few spacings, so corners and contact
shadows change within that band.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array3f, Float

UNIT_ROUNDOFF = 2.0**-24


def gamma(n: int) -> float:
    """``n u / (1 - n u)``: bounds the relative error of ``n`` float32 roundings."""
    return n * UNIT_ROUNDOFF / (1.0 - n * UNIT_ROUNDOFF)


POINT_GAMMA = gamma(3)
SHAPE_GAMMA = gamma(5)
SPHERE_GAMMA = gamma(12)
PLANE_GAMMA = gamma(10)


def triangle_point(p0: Array3f, e1: Array3f, e2: Array3f, u: Float, v: Float
                   ) -> tuple[Array3f, Array3f, Float]:
    """The point ``p0 + (u e1 + v e2)`` of a triangle (``u, v >= 0``), its unit
    geometric normal ``normalize(cross(e1, e2))`` and the bound ``err`` of the
    point (its rounding, and the watertight test's for a ray starting there)."""
    p = p0 + (e1 * u + e2 * v)
    c = dr.cross(e1, e2)
    # |c|^2 ~ |e|^4 overflows float32 past edges of 4e9: normalize c by its largest component
    m = dr.maximum(dr.maximum(dr.abs(c.x), dr.abs(c.y)), dr.abs(c.z))
    c = c * dr.rcp(m)
    r = dr.rsqrt(dr.squared_norm(c))
    ng = c * r
    edges = dr.squared_norm(e1) + dr.squared_norm(e2)
    shape = edges * (dr.sqrt(edges) * r / m)  # |e|^3 / |e1 x e2|: a length, large for slivers
    return p, ng, dr.dot(dr.abs(ng), dr.abs(p)) * POINT_GAMMA + shape * SHAPE_GAMMA


def sphere_error(p: Array3f, r: Float, n: Array3f) -> Float:
    """Bound on the distance along unit ``n`` of ``p = c + r n`` from the
    sphere ``(c, r)``."""
    return dr.dot(dr.abs(n), dr.abs(p)) * POINT_GAMMA + r * SPHERE_GAMMA


def plane_error(p: Array3f, n: Array3f, offset: Float) -> Float:
    """Bound on the distance along unit ``n`` of ``p``, reprojected onto the
    plane ``dot(n, x) = offset`` by :func:`plane_project`, from that plane."""
    return (dr.dot(dr.abs(n), dr.abs(p)) + dr.abs(offset)) * PLANE_GAMMA


def plane_project(p: Array3f, n: Array3f, offset: Float) -> Array3f:
    """``p`` moved along unit ``n`` onto the plane ``dot(n, x) = offset``."""
    return p - n * (dr.dot(n, p) - offset)


def origin(p: Array3f, ng: Array3f, err: Float, d: Array3f) -> Array3f:
    """``p`` moved by ``err`` along ``ng`` to the side of direction ``d``."""
    return p + ng * dr.mulsign(err, dr.dot(ng, d))


def plane_shift(delta: Array3f, d: Array3f, n: Array3f) -> tuple[Float, Array3f]:
    """A ray ``(o, d)`` meets a plane of normal ``n`` (any length) at ``o + t d``; the ray
    moved by ``delta``, ``(o + delta, d)``, meets it at ``t + dt``, at the point moved by
    ``shift = delta + d dt`` (in the plane): ``(dt, shift)``, not finite where ``d`` is
    parallel to the plane."""
    dt = -dr.dot(delta, n) / dr.dot(d, n)
    return dt, delta + d * dt


def triangle_shift(e1: Array3f, e2: Array3f, delta: Array3f, d: Array3f
                   ) -> tuple[Float, Float, Float]:
    """:func:`plane_shift` on the triangle of edges ``e1, e2``: ``(dt, du, dv)``, the change
    of the hit's distance and of its barycentrics ``(u, v)`` (``p0 + u e1 + v e2``). The
    shift is small against the coordinates (it is computed alone, not from the moved point),
    so ``u + du`` is as accurate as ``u``."""
    c = dr.cross(e1, e2)
    m = dr.maximum(dr.maximum(dr.abs(c.x), dr.abs(c.y)), dr.abs(c.z))
    c = c * dr.rcp(m)  # (|c|^2 overflows past edges of 4e9: triangle_point)
    dt, s = plane_shift(delta, d, c)
    inv = dr.rcp(dr.squared_norm(c) * m)
    return dt, dr.dot(dr.cross(s, e2), c) * inv, dr.dot(dr.cross(e1, s), c) * inv
