"""Mitsuba 3's ``principled`` BSDF (Burley 2012/2015, ``src/bsdfs/principled.cpp``
and ``principledhelpers.h``, Mitsuba 3.9), every lobe: Burley diffuse with
retro-reflection and the "flatness" fake subsurface, sheen, the main GGX
specular (anisotropic, metallic, spec-tinted), rough specular transmission
(``spec_trans``, seen from both sides) and the GTR1 clearcoat.

``eval`` and ``pdf`` reproduce principled's formula for formula, with the
departures listed at the end (tested against Mitsuba's own plugin in
``tests/render/bsdf/test_principled.py``). ``sample`` draws the same lobes with the
same probabilities (its visible-normal warp is Heitz 2018's, Mitsuba's is
Heitz 2014's: the same density, other directions for the same ``u``).

Parameters (:class:`PrincipledParams`)
--------------------------------------
``c = base_color`` (rgb), ``r = roughness``, ``m = metallic``, ``st =
spec_trans``, ``aniso = anisotropic``, ``spec_tint``, ``sheen``,
``sheen_tint``, ``cc = clearcoat``, ``clearcoat_gloss``, ``flatness`` (all in
[0, 1]: :func:`derive` refuses a number outside, a texture's value is clipped
to it), the relative IOR ``eta`` and the three sampling rates ``s_d =
diffuse_reflectance_sampling_rate``, ``s_s = main_specular_sampling_rate``,
``s_c = clearcoat_sampling_rate`` (>= 0, default 1; Mitsuba's documentation
says 0 for the clearcoat rate, its code reads 1).

``eta`` (:func:`derive`): the ``eta`` parameter when given, else
``eta = 2 / (1 - sqrt(0.08 specular)) - 1`` (``specular`` 0.5 -> 1.5, the
Schlick ``F0 = 0.08 specular``). When the material transmits (``spec_trans``
given and not 0), ``eta = 1`` becomes 1.001 and ``specular = 0`` becomes
1e-3, as Mitsuba does. Mitsuba refuses ``eta`` and ``specular`` both given;
drpt's spec always has a ``specular`` (its default), so a given ``eta`` wins.

Weights ``brdf = (1 - m)(1 - st)`` (diffuse) and ``bsdf = (1 - m) st``
(transmission). GGX widths (Disney's mapping)::

    a = r^2, aspect = sqrt(1 - 0.9 aniso)
    alpha_x = max(1e-3, a / aspect),  alpha_y = max(1e-3, a * aspect)

(``alpha_x`` along the shading frame's ``+x``: the tangent.)

Frame and sides
---------------
principled is NOT two-sided: it sees the unflipped frame (``+z`` = the
shading normal = the outside). ``front = wi.z > 0``; ``wi.z == 0`` gives 0
everywhere. ``reflect = wi.z wo.z > 0``, ``refract = wi.z wo.z < 0``. From
the front every lobe below is active; from the back (``wi.z < 0``, inside the
object) only the dielectric specular reflection and the transmission are,
weighted by ``bsdf``, so a material with ``st = 0`` is black from behind.

Half vector and Fresnel
-----------------------
``eta_p = eta`` from the front, ``1 / eta`` from the back (the IOR ratio
across the surface along the path)::

    h = normalize(wi + wo)          (reflect)
    h = normalize(wi + eta_p wo)    (refract)
    h = h * sign(h.z)               (toward the outside)

``F = F_diel(dot(wi, h); eta)`` the exact unpolarized dielectric Fresnel
(:func:`fresnel`, Mitsuba's ``fresnel()`` operation for operation: 1 under
total internal reflection and at ``c_h = 0``, 0 for ``eta = 1``).
Micro/macro compatibility (``s = sign(wi.z)``): ``dot(wi, s h) > 0`` and ``dot(wo, s h) > 0`` for reflection,
``dot(wi, s h) > 0`` and ``dot(wo, -s h) > 0`` for refraction.

``D`` is anisotropic GGX, ``D(h) = 1 / (pi ax ay (h.x^2/ax^2 + h.y^2/ay^2
+ h.z^2)^2)`` (0 where ``D h.z <= 1e-20``), ``G = G1(wi) G1(wo)`` separable
Smith with ``G1(v) = 2 / (1 + sqrt(1 + ((ax v.x)^2 + (ay v.y)^2) / v.z^2))``
(1 at ``v = +-z``, 0 when ``dot(v, h) v.z <= 0``).
``SW(x) = clip(1 - x, 0, 1)^5``, ``Schlick(R0, c) = R0 + (1 - R0) SW(|c|)``
-- Mitsuba's ``calc_schlick``, which for ``eta < 1`` from the outside uses
the refracted cosine instead (0 beyond the critical angle).
``lum(c) = 0.212671 c.r + 0.715160 c.g + 0.072169 c.b`` and
``tint = c / lum(c)`` (1 when ``lum = 0``).

``eval(wi, wo) = f * |wo.z|``, the sum of
-------------------------------------------

main specular reflection (``reflect``, compatible, ``F > 0``)::

    F_p D(h) G / (4 |wi.z|)
    F_p = (1 - m)(1 - spec_tint) F + m Schlick(c, c_h)
          + (1 - m) spec_tint Schlick(tint ((eta - 1)/(eta + 1))^2, c_h)    (front)
    F_p = bsdf F                                                           (back)

with ``c_h = dot(wi, h)``;

specular transmission (``refract``, compatible, ``bsdf > 0``, ``F < 1``)::

    sqrt(c) bsdf (1 - F) D(h) G |dot(wi, h) dot(wo, h)|
        / (|wi.z| (dot(wi, h) + eta_p dot(wo, h))^2)

(Mitsuba's ``TransportMode::Radiance`` value: its ``1/eta_p^2`` radiance
scaling cancels the ``eta_p^2`` of the Jacobian; not reciprocal);

clearcoat (front, ``reflect``, compatible, ``cc > 0``)::

    0.25 cc Schlick(0.04, c_h) D_cc(h) G_cc |wo.z|
    D_cc(h) = (a^2 - 1) / (pi log(a^2) (1 + (a^2 - 1) h.z^2)),  a = lerp(0.1, 1e-3, clearcoat_gloss)
    G_cc = G1_0.25(wi) G1_0.25(wo)   (isotropic GGX Smith, alpha 0.25)

-- note there is no ``1 / (4 wi.z wo.z)``: Mitsuba's clearcoat is
``0.25 cc F D G cos_o``, Disney's ``G`` had that factor built in;

diffuse (front, ``reflect``, ``brdf > 0``), ``Fi = SW(|wi.z|)``, ``Fo =
SW(|wo.z|)``, ``c_d = dot(h, wo)``::

    brdf |wo.z| c / pi lerp(f_d + f_r, f_ss, flatness)
    f_d  = (1 - Fi/2)(1 - Fo/2)
    R_r  = 2 r c_d^2,  f_r = R_r (Fo + Fi + Fo Fi (R_r - 1))
    F_ss = lerp(1, R_r/2, Fo) lerp(1, R_r/2, Fi)
    f_ss = 1.25 (F_ss (1 / (|wo.z| + |wi.z|) - 0.5) + 0.5)

(``r`` here is the roughness itself, not ``r^2``, and not clamped);

sheen (front, ``reflect``, ``m < 1``, ``sheen > 0``; not gated by ``brdf``,
as in Mitsuba's JIT variants -- its scalar ones skip it when no lane has
``brdf > 0``)::

    sheen (1 - m) SW(|c_d|) lerp(1, tint, sheen_tint) |wo.z|

``pdf`` and ``sample``
----------------------
Lobe probabilities, normalized to sum 1 (``F`` at the sampled microfacet
in ``sample``, at ``h`` in ``pdf`` -- the same normal)::

    front: P_s = s_s (1 - bsdf (1 - F)), P_t = s_s bsdf (1 - F),
           P_c = 0.25 cc s_c, P_d = brdf s_d
    back:  P_s = F, P_t = 1 - F, P_c = P_d = 0

(from the front ``P_s + P_t = s_s`` whatever ``F``, so ``P_d``, ``P_c`` do
not depend on the microfacet and the mixture is a normalized density.)
``sample`` draws a GGX visible normal ``n ~ D_wi'`` for ``wi' = sign(wi.z)
wi`` (Heitz 2018, stretched by ``(ax, ay)``) and picks with ``u1``, in
Mitsuba's order: diffuse (cosine-weighted hemisphere), clearcoat (GTR1
normal ``cos^2 theta = (1 - a^(2 (1 - u.y))) / (1 - a^2)``, ``phi = 2 pi
u.x``, reflected), transmission (``wi`` refracted through ``n``) or the
main reflection (``wi`` reflected about ``n``). ``pdf`` is::

    P_s D_wi'(h) / (4 |dot(wo, h)|) + P_d wo.z / pi + P_c D_cc(h) h.z / (4 |dot(wo, h)|)   (reflect)
    P_t D_wi'(h) eta_p^2 |dot(wo, h)| / (dot(wi, h) + eta_p dot(wo, h))^2                 (refract)

with ``D_wi'(h) = G1(wi') |dot(wi, h)| D(h) / |wi.z|`` and each term only
where its compatibility mask holds. ``weight = eval / pdf`` at the returned
``wo`` (the whole mixture), ``BSDFSample.eta`` is ``eta_it`` (``eta`` from
the outside, ``1/eta`` from the inside) for a transmission, else 1;
``delta`` is False. A sample whose direction fails its lobe's side or
compatibility test, or whose pdf is 0, is invalid (weight 0, pdf 0).

Energy
------
principled does not conserve energy in general, exactly as Mitsuba's
(``tests/render/bsdf/test_principled.py`` pins it against Mitsuba's albedo): the
Burley diffuse is not reduced by the specular Fresnel and its
retro-reflection grows at grazing angles (white, roughness 1: albedo 1.05 at
normal incidence, 1.57 at 89 degrees), and the sheen and the clearcoat are
added on top of everything else. It does conserve it for pure metals
(``m = 1``: the weight is ``F G1(wo) <= 1`` per sample) and for the
dielectric specular/transmission pair (reflected plus transmitted flux
``<= 1`` once the radiance scaling ``1 / eta_it^2`` of a transmission is
undone: ``weight * BSDFSample.eta^2``).

Departures from Mitsuba (all tested)
------------------------------------
* From the back with ``bsdf = 0`` (``st = 0`` or ``m = 1``), ``pdf`` is 0:
  Mitsuba's is that of a specular reflection although its ``eval`` there is
  0 and its ``sample`` rejects (``pdf`` must be the density ``sample``
  draws with; a nonzero ``pdf`` for an impossible sample would only perturb
  MIS weights).
* The main reflection's ``D_wi'(h) / (4 dot(wo, h))`` is computed as
  ``G1(wi') D(h) / (4 |wi.z|)``: ``dot(wi, h) = dot(wo, h)`` for a
  reflection, cancelled analytically (float32 does not, at grazing ``wo ~
  -wi``). Same choice as :mod:`.cook_torrance`.
* All sampling rates 0 where nothing else is sampled (e.g. ``m = 1``, ``s_s
  = 0``): Mitsuba divides by 0 (NaN); drpt's pdf is 0 and samples invalid.
* Parameters clipped to [0, 1] (textures only: numbers are refused outside).

Trace-time specialization
-------------------------
As Mitsuba's ``m_has_*`` flags: :func:`params` reads
``table.specs_of("principled")`` and traces a lobe's code only when some
material of the scene has the parameter given non-zero (or as a texture):
:class:`Lobes`. Without any ``clearcoat`` no clearcoat code is traced, etc.
A lane whose own material has the parameter 0 gets the same value either
way (every such term is multiplied by its parameter, or, for
``anisotropic``, reduces to the isotropic widths), so one kernel serves all
the scene's principled materials. A :class:`PrincipledParams` built directly
traces every lobe unless given ``lobes``; :func:`from_params` builds one
from a spec's parameters with the lobes they need.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials.bsdf_kinds import defaults, given
from ..warp import INV_PI, concentric_polar, disk_to_cosine_hemisphere, polar_to_disk, square_to_cosine_hemisphere
from . import BSDFSample
from . import microfacet as mf
from .dielectric import transmission_importance

#: GGX widths are clamped to this (principled's ``max(0.001, ...)``).
ALPHA_MIN = 1e-3
#: Rec. 709 luminance weights (Mitsuba's ``luminance`` for RGB).
LUMINANCE = (0.212671, 0.715160, 0.072169)

#: the unit-range parameters (refused outside [0, 1] when numbers, clipped when textures)
UNIT = ("roughness", "metallic", "spec_tint", "anisotropic", "sheen", "sheen_tint", "clearcoat",
        "clearcoat_gloss", "spec_trans", "flatness")
RATES = ("diffuse_reflectance_sampling_rate", "main_specular_sampling_rate", "clearcoat_sampling_rate")

#: Per-material values the material table uploads (``eta_ratio`` comes from :func:`derive`).
FIELDS = {"base_color": "rgb", **{n: "float" for n in UNIT}, "eta_ratio": "float",
          **{n: "float" for n in RATES}}
DELTA = False
COLOR = "base_color"  # what the Whitted ambient term multiplies


@dataclass(frozen=True)
class Lobes:
    """Which optional parts to trace: Mitsuba's ``m_has_*`` flags, for a whole scene."""

    anisotropic: bool = True
    spec_trans: bool = True
    sheen: bool = True
    sheen_tint: bool = True
    flatness: bool = True
    spec_tint: bool = True
    metallic: bool = True
    clearcoat: bool = True


