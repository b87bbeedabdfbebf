"""Sample warps and local frames: maps from the unit square to directions
and points, each with its density. Pure Dr.Jit, usable inside symbolic loops.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Float

INV_PI = 1.0 / dr.pi


def concentric_polar(u: Array2f) -> tuple[Float, Float]:
    """``(r, phi)`` of :func:`square_to_uniform_disk_concentric`'s point ``r (cos phi,
    sin phi)`` (``r`` signed). A lobe that picks one of several warps per lane can take
    the sine and cosine of the picked angle once (``dr.sincos`` is the costly part) and
    still produce each warp's point to the float."""
    a = 2.0 * u.x - 1.0
    b = 2.0 * u.y - 1.0
    use_a = dr.abs(a) > dr.abs(b)
    r = dr.select(use_a, a, b)
    phi = dr.select(use_a, (dr.pi / 4.0) * (b / a), (dr.pi / 2.0) - (dr.pi / 4.0) * (a / b))
    phi = dr.select((a == 0) & (b == 0), 0.0, phi)
    return r, phi


def polar_to_disk(r: Float, phi: Float) -> Array2f:
    """The point ``r (cos phi, sin phi)``."""
    s, c = dr.sincos(phi)
    return Array2f(r * c, r * s)


def square_to_uniform_disk_concentric(u: Array2f) -> Array2f:
    """Uniform point on the unit disk: Shirley and Chiu's concentric map (no
    clumping at the rim), the mapping of Mitsuba's function of that name."""
    return polar_to_disk(*concentric_polar(u))


def disk_to_cosine_hemisphere(p: Array2f) -> Array3f:
    """A point ``p`` of the unit disk lifted to the hemisphere around +z (Malley)."""
    x, y = p.x, p.y
    z = dr.safe_sqrt(1.0 - x * x - y * y)
    return Array3f(x, y, z)


def square_to_cosine_hemisphere(u: Array2f) -> Array3f:
    """Cosine-weighted direction around +z (Malley: concentric disk, lifted)."""
    return disk_to_cosine_hemisphere(square_to_uniform_disk_concentric(u))


def cosine_hemisphere_pdf(cos_theta: Float) -> Float:
    """Solid-angle density of :func:`square_to_cosine_hemisphere` at a direction of
    ``cos_theta`` (its z): ``max(cos_theta, 0) / pi``, 0 below the horizon."""
    return dr.maximum(cos_theta, 0.0) * INV_PI


def square_to_uniform_sphere(u: Array2f) -> Array3f:
    """Uniform direction on the unit sphere (``z = 1 - 2 u.y``, azimuth ``2 pi u.x``);
    density ``1 / (4 pi)``."""
    z = 1.0 - 2.0 * u.y
    r = dr.safe_sqrt(1.0 - z * z)
    s, c = dr.sincos(2.0 * dr.pi * u.x)
    return Array3f(r * c, r * s, z)


def square_to_uniform_cone(u: Array2f, cos_cutoff: float) -> Array3f:
    """Uniform direction in the cone of half-angle ``acos(cos_cutoff)`` around +z;
    density ``1 / (2 pi (1 - cos_cutoff))``."""
    z = 1.0 - u.y * (1.0 - cos_cutoff)
    r = dr.safe_sqrt(1.0 - z * z)
    s, c = dr.sincos(2.0 * dr.pi * u.x)
    return Array3f(r * c, r * s, z)


def square_to_uniform_triangle(u: Array2f) -> Array2f:
    """Uniform barycentrics (b1, b2) on a triangle; b0 = 1 - b1 - b2."""
    t = dr.safe_sqrt(1.0 - u.x)
    return Array2f(1.0 - t, t * u.y)


#: the solid angles (sr) between which an emissive triangle is sampled by its spherical
#: triangle (:func:`spherical_triangle_sample`); outside, by area: below, float32 loses
#: the warp's precision and the gain is nil (the density varies little over a far or
#: tiny light); near 2 pi the warp's arcs degenerate (pbrt-v4's ``MinSphericalSampleArea``
#: and ``MaxSphericalSampleArea``)
SPHERICAL_MIN = 3e-4
SPHERICAL_MAX = 6.22


class SphericalTriangle:
    """The triangle ``(p0, p0 + e1, p0 + e2)`` seen from ``ref``: the unit directions
    ``a, b, c`` toward its corners and its solid angle ``omega`` (Van Oosterom and
    Strackee: ``tan(omega / 2) = |a . (b x c)| / (1 + a.b + b.c + c.a)``), and
    :attr:`sampled`, the lanes where :func:`spherical_triangle_sample` is used (``omega``
    between :data:`SPHERICAL_MIN` and :data:`SPHERICAL_MAX`): the one rule that both the
    sampling and the density of a hit apply."""

    def __init__(self, p0: Array3f, e1: Array3f, e2: Array3f, ref: Array3f):
        self.a = dr.normalize(p0 - ref)
        self.b = dr.normalize(p0 + e1 - ref)
        self.c = dr.normalize(p0 + e2 - ref)
        self.nab = dr.cross(self.a, self.b)
        self.triple = dr.abs(dr.dot(self.nab, self.c))
        cos_sum = 1.0 + dr.dot(self.a, self.b) + dr.dot(self.b, self.c) + dr.dot(self.c, self.a)
        self.omega = 2.0 * dr.atan2(self.triple, cos_sum)
        self.sampled = (self.omega >= SPHERICAL_MIN) & (self.omega <= SPHERICAL_MAX)


