"""Cook-Torrance, metalness/roughness workflow: GGX + Smith + Fresnel specular
over a Burley diffuse lobe, sampled with GGX visible normals.

This lobe *is* the metallic/roughness subset of Mitsuba 3's ``principled``
BSDF (Burley 2012/2015 as implemented in ``src/bsdfs/principled.cpp``,
Mitsuba 3.9): ``base_color``, ``metallic``, ``roughness``, with every other
parameter at its default -- ``specular = 0.5`` (so ``eta = 1.5``),
``spec_tint = 0``, ``anisotropic = 0``, ``sheen = 0``, ``clearcoat = 0``,
``spec_trans = 0``, ``flatness = 0``, not ``thin``. ``eval`` reproduces
principled's ``eval`` formula for formula (checked against Mitsuba's own
``eval`` to 1e-4 relative in ``tests/render/bsdf/test_cook_torrance.py``), and the
lobe-selection probabilities are principled's too, so ``pdf`` equals
principled's ``pdf`` as well. It is *not* a textbook "F0 = lerp(0.04, kd,
m) Schlick + Lambert" Cook-Torrance: the differences are spelled out below.

Parameters (:class:`CookTorranceParams`)
----------------------------------------
``base_color`` (Array3f, ``c``), ``alpha`` (Float, the GGX width, see
below) and ``metalness`` (Float, ``m`` in [0, 1]).

Roughness-to-alpha mapping
--------------------------
drpt's parameter *is* the GGX ``alpha``; :mod:`drpt.materials.interpret` sets it to the
seed's ``Roughness^2`` (the seed's parser stores ``Roughness * Roughness`` and
its GGX squares that again), with ``Roughness = 0.95`` when absent.
Principled's ``roughness`` is the *perceptual* roughness ``r`` with
``alpha = r^2``, so the exporter (:mod:`drpt.export.mitsuba_bsdf`) writes
``roughness = sqrt(alpha)``, i.e. the seed's ``Roughness``. Inside the lobe:

* ``a = max(alpha, 1e-3)`` is the alpha of ``D`` and ``G`` (principled's
  clamp ``max(0.001, roughness^2)``), so alpha 0 renders as alpha 1e-3;
* ``r = sqrt(alpha)`` (unclamped) drives the diffuse retro-reflection term.

Formulas
--------
All directions local (``+z`` = normal), ``wi`` toward the viewer, ``wo``
toward the light; zero unless ``wi.z > 0`` and ``wo.z > 0``.
``h = normalize(wi + wo)``, ``c_h = dot(wi, h) = dot(wo, h)``,
``SW(x) = (1 - x)^5`` (Schlick weight, ``1 - x`` clamped to [0, 1])::

    f(wi, wo) = f_spec + f_diff

    f_spec = F(c_h) D(h) G1(wi, h) G1(wo, h) / (4 wi.z wo.z)
    F(c_h) = (1 - m) F_diel(c_h; eta = 1.5) + m (c + (1 - c) SW(c_h))

    f_diff = (1 - m) c / pi (f_d + f_r)
    f_d    = (1 - SW(wi.z) / 2) (1 - SW(wo.z) / 2)                   (Burley)
    R_r    = 2 r c_h^2
    f_r    = R_r (SW(wo.z) + SW(wi.z) + SW(wo.z) SW(wi.z) (R_r - 1))  (retro)

``D``, ``G1`` are GGX and Smith's GGX masking with alpha ``a``
(:class:`.microfacet.Distribution`, isotropic GGX, as principled's); G is *separable* (``G1 G1``, Mitsuba's choice), not
height-correlated. ``F_diel`` is the exact unpolarized Fresnel reflectance
of a dielectric interface with relative IOR ``eta = 2 / (1 - sqrt(0.08 *
0.5)) - 1 = 1.5`` (principled's ``specular = 0.5``)::

    cos_t = sqrt(1 - (1 - c_h^2) / eta^2)
    F_diel = ((c_h - eta cos_t)^2 / (c_h + eta cos_t)^2
              + (cos_t - eta c_h)^2 / (cos_t + eta c_h)^2) / 2      (1 at c_h = 0)

so the dielectric part has ``F0 = ((eta-1)/(eta+1))^2 = 0.04`` but the real
Fresnel curve, not Schlick's; the metallic part is Schlick with
``F0 = base_color``. ``eval`` returns ``f * wo.z``.

Differences from the textbook metal/rough model (worth knowing when
comparing with other renderers): the diffuse lobe is Burley's (with
retro-reflection growing with ``r``), not Lambert, and it is *not* reduced
by the specular Fresnel (only by ``1 - m``), so for ``m = 0`` the total
albedo can slightly exceed ``c`` (still <= 1 for ``c <= 1``: see the furnace
test); the dielectric Fresnel is exact, not Schlick; G is separable.
``f`` is reciprocal (every term is symmetric in ``wi``, ``wo``).

Sampling
--------
With ``u1`` pick the diffuse lobe with probability ``P_d = (1 - m) / (2 - m)``
(principled: weights ``1 - m`` for diffuse and 1 for the specular
reflection, normalized), else the specular lobe; with ``u2``:

* specular: a visible GGX normal ``n ~ D_wi``
  (:meth:`.microfacet.Distribution.sample_visible_normal`, the sampler
  principled uses), ``wo = reflect(wi, n)``; density
  ``D_wi(h) / (4 dot(wo, h))``;
* diffuse: cosine-weighted hemisphere, density ``wo.z / pi``.

``pdf = (1 - P_d) D_wi(h) / (4 dot(wo, h)) + P_d wo.z / pi``
(``= (1 - P_d) G1(wi, h) D(h) / (4 wi.z) + ...``: the code cancels
``dot(wi, h) / dot(wo, h) = 1`` analytically, which float32 would not do for
``wo ~ -wi`` at grazing angles -- Mitsuba does not cancel it, the only
numerical difference from principled's ``pdf``), evaluated at
the returned ``wo`` (the full mixture, as :func:`pdf` returns it and as
principled's ``pdf`` does), and ``weight = eval / pdf``. A reflected
direction below the surface is an invalid sample (weight 0, pdf 0). The
specular part of the weight is at most ``F G1(wo) / (1 - P_d) <= 2 - m``
and the diffuse part at most ``c (f_d + f_r)(2 - m)``, so weights stay
bounded (no fireflies from the BSDF itself).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Float

from ..warp import INV_PI, square_to_cosine_hemisphere
from . import BSDFSample
from .microfacet import Distribution, reflect

#: principled's ``specular`` parameter (its default) and the relative IOR it implies.
SPECULAR = 0.5
ETA = 2.0 / (1.0 - (0.08 * SPECULAR) ** 0.5) - 1.0  # = 1.5
#: principled's lower bound on the GGX alpha (``max(0.001, roughness^2)``).
ALPHA_MIN = 1e-3


#: Spec fields the material table uploads for this lobe (see :class:`drpt.render.bsdf.BSDF`).
FIELDS = {"kd": "rgb", "alpha": "float", "metalness": "float"}
#: The field the Whitted ambient term multiplies.
COLOR = "kd"
DELTA = False


class CookTorranceParams:
    """Per-lane parameters: ``base_color`` (Array3f), GGX ``alpha`` (Float in
    [0, 1]) and ``metalness`` (Float in [0, 1])."""

    DRJIT_STRUCT = {"base_color": Array3f, "alpha": Float, "metalness": Float}

    def __init__(self, base_color=None, alpha=None, metalness=None):
        self.base_color = base_color if base_color is not None else Array3f(0.5)
        self.alpha = alpha if alpha is not None else Float(0.25)
        self.metalness = metalness if metalness is not None else Float(0.0)


def params(table, si, active) -> CookTorranceParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return CookTorranceParams(table.value("kd", si, active), table.value("alpha", si, active),
                              table.value("metalness", si, active))


def _schlick_weight(c: Float) -> Float:
    x = dr.clip(1.0 - c, 0.0, 1.0)
    x2 = x * x
    return x2 * x2 * x


def fresnel_dielectric(cos_i: Float, eta: float = ETA) -> Float:
    """Unpolarized Fresnel reflectance from the outside (``cos_i >= 0``) of an
    interface with relative IOR ``eta > 1`` (no total internal reflection)."""
    c = dr.abs(cos_i)
    cos_t = dr.safe_sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    a_s = (c - eta * cos_t) / (c + eta * cos_t)
    a_p = (cos_t - eta * c) / (cos_t + eta * c)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    return dr.select(c == 0.0, 1.0, r)


def _alphas(p: CookTorranceParams):
    """The specular lobe's distribution and ``r``, the alpha the retro-reflection term reads."""
    alpha = dr.clip(p.alpha, 0.0, 1.0)
    return distribution(alpha), dr.sqrt(alpha)