ALL = Lobes()
NONE = Lobes(**{f.name: False for f in fields(Lobes)})


def _number(v) -> bool:
    """A plain number (Python or numpy), not a texture (nor a bool)."""
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


_given = given  # Mitsuba's get_flag (drpt.materials.bsdf_kinds.given)


def lobes_of(specs) -> Lobes:
    """The :class:`Lobes` a list of principled specs (``.params`` dicts, or dicts) needs."""
    ps = [getattr(s, "params", s) for s in specs]
    return Lobes(**{f.name: any(_given(p.get(f.name, 0.0)) for p in ps) for f in fields(Lobes)})


def derive(params: dict) -> dict:
    """Host side: the relative IOR ``eta_ratio`` (from ``eta`` or ``specular``,
    with Mitsuba's clamps for transmitting materials), after checking the
    parameters. Raises ``ValueError`` for a bad one."""
    for name in UNIT:
        v = params.get(name, 0.0)
        if _number(v) and not (0.0 <= float(v) <= 1.0):
            raise ValueError(f"principled: {name} = {v!r} is outside [0, 1]")
    for name in RATES:
        v = params.get(name, 1.0)
        if not _number(v) or not (math.isfinite(v) and v >= 0.0):
            raise ValueError(f"principled: {name} = {v!r} must be a number >= 0")
    transmits = _given(params.get("spec_trans", 0.0))
    eta = params.get("eta")
    if eta is not None:
        if not _number(eta) or not (math.isfinite(eta) and eta > 0.0):
            raise ValueError(f"principled: eta = {eta!r} must be a number > 0")
        eta = float(eta)
        if transmits and eta == 1.0:
            eta = 1.001
    else:
        spec = params.get("specular", 0.5)
        if not _number(spec) or not (0.0 <= spec < 12.5):
            raise ValueError(f"principled: specular = {spec!r} must be a number in [0, 12.5)")
        spec = np.float32(spec)
        if transmits and spec == 0.0:
            spec = np.float32(1e-3)
        # in float32, as Mitsuba computes it (specular 0 -> exactly 1)
        one, two = np.float32(1.0), np.float32(2.0)
        eta = float(two / (one - np.sqrt(np.float32(0.08) * spec)) - one)
    return {"eta_ratio": eta}


