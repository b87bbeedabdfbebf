"""Isotropic GGX (Trowbridge-Reitz) microfacet distribution: the normal
distribution ``D``, Smith's masking ``G1``/``G`` and visible-normal (VNDF)
sampling. Directions are local (``+z`` = macro-surface normal), unit length;
``alpha`` is the GGX width (the slope standard deviation / sqrt 2; *not* an
artist's "roughness": see :mod:`drpt.render.bsdf.cook_torrance` for that
mapping). Pure Dr.Jit, usable in symbolic loops.

Formulas (``m`` a microfacet normal, ``v`` a direction, ``a = alpha``)
-------------------------------------------------------------------
``D(m) = 1 / (pi a^2 (  (m.x^2 + m.y^2) / a^2 + m.z^2 )^2)``
    normalized so that ``integral D(m) m.z dm = 1``; 0 where ``m.z <= 0``
    (tested as ``D * m.z > 1e-20``, the same cut Mitsuba 3 makes).
``G1(v, m) = 2 / (1 + sqrt(1 + a^2 (v.x^2 + v.y^2) / v.z^2))``
    Smith's masking for GGX (``= 2 / (1 + sqrt(1 + a^2 tan^2 theta_v))``);
    1 when ``v.x = v.y = 0``; 0 when ``dot(v, m) v.z <= 0`` (the back of a
    facet cannot be seen).
``G(wi, wo, m) = G1(wi, m) G1(wo, m)``
    the *separable* (uncorrelated) form, as Mitsuba 3's
    ``MicrofacetDistribution::G`` (which ``principled`` uses).
``D_wi(m) = G1(wi, m) max(0, dot(wi, m)) D(m) / wi.z``
    the distribution of normals visible from ``wi`` (Heitz 2014); its
    integral over the sphere is exactly 1 for the Smith ``G1`` above.
    :func:`pdf_visible` returns it (0 when ``wi.z <= 0``).

Sampling: :func:`sample_visible` is Heitz 2018, "Sampling the GGX
Distribution of Visible Normals" (JCGT 7(4)): stretch ``wi`` by ``(a, a, 1)``
into the configuration with ``alpha = 1``, sample a point on the projected
hemisphere (a disk, the half away from ``wi`` squashed by
``(1 + cos theta)/2``), lift it onto the hemisphere and unstretch the
normal. Its density is exactly :func:`pdf_visible` (checked by a chi-square
test). Reflecting ``wi`` about ``m`` gives ``wo`` with density
``D_wi(m) / (4 dot(wo, m))``.

Robustness: every function clamps ``alpha`` to ``[ALPHA_MIN, 1]`` with
``ALPHA_MIN = 1e-4``, the clamp Mitsuba's microfacet plugins apply (the
``principled``-matching lobe clamps harder, to 1e-3, before calling here).
``D`` at ``a = 1e-4`` peaks at ``1/(pi a^2) ~ 3.2e7``: finite in float32.
Cosines down to 1e-6 (and exactly 0: ``G1 = 0``) give finite values.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Float

#: Smallest GGX alpha used (Mitsuba 3's clamp for its microfacet plugins).
ALPHA_MIN = 1e-4


def clamp_alpha(alpha) -> Float:
    return dr.clip(Float(alpha), ALPHA_MIN, 1.0)


def D(m: Array3f, alpha) -> Float:
    """GGX normal distribution, a density over the solid angle of ``m``
    normalized as ``integral D(m) cos(theta_m) dm = 1``."""
    a = clamp_alpha(alpha)
    x, y = m.x / a, m.y / a
    t = x * x + y * y + m.z * m.z
    d = dr.rcp(dr.pi * a * a * t * t)
    return dr.select(d * m.z > 1e-20, d, 0.0)


def G1(v: Array3f, m: Array3f, alpha) -> Float:
    """Smith masking of GGX for direction ``v`` and microfacet normal ``m``."""
    a = clamp_alpha(alpha)
    xy = dr.square(a * v.x) + dr.square(a * v.y)
    tan2 = xy / dr.square(v.z)  # +inf for v.z = 0 -> G1 = 0
    g = 2.0 / (1.0 + dr.sqrt(1.0 + tan2))
    g = dr.select(xy == 0.0, 1.0, g)
    return dr.select(dr.dot(v, m) * v.z <= 0.0, 0.0, g)


def G(wi: Array3f, wo: Array3f, m: Array3f, alpha) -> Float:
    """Separable Smith shadowing-masking ``G1(wi) G1(wo)``."""
    return G1(wi, m, alpha) * G1(wo, m, alpha)


def pdf_visible(wi: Array3f, m: Array3f, alpha) -> Float:
    """Density of :func:`sample_visible` (solid angle of ``m``)."""
    ok = (wi.z > 0.0)
    cos_im = dr.maximum(dr.dot(wi, m), 0.0)
    v = G1(wi, m, alpha) * cos_im * D(m, alpha) / dr.select(ok, wi.z, 1.0)
    return dr.select(ok, v, 0.0)


def sample_visible(wi: Array3f, alpha, u: Array2f) -> Array3f:
    """A microfacet normal visible from ``wi`` (``wi.z > 0``), density
    :func:`pdf_visible`. Heitz 2018 (see the module docs)."""
    a = clamp_alpha(alpha)
    # 1. stretch to the alpha = 1 configuration
    vh = dr.normalize(Array3f(a * wi.x, a * wi.y, wi.z))
    # 2. orthonormal basis around vh (t1 horizontal)
    lensq = vh.x * vh.x + vh.y * vh.y
    inv = dr.rsqrt(dr.select(lensq > 0.0, lensq, 1.0))
    t1 = dr.select(lensq > 0.0, Array3f(-vh.y * inv, vh.x * inv, 0.0), Array3f(1.0, 0.0, 0.0))
    t2 = dr.cross(vh, t1)
    # 3. uniform point on the disk, the half behind vh squashed
    r = dr.sqrt(u.x)
    s_phi, c_phi = dr.sincos(2.0 * dr.pi * u.y)
    p1 = r * c_phi
    p2 = r * s_phi
    s = 0.5 * (1.0 + vh.z)
    p2 = (1.0 - s) * dr.safe_sqrt(1.0 - p1 * p1) + s * p2
    # 4. lift onto the hemisphere
    nh = p1 * t1 + p2 * t2 + dr.safe_sqrt(1.0 - p1 * p1 - p2 * p2) * vh
    # 5. unstretch
    return dr.normalize(Array3f(a * nh.x, a * nh.y, dr.maximum(nh.z, 0.0)))


def reflect(wi: Array3f, m: Array3f) -> Array3f:
    """Mirror ``wi`` about ``m``: ``2 dot(wi, m) m - wi``."""
    return 2.0 * dr.dot(wi, m) * m - wi