def distribution(alpha: Float) -> Distribution:
    """The specular lobe: isotropic GGX of width ``max(alpha, ALPHA_MIN)``, sampled by
    visible normals (principled's main lobe, its clamp)."""
    return Distribution(False, alpha, alpha_min=ALPHA_MIN)


def diffuse_probability(p: CookTorranceParams) -> Float:
    """``P_d = (1 - m) / (2 - m)``: principled's lobe-selection weight."""
    m = dr.clip(p.metalness, 0.0, 1.0)
    return (1.0 - m) / (2.0 - m)


def _half(wi: Array3f, wo: Array3f, ok):
    h = dr.normalize(dr.select(ok, wi + wo, Array3f(0.0, 0.0, 1.0)))
    return h


def eval(p: CookTorranceParams, wi: Array3f, wo: Array3f) -> Array3f:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    d, r = _alphas(p)
    m = dr.clip(p.metalness, 0.0, 1.0)
    c = p.base_color
    h = _half(wi, wo, ok)
    c_h = dr.dot(wi, h)
    cos_i = dr.select(ok, wi.z, 1.0)

    # Specular: F D G / (4 cos_i cos_o), times cos_o.
    sw_h = _schlick_weight(c_h)
    F = (1.0 - m) * fresnel_dielectric(c_h) + m * (c + (1.0 - c) * sw_h)
    spec = F * (d.D(h) * d.G(wi, wo, h) / (4.0 * cos_i))

    # Burley diffuse with retro-reflection, times cos_o.
    fi, fo = _schlick_weight(wi.z), _schlick_weight(wo.z)
    f_d = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
    c_d = dr.dot(h, wo)
    rr = 2.0 * r * c_d * c_d
    f_r = rr * (fo + fi + fo * fi * (rr - 1.0))
    diff = ((1.0 - m) * INV_PI * wo.z * (f_d + f_r)) * c

    return dr.select(ok, spec + diff, 0.0)