class PrincipledParams:
    """Per-lane parameters (see the module docs); ``lobes`` (a Python
    :class:`Lobes`, not a Dr.Jit field) says which optional lobes to trace."""

    DRJIT_STRUCT = {"base_color": Array3f, **{n: Float for n in UNIT}, "eta": Float,
                    "rate_diffuse": Float, "rate_spec": Float, "rate_clearcoat": Float}
    lobes: Lobes = ALL

    def __init__(self, base_color=None, roughness=None, metallic=None, spec_tint=None,
                 anisotropic=None, sheen=None, sheen_tint=None, clearcoat=None, clearcoat_gloss=None,
                 spec_trans=None, flatness=None, eta=None, rate_diffuse=None, rate_spec=None,
                 rate_clearcoat=None, lobes=None):
        def f(v, default):
            return v if v is not None else Float(default)

        self.base_color = base_color if base_color is not None else Array3f(0.5)
        self.roughness = f(roughness, 0.5)
        self.metallic = f(metallic, 0.0)
        self.spec_tint = f(spec_tint, 0.0)
        self.anisotropic = f(anisotropic, 0.0)
        self.sheen = f(sheen, 0.0)
        self.sheen_tint = f(sheen_tint, 0.0)
        self.clearcoat = f(clearcoat, 0.0)
        self.clearcoat_gloss = f(clearcoat_gloss, 0.0)
        self.spec_trans = f(spec_trans, 0.0)
        self.flatness = f(flatness, 0.0)
        self.eta = f(eta, 1.5)
        self.rate_diffuse = f(rate_diffuse, 1.0)
        self.rate_spec = f(rate_spec, 1.0)
        self.rate_clearcoat = f(rate_clearcoat, 1.0)
        if lobes is not None:
            self.lobes = lobes