def spherical_triangle_sample(t: SphericalTriangle, u: Array2f) -> Array3f:
    """A direction uniform in the spherical triangle ``t`` (Arvo 1995, "Stratified
    sampling of spherical triangles"), density ``1 / t.omega``: ``u.x`` picks the area
    ``u.x omega`` of the sub-triangle ``(a, b, c')`` with ``c'`` on the arc from ``a`` to
    ``c``, ``u.y`` the point on the arc from ``b`` to ``c'`` (``1 - cos`` uniform). The
    angle ``alpha`` at ``a`` comes from the planes ``a x b`` and ``a x c``: its cosine
    from their dot product, its sine from ``|(a x b) x (a x c)| = |a . (b x c)|``."""
    a, b, c = t.a, t.b, t.c
    nac = dr.cross(a, c)
    inv = dr.rsqrt(dr.maximum(dr.squared_norm(t.nab) * dr.squared_norm(nac), 1e-36))
    cos_alpha = dr.dot(t.nab, nac) * inv
    sin_alpha = t.triple * inv
    s_area, c_area = dr.sincos(u.x * t.omega)
    s = s_area * cos_alpha - c_area * sin_alpha  # sin(area - alpha)
    tt = c_area * cos_alpha + s_area * sin_alpha  # cos(area - alpha)
    k1 = tt - cos_alpha
    k2 = s + sin_alpha * dr.dot(a, b)
    q = ((k2 * tt - k1 * s) * cos_alpha - k2) / dr.maximum((k2 * s + k1 * tt) * sin_alpha, 1e-30)
    q = dr.clip(q, -1.0, 1.0)
    c_perp = dr.normalize(c - a * dr.dot(c, a))
    cp = a * q + c_perp * dr.safe_sqrt(1.0 - q * q)
    z = 1.0 - u.y * (1.0 - dr.dot(cp, b))
    cp_perp = dr.normalize(cp - b * dr.dot(cp, b))
    return b * z + cp_perp * dr.safe_sqrt(1.0 - z * z)


def ray_triangle_barycentrics(o: Array3f, d: Array3f, p0: Array3f, e1: Array3f, e2: Array3f) -> Array2f:
    """The barycentrics ``(b1, b2)`` where the line ``o + t d`` meets the triangle's plane
    (Moller and Trumbore), clamped into the triangle."""
    s1 = dr.cross(d, e2)
    inv = dr.rcp(dr.dot(s1, e1))
    sp = o - p0
    b1 = dr.clip(dr.dot(sp, s1) * inv, 0.0, 1.0)
    b2 = dr.clip(dr.dot(d, dr.cross(sp, e1)) * inv, 0.0, 1.0)
    over = b1 + b2
    scale = dr.select(over > 1.0, dr.rcp(over), 1.0)
    b = Array2f(b1 * scale, b2 * scale)
    return dr.select(dr.isfinite(b.x) & dr.isfinite(b.y), b, Array2f(1.0 / 3.0, 1.0 / 3.0))


class Frame:
    """Orthonormal frame (s, t, n); ``to_local``/``to_world`` rotate vectors."""

    def __init__(self, n: Array3f):
        # Duff et al. 2017, "Building an orthonormal basis, revisited".
        sign = dr.copysign(1.0, n.z)
        a = -1.0 / (sign + n.z)
        b = n.x * n.y * a
        self.s = Array3f(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x)
        self.t = Array3f(b, sign + n.y * n.y * a, -n.y)
        self.n = n

    @classmethod
    def from_axes(cls, s: Array3f, t: Array3f, n: Array3f) -> Frame:
        """The frame of given axes (orthonormal; ``(s, t, -n)`` is a mirrored frame)."""
        f = cls.__new__(cls)
        f.s, f.t, f.n = s, t, n
        return f

    def to_local(self, v: Array3f) -> Array3f:
        """``v`` in this frame's coordinates, ``(v . s, v . t, v . n)``: ``n`` becomes +z."""
        return Array3f(dr.dot(v, self.s), dr.dot(v, self.t), dr.dot(v, self.n))

    def to_world(self, v: Array3f) -> Array3f:
        """The inverse of :meth:`to_local`: ``s v.x + t v.y + n v.z``."""
        return self.s * v.x + self.t * v.y + self.n * v.z