def pdf(p: CookTorranceParams, wi: Array3f, wo: Array3f) -> Float:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    d, _ = _alphas(p)
    p_d = diffuse_probability(p)
    h = _half(wi, wo, ok)
    # D_wi(h) / (4 dot(wo, h)) = G1(wi, h) D(h) dot(wi, h) / (4 wi.z dot(wo, h));
    # dot(wi, h) = dot(wo, h) for a reflection, so the ratio is cancelled
    # analytically: in float32 the two dots differ wildly when wo ~ -wi at
    # grazing (h loses its horizontal part), and cancelling keeps the
    # specular weight exactly F G1(wo, h) <= 1 there.
    ok_h = (dr.dot(wi, h) > 0.0) & (dr.dot(wo, h) > 0.0)
    spec = d.G1(wi, h) * d.D(h) / (4.0 * dr.select(ok, wi.z, 1.0))
    spec = dr.select(ok_h, spec, 0.0)
    v = (1.0 - p_d) * spec + p_d * (INV_PI * wo.z)
    return dr.select(ok, v, 0.0)


def sample(p: CookTorranceParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    d, _ = _alphas(p)
    front = wi.z > 0.0
    pick_diffuse = u1 < diffuse_probability(p)
    wi_s = dr.select(front, wi, Array3f(0.0, 0.0, 1.0))  # keep the warp finite
    n = d.sample_visible_normal(wi_s, u2)
    wo_spec = dr.normalize(reflect(wi_s, n))
    wo = dr.select(pick_diffuse, square_to_cosine_hemisphere(u2), wo_spec)
    valid = front & (wo.z > 0.0) & (pick_diffuse | (dr.dot(wi_s, n) > 0.0))
    pd = dr.select(valid, pdf(p, wi, wo), 0.0)
    valid &= pd > 0.0
    f = eval(p, wi, wo)
    weight = dr.select(valid, f / dr.select(valid, pd, 1.0), 0.0)
    return BSDFSample(wo, weight, dr.select(valid, pd, 0.0), valid)