def from_params(params: dict, lobes: Lobes | None = None) -> PrincipledParams:
    """A one-lane record straight from a spec's parameters (Mitsuba's names,
    numbers only; missing ones at their defaults), through :func:`derive` --
    what the material table produces for a material, without a table.
    ``lobes=None`` traces the lobes these parameters need."""
    prm = {**defaults("principled"), **params}
    eta = derive(prm)["eta_ratio"]

    def f(v):  # opaque: one kernel serves every parameter value
        return dr.opaque(Float, float(v), 1)

    vals = {n: f(prm[n]) for n in UNIT}
    c = prm["base_color"]
    return PrincipledParams(base_color=Array3f(f(c[0]), f(c[1]), f(c[2])), eta=f(eta),
                            rate_diffuse=f(prm[RATES[0]]), rate_spec=f(prm[RATES[1]]),
                            rate_clearcoat=f(prm[RATES[2]]),
                            lobes=lobes if lobes is not None else lobes_of([prm]), **vals)


#: record field -> lobe flag that needs it (others are always gathered)
_NEEDS = {"anisotropic": "anisotropic", "spec_trans": "spec_trans", "sheen": "sheen",
          "sheen_tint": "sheen_tint", "flatness": "flatness", "spec_tint": "spec_tint",
          "metallic": "metallic", "clearcoat": "clearcoat", "clearcoat_gloss": "clearcoat",
          "rate_clearcoat": "clearcoat"}
_SOURCE = {"rate_diffuse": "diffuse_reflectance_sampling_rate", "rate_spec": "main_specular_sampling_rate",
           "rate_clearcoat": "clearcoat_sampling_rate", "eta": "eta_ratio"}


def params(table, si, active) -> PrincipledParams:
    """The lanes' parameters from the material table; only the fields of the
    lobes some principled material of the scene uses are gathered."""
    lobes = lobes_of(table.specs_of("principled"))
    rough = dr.clip(table.value("roughness", si, active), 0.0, 1.0)
    n = dr.width(rough)
    vals = {"base_color": table.value("base_color", si, active), "roughness": rough}
    for name in PrincipledParams.DRJIT_STRUCT:
        if name in vals:
            continue
        if name in _NEEDS and not getattr(lobes, _NEEDS[name]):
            vals[name] = dr.zeros(Float, n)
            continue
        v = table.value(_SOURCE.get(name, name), si, active)
        vals[name] = dr.clip(v, 0.0, 1.0) if name in UNIT else v
    return PrincipledParams(**vals, lobes=lobes)


# ------------------------------------------------------------------ helpers
def _sw(x: Float) -> Float:
    """Schlick weight ``clip(1 - x, 0, 1)^5``."""
    t = dr.clip(1.0 - x, 0.0, 1.0)
    t2 = t * t
    return t2 * t2 * t


def _schlick(r0, cos_i: Float, eta: Float):
    """Mitsuba's ``calc_schlick(R0, cos_i, eta)``: ``lerp(SW(|cos|), 1, R0)``,
    with the refracted cosine when the far side is the less dense."""
    outside = cos_i >= 0.0
    rcp = dr.rcp(eta)
    eta_it = dr.select(outside, eta, rcp)
    eta_ti = dr.select(outside, rcp, eta)
    cos_t = dr.safe_sqrt(1.0 - (1.0 - cos_i * cos_i) * dr.square(eta_ti))
    w = dr.select(eta_it > 1.0, _sw(dr.abs(cos_i)), _sw(cos_t))
    return r0 + (1.0 - r0) * w


def fresnel(cos_i: Float, eta: Float):
    """Unpolarized dielectric Fresnel ``(F, cos_t, eta_it, eta_ti)`` written as
    Mitsuba's ``fresnel()`` (``cos_t^2 = 1 - (1 - cos_i^2) eta_ti^2`` with its
    fused multiply-adds), so that ``1 - F`` rounds as Mitsuba's does near the
    critical angle, where it is ill-conditioned in float32. ``F = 0`` for
    ``eta = 1``, 1 at ``cos_i = 0`` and under total internal reflection;
    ``cos_t`` is signed (opposite to ``cos_i``)."""
    outside = cos_i >= 0.0
    rcp = dr.rcp(eta)
    eta_it = dr.select(outside, eta, rcp)
    eta_ti = dr.select(outside, rcp, eta)
    cos_t2 = dr.fma(-dr.fma(-cos_i, cos_i, 1.0), eta_ti * eta_ti, 1.0)
    ci = dr.abs(cos_i)
    ct = dr.safe_sqrt(cos_t2)
    a_s = dr.fma(-eta_it, ct, ci) / dr.fma(eta_it, ct, ci)
    a_p = dr.fma(-eta_it, ci, ct) / dr.fma(eta_it, ci, ct)
    f = 0.5 * (dr.square(a_s) + dr.square(a_p))
    matched = eta == 1.0
    f = dr.select(matched | (ci == 0.0), dr.select(matched, 0.0, 1.0), f)
    return f, dr.mulsign(-ct, cos_i), eta_it, eta_ti


def _luminance(c: Array3f) -> Float:
    return c.x * LUMINANCE[0] + c.y * LUMINANCE[1] + c.z * LUMINANCE[2]


def _tint(c: Array3f) -> Array3f:
    lum = _luminance(c)
    return dr.select(lum > 0.0, c / dr.select(lum > 0.0, lum, 1.0), Array3f(1.0))


def alphas(p: PrincipledParams):
    """``(alpha_x, alpha_y)`` of the main GGX lobe (``alpha_y`` None: isotropic)."""
    r2 = dr.square(p.roughness)
    if not p.lobes.anisotropic:
        return dr.maximum(ALPHA_MIN, r2), None
    aspect = dr.sqrt(1.0 - 0.9 * p.anisotropic)
    return dr.maximum(ALPHA_MIN, r2 / aspect), dr.maximum(ALPHA_MIN, r2 * aspect)


def distribution(p: PrincipledParams) -> mf.Distribution:
    """The main lobe's GGX (visible-normal sampling), :class:`.microfacet.Distribution`."""
    return mf.Distribution(False, *alphas(p))


def _cc_alpha(p: PrincipledParams) -> Float:
    return dr.lerp(0.1, 0.001, p.clearcoat_gloss)


def gtr1_D(m: Array3f, a: Float) -> Float:
    """GTR1 (Berry) distribution of the clearcoat (0 where ``D m.z <= 1e-20``)."""
    a2 = a * a
    d = (a2 - 1.0) / (dr.pi * dr.log(a2) * (1.0 + (a2 - 1.0) * dr.square(m.z)))
    return dr.select(d * m.z > 1e-20, d, 0.0)


def gtr1_sample(a: Float, u: Array2f, cs: Array2f | None = None) -> Array3f:
    """A clearcoat normal (density ``gtr1_D(m, a) m.z``); ``cs``: ``(cos, sin)`` of its
    azimuth ``2 pi u.x``, when the caller has them."""
    if cs is None:
        s_phi, c_phi = dr.sincos(2.0 * dr.pi * u.x)
    else:
        c_phi, s_phi = cs.x, cs.y
    a2 = a * a
    cos2 = (1.0 - dr.power(a2, 1.0 - u.y)) / (1.0 - a2)
    sin_t = dr.sqrt(dr.maximum(0.0, 1.0 - cos2))
    cos_t = dr.sqrt(dr.maximum(0.0, cos2))
    return Array3f(c_phi * sin_t, s_phi * sin_t, cos_t)


def _smith_iso(v: Array3f, m: Array3f, a: float) -> Float:
    """principled's ``smith_ggx1`` (the clearcoat's masking, isotropic alpha ``a``)."""
    c2 = dr.square(v.z)
    tan2 = (1.0 - c2) / c2
    g = 2.0 / (1.0 + dr.sqrt(1.0 + a * a * tan2))
    g = dr.select(v.z == 1.0, 1.0, g)
    return dr.select(dr.dot(v, m) * v.z <= 0.0, 0.0, g)


def _reflect(wi: Array3f, m: Array3f) -> Array3f:
    return 2.0 * dr.dot(wi, m) * m - wi


def _weights(p: PrincipledParams):
    """``(1 - m, brdf, bsdf)``: the non-metallic, diffuse and transmission weights."""
    n = dr.width(p.roughness)
    m = p.metallic if p.lobes.metallic else dr.zeros(Float, n)
    st = p.spec_trans if p.lobes.spec_trans else dr.zeros(Float, n)
    one_m = 1.0 - m
    return one_m, one_m * (1.0 - st), one_m * st


class _Geometry:
    """What eval and pdf share for a (wi, wo) pair."""

    def __init__(self, p: PrincipledParams, wi: Array3f, wo: Array3f):
        self.cos_i, self.cos_o = wi.z, wo.z
        self.active = self.cos_i != 0.0
        self.front = self.cos_i > 0.0
        self.reflect = self.cos_i * self.cos_o > 0.0
        self.refract = self.cos_i * self.cos_o < 0.0
        self.eta_p = dr.select(self.front, p.eta, dr.rcp(p.eta))
        v = wi + wo * dr.select(self.reflect, 1.0, self.eta_p)
        ok = dr.squared_norm(v) > 0.0
        h = dr.normalize(dr.select(ok, v, Array3f(0.0, 0.0, 1.0)))
        self.h = h = dr.mulsign(h, h.z)
        self.wi_h, self.wo_h = dr.dot(wi, h), dr.dot(wo, h)
        s = dr.mulsign(h, self.cos_i)  # the microfacet normal on the viewer's side
        self.compat_r = ok & (dr.dot(wi, s) > 0.0) & (dr.dot(wo, s) > 0.0)
        self.compat_t = ok & (dr.dot(wi, s) > 0.0) & (dr.dot(wo, -s) > 0.0)
        self.F = fresnel(self.wi_h, p.eta)[0]
        self.dist = distribution(p)
        self.one_m, self.brdf, self.bsdf = _weights(p)


def eval(p: PrincipledParams, wi: Array3f, wo: Array3f) -> Array3f:
    g = _Geometry(p, wi, wo)
    lb = p.lobes
    c = p.base_color
    abs_i, abs_o = dr.abs(g.cos_i), dr.abs(g.cos_o)
    safe_i = dr.select(g.active, abs_i, 1.0)
    D = g.dist.D(g.h)
    G = g.dist.G(wi, wo, g.h)
    value = Array3f(0.0)

    # main specular reflection
    spec_on = g.active & g.reflect & g.compat_r & (g.F > 0.0)
    f_front = (g.one_m * (1.0 - (p.spec_tint if lb.spec_tint else 0.0))) * g.F
    f_front = Array3f(f_front)
    if lb.metallic:
        f_front += p.metallic * _schlick(c, g.wi_h, p.eta)
    if lb.spec_tint:
        eta_it = dr.select(g.wi_h >= 0.0, p.eta, dr.rcp(p.eta))
        r0 = dr.square((eta_it - 1.0) / (eta_it + 1.0))
        f_front += (g.one_m * p.spec_tint) * _schlick(_tint(c) * r0, g.wi_h, p.eta)
    F_p = dr.select(g.front, f_front, Array3f(g.bsdf * g.F))
    value += dr.select(spec_on, F_p * (D * G / (4.0 * safe_i)), 0.0)

    # specular transmission
    if lb.spec_trans:
        on = g.active & (g.bsdf > 0.0) & g.refract & g.compat_t & (g.F < 1.0)
        den = dr.square(g.wi_h + g.eta_p * g.wo_h)
        den = dr.select(on & (den > 0.0), den, 1.0)
        t = g.bsdf * dr.abs((1.0 - g.F) * D * G * g.wi_h * g.wo_h / (safe_i * den))
        value += dr.select(on, dr.sqrt(dr.maximum(c, 0.0)) * t, 0.0)

    # clearcoat
    if lb.clearcoat:
        on = g.active & (p.clearcoat > 0.0) & g.reflect & g.compat_r & g.front
        fcc = _schlick(0.04, g.wi_h, p.eta)
        dcc = gtr1_D(g.h, _cc_alpha(p))
        gcc = _smith_iso(wi, g.h, 0.25) * _smith_iso(wo, g.h, 0.25)
        value += Array3f(dr.select(on, (p.clearcoat * 0.25) * fcc * dcc * gcc * abs_o, 0.0))

    # diffuse, retro-reflection, fake subsurface
    on = g.active & (g.brdf > 0.0) & g.reflect & g.front
    fo, fi = _sw(abs_o), _sw(abs_i)
    f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
    cos_d = dr.dot(g.h, wo)
    rr = 2.0 * p.roughness * dr.square(cos_d)
    f = f_diff + rr * (fo + fi + fo * fi * (rr - 1.0))
    if lb.flatness:
        fss90 = 0.5 * rr
        fss = dr.lerp(1.0, fss90, fo) * dr.lerp(1.0, fss90, fi)
        sum_io = dr.select(on, abs_o + abs_i, 1.0)
        f_ss = 1.25 * (fss * (1.0 / sum_io - 0.5) + 0.5)
        f = dr.lerp(f, f_ss, p.flatness)
    value += dr.select(on, c * (g.brdf * abs_o * INV_PI * f), 0.0)

    # sheen
    if lb.sheen:
        on = g.active & (p.sheen > 0.0) & g.reflect & (g.one_m > 0.0) & g.front
        w = p.sheen * g.one_m * _sw(dr.abs(cos_d)) * abs_o
        c_sheen = dr.lerp(Array3f(1.0), _tint(c), p.sheen_tint) if lb.sheen_tint else Array3f(1.0)
        value += dr.select(on, c_sheen * w, 0.0)

    return dr.select(g.active, value, 0.0)


def _probabilities(p: PrincipledParams, front, F, bsdf, brdf):
    """Normalized lobe probabilities (diffuse, clearcoat, transmission, reflection) and
    whether any lobe can be sampled at all."""
    lb = p.lobes
    zero = dr.zeros(Float, dr.width(F))
    ps = dr.select(front, p.rate_spec * (1.0 - bsdf * (1.0 - F)), F)
    pt = dr.select(front, p.rate_spec * bsdf * (1.0 - F), 1.0 - F) if lb.spec_trans else zero
    pc = dr.select(front, 0.25 * p.clearcoat * p.rate_clearcoat, 0.0) if lb.clearcoat else zero
    pd = dr.select(front, brdf * p.rate_diffuse, 0.0)
    tot = ps + pt + pc + pd
    # from the inside only a transmitting material is sampled (Mitsuba's sample)
    ok = (tot > 0.0) & (front | (bsdf > 0.0))
    inv = dr.select(ok, dr.rcp(dr.select(ok, tot, 1.0)), 0.0)
    return pd * inv, pc * inv, pt * inv, ps * inv, ok


def importance_scale(p: PrincipledParams, wi: Array3f, wo: Array3f) -> Float:
    """The factor from :func:`eval`'s radiance-mode value to importance mode's (a light
    subpath's vertex): ``eta_p^2`` where ``wi`` and ``wo`` lie on opposite sides (the
    specular transmission, the one lobe there; its radiance scaling undone), else 1:
    :func:`~drpt.render.bsdf.dielectric.transmission_importance`."""
    return transmission_importance(p.eta, wi, wo)


def pdf(p: PrincipledParams, wi: Array3f, wo: Array3f) -> Float:
    g = _Geometry(p, wi, wo)
    lb = p.lobes
    pd, pc, pt, ps, ok = _probabilities(p, g.front, g.F, g.bsdf, g.brdf)
    safe_i = dr.select(g.active, dr.abs(g.cos_i), 1.0)
    D = g.dist.D(g.h)
    g1 = g.dist.G1(wi, g.h)  # = G1(wi_up, h) to the float (G1 is even in v); eval's
    refl = g.reflect & g.compat_r
    # D_wi'(h) / (4 |dot(wo, h)|), dot(wi, h) = dot(wo, h) cancelled (see the module docs)
    v = dr.select(refl, ps * (g1 * D / (4.0 * safe_i)), 0.0)
    v += dr.select(g.reflect, pd * (INV_PI * dr.abs(g.cos_o)), 0.0)
    if lb.spec_trans:
        on = g.refract & g.compat_t
        den = dr.square(g.wi_h + g.eta_p * g.wo_h)
        den = dr.select(on & (den > 0.0), den, 1.0)
        d_wi = g1 * dr.abs(g.wi_h) * D / safe_i
        v += dr.select(on, pt * d_wi * (dr.square(g.eta_p) * dr.abs(g.wo_h) / den), 0.0)
    if lb.clearcoat:
        wo_h = dr.select(refl, dr.abs(g.wo_h), 1.0)
        dcc = gtr1_D(g.h, _cc_alpha(p)) * dr.maximum(g.h.z, 0.0)
        v += dr.select(refl, pc * dcc / (4.0 * wo_h), 0.0)
    return dr.select(g.active & ok, v, 0.0)


def sample(p: PrincipledParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    lb = p.lobes
    cos_i = wi.z
    n_lanes = max(dr.width(wi), dr.width(u1), dr.width(u2))
    active = cos_i != 0.0
    front = cos_i > 0.0
    _, brdf, bsdf = _weights(p)
    wi_up = dr.mulsign(wi, cos_i)
    wi_up = dr.select(active, wi_up, Array3f(0.0, 0.0, 1.0))
    n = distribution(p).sample_visible_normal(wi_up, u2)
    F, cos_t, eta_it, eta_ti = fresnel(dr.dot(wi, n), p.eta)
    pd, pc, pt, ps, ok = _probabilities(p, front, F, bsdf, brdf)
    active &= ok

    pick_d = u1 < pd
    no = dr.zeros(Bool, n_lanes)
    pick_c = (u1 >= pd) & (u1 < pd + pc) if lb.clearcoat else no
    pick_t = (u1 >= pd + pc) & (u1 < pd + pc + pt) if lb.spec_trans else no
    pick_r = ~(pick_d | pick_c | pick_t)

    s = dr.mulsign(n, cos_i)
    wo_r = _reflect(wi, n)
    wo = wo_r
    valid = pick_r & (cos_i * wo_r.z > 0.0) & (dr.dot(wi, s) > 0.0) & (dr.dot(wo_r, s) > 0.0)
    eta = dr.full(Float, 1.0, n_lanes)
    if lb.spec_trans:
        wo_t = n * (dr.dot(wi, n) * eta_ti + cos_t) - wi * eta_ti
        ok_t = (cos_i * wo_t.z < 0.0) & (dr.dot(wi, s) > 0.0) & (dr.dot(wo_t, -s) > 0.0)
        wo = dr.select(pick_t, wo_t, wo)
        valid |= pick_t & ok_t
        eta = dr.select(pick_t, eta_it, eta)
    if lb.clearcoat:
        # one sincos for the clearcoat's azimuth and the cosine hemisphere's disk point
        r_h, phi_h = concentric_polar(u2)
        disk = polar_to_disk(dr.select(pick_c, 1.0, r_h), dr.select(pick_c, 2.0 * dr.pi * u2.x, phi_h))
        wo_d = disk_to_cosine_hemisphere(disk)
        n_cc = gtr1_sample(_cc_alpha(p), u2, disk)
        wo_c = _reflect(wi, n_cc)
        s_c = dr.mulsign(n_cc, cos_i)
        ok_c = (cos_i * wo_c.z > 0.0) & (dr.dot(wi, s_c) > 0.0) & (dr.dot(wo_c, s_c) > 0.0)
        wo = dr.select(pick_c, wo_c, wo)
        valid |= pick_c & ok_c
    else:
        wo_d = square_to_cosine_hemisphere(u2)
    wo = dr.select(pick_d, wo_d, wo)
    valid |= pick_d & (cos_i * wo_d.z > 0.0)
    valid &= active

    wo = dr.select(valid, wo, Array3f(0.0, 0.0, 1.0))
    pdf_v = pdf(p, wi, wo)
    valid &= pdf_v > 0.0
    f = eval(p, wi, wo)
    weight = dr.select(valid, f / dr.select(valid, pdf_v, 1.0), 0.0)
    return BSDFSample(wo, weight, dr.select(valid, pdf_v, 0.0), valid,
                      dr.zeros(Bool, n_lanes), dr.select(valid, eta, 1.0))
