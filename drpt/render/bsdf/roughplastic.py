"""Rough plastic: Mitsuba 3's ``roughplastic`` plugin (``src/bsdfs/roughplastic.cpp``).

A diffuse base under a *rough* dielectric coating: a microfacet specular
lobe (Beckmann or GGX, isotropic ``alpha``) over a diffuse lobe scaled by the
coating's transmittance on the way in and out. One-sided, as Mitsuba's
plugin: zero unless ``wi.z > 0`` and ``wo.z > 0``. Neither lobe is a Dirac
(``DELTA = False``, ``BSDFSample.delta`` always False).

Parameters (Mitsuba's names and defaults, :data:`drpt.materials.bsdf_kinds.PARAMS`)
-------------------------------------------------------------------------
``diffuse_reflectance`` ``rho_d`` (rgb or texture, 0.5),
``specular_reflectance`` ``k_s`` (rgb or texture, 1), ``int_ior``
(polypropylene), ``ext_ior`` (air) -- numbers or Mitsuba's names,
``eta = int_ior / ext_ior``, which must not be 1 (Mitsuba refuses it:
``ValueError``) -- ``nonlinear`` (False), ``distribution`` (``"beckmann"``
or ``"ggx"``), ``alpha`` (0.1, clamped to >= 1e-4 as Mitsuba; isotropic
only: ``alpha_u``/``alpha_v`` are refused, as Mitsuba refuses anisotropic
roughness), ``sample_visible`` (True).

Formulas
--------
``D``, ``G1`` are Mitsuba's distribution (:class:`.microfacet.Distribution`),
``G = G1(wi, H) G1(wo, H)``, ``H = normalize(wi + wo)``, ``F`` the exact
dielectric Fresnel reflectance (:func:`.plastic.fresnel`)::

    f_spec cos = k_s F(wi.H) D(H) G / (4 wi.z)
    f_diff cos = rho' T(wi.z) T(wo.z) / eta^2 wo.z / pi
    rho' = rho_d / (1 - R_int)           (linear)
    rho' = rho_d / (1 - rho_d R_int)     (nonlinear)

``T(mu)`` is the external transmittance of the rough interface and
``R_int`` the internal reflectance scalar, precomputed host side in
:func:`derive` by Mitsuba's quadrature (:mod:`.roughplastic_tables`; the
visible-normal sampler is used there whatever ``sample_visible`` says, as in
Mitsuba). ``T`` is a ``("table", 64)`` field read as Mitsuba's
``lerp_gather``: ``x = mu (N - 1)``, ``i = min(floor(x), N - 2)``,
``T = lerp(t[i], t[i + 1], x - i)`` -- exactly the material table's
``table_lerp`` for ``x`` in [0, 1] -- with samples at ``mu = i / 63`` (the
first at ``1e-6``).

Sampling (Mitsuba's)::

    w   = mean(k_s) / (mean(rho_d) + mean(k_s))        (host, derive)
    P_s = (1 - T(wi.z)) w / ((1 - T(wi.z)) w + T(wi.z) (1 - w)),  P_d = 1 - P_s

``u1 < P_s``: ``wo = reflect(wi, m)``, ``m`` from the distribution (visible
normals if ``sample_visible``, else ``D(m) m.z``) with ``u2``; else a
cosine-weighted ``wo`` (``u2``). The density of either choice is the mixture::

    pdf = P_s D(H) G1(wi, H) / (4 wi.z) + P_d wo.z / pi    (sample_visible)
    pdf = P_s D(H) H.z / (4 wo.H)       + P_d wo.z / pi    (otherwise)

(``D_wi(H) / (4 wo.H)`` with ``wi.H = wo.H`` cancelled, as Mitsuba writes
it), and ``weight = eval / pdf`` at the sampled ``wo``; a sample with
``pdf = 0`` (below the surface) is invalid. The microfacet samplers and the
cosine warp are Mitsuba's mappings, so the same ``(u1, u2)`` give Mitsuba's
sample (to float32 rounding; ~5e-4 in the normal with ``sample_visible =
False`` at small alphas, see :class:`.microfacet.Distribution`).

Trace-time choices: :func:`params` looks at the scene's roughplastic specs
(``table.specs_of``): one distribution, one ``sample_visible``, one
``nonlinear`` -> Python constants, only that code traced; both present ->
per-lane ``Bool``/float fields and both branches traced and selected.

Mitsuba's ``pdf`` is not masked to the upper hemisphere (for ``wo.z < 0``
it returns its specular term, and for ``wi.z < 0`` too with
``sample_visible = False``); drpt's is 0 there, as both plugins' ``eval``.

Where drpt differs from Mitsuba
-------------------------------
Only on degenerate input: ``P_s`` when its denominator is 0 (``T = 0`` and
``w = 0``, or ``T = 1`` and ``w = 1``; Mitsuba: NaN) is ``w``;
``1 - rho_d R_int`` (nonlinear) is clamped to >= 1e-4 (reflectances above
``1 / R_int``); the sampling weight ``w`` of two zero means (Mitsuba: NaN)
is 0.5. ``eval``/``pdf`` differ from Mitsuba's at float32 rounding (the
tables: ~3e-6 absolute, float64 sums here, float32 there).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials.bsdf_kinds import PARAMS
from ..warp import INV_PI, square_to_cosine_hemisphere
from . import BSDFSample, plastic
from . import microfacet as mf
from .roughplastic_tables import ALPHA_MIN, RES, coating_tables

#: Name of the transmittance table field (``("table", RES)``).
TABLE = "roughplastic_transmittance"

#: Per-material values the material table uploads (see :mod:`drpt.render.bsdf`).
FIELDS = {
    "diffuse_reflectance": "rgb",
    "specular_reflectance": "rgb",
    "alpha": "float",
    "plastic_eta": "float",
    "plastic_specular_weight": "float",
    "plastic_nonlinear": "float",
    "roughplastic_internal_reflectance": "float",
    "roughplastic_beckmann": "float",
    "roughplastic_sample_visible": "float",
    TABLE: ("table", RES),
}
DELTA = False
#: The field the Whitted ambient term multiplies (the diffuse base).
COLOR = "diffuse_reflectance"


# ---------------------------------------------------------------- host side
def _distribution(value) -> bool:
    """True for Beckmann, False for GGX (Mitsuba's names, case-insensitive)."""
    name = str(value).strip().lower()
    if name not in ("beckmann", "ggx"):
        raise ValueError(f"roughplastic: distribution must be 'beckmann' or 'ggx', got {value!r}")
    return name == "beckmann"


def _alpha(value) -> float:
    try:
        a = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"roughplastic: alpha must be a number, got {value!r}") from None
    if not (math.isfinite(a) and a >= 0.0):
        raise ValueError(f"roughplastic: alpha must be finite and >= 0, got {value!r}")
    return max(a, ALPHA_MIN)


def settings(params: dict) -> tuple[bool, bool, bool, float]:
    """``(beckmann, sample_visible, nonlinear, alpha)`` of a spec's params."""
    p = {**PARAMS["roughplastic"], **params}
    for k in ("alpha_u", "alpha_v"):
        if p.get(k) is not None:
            raise ValueError("roughplastic: anisotropic roughness (alpha_u/alpha_v) is not supported "
                             "(Mitsuba's roughplastic refuses it too); give 'alpha'")
    return (_distribution(p["distribution"]), plastic.flag(p["sample_visible"], "sample_visible"),
            plastic.flag(p["nonlinear"], "nonlinear"), _alpha(p["alpha"]))


def derive(params: dict) -> dict:
    """The derived fields of one material (host side, numpy only): the
    coating's eta, sampling weight, transmittance table and internal
    reflectance, and the trace-time choices as 0/1 floats."""
    beckmann, visible, nonlinear, alpha = settings(params)
    eta, w = plastic.coating(params, "roughplastic")
    if eta == 1.0:
        raise ValueError("roughplastic: int_ior and ext_ior must differ (as in Mitsuba)")
    t, r_int = coating_tables(beckmann, alpha, eta)
    return {"alpha": alpha, "plastic_eta": eta, "plastic_specular_weight": w,
            "plastic_nonlinear": 1.0 if nonlinear else 0.0,
            "roughplastic_internal_reflectance": r_int,
            "roughplastic_beckmann": 1.0 if beckmann else 0.0,
            "roughplastic_sample_visible": 1.0 if visible else 0.0,
            TABLE: np.array(t, np.float64)}


# ---------------------------------------------------------------- device side
class RoughPlasticParams:
    """Per-lane parameters: ``diffuse`` (rho_d), ``specular`` (k_s),
    ``alpha``, ``eta``, ``spec_weight`` (w), ``nonlinear`` (0/1),
    ``r_int`` (R_int); and, as plain attributes (trace-time choices, not
    per-lane data): ``transmittance`` -- a callable ``mu -> T(mu)`` (the
    material table's lerp of the lanes' tables) -- ``beckmann`` and
    ``visible``: Python bools, or per-lane ``Bool`` when the scene mixes
    both."""

    DRJIT_STRUCT = {"diffuse": Array3f, "specular": Array3f, "alpha": Float, "eta": Float,
                    "spec_weight": Float, "nonlinear": Float, "r_int": Float}

    def __init__(self, diffuse=None, specular=None, alpha=None, eta=None, spec_weight=None,
                 nonlinear=None, r_int=None, transmittance=None, beckmann=True, visible=True):
        self.diffuse = diffuse if diffuse is not None else Array3f(0.5)
        self.specular = specular if specular is not None else Array3f(1.0)
        self.alpha = alpha if alpha is not None else Float(0.1)
        self.eta = eta if eta is not None else Float(1.49 / 1.000277)
        self.spec_weight = spec_weight if spec_weight is not None else Float(2.0 / 3.0)
        self.nonlinear = nonlinear if nonlinear is not None else Float(0.0)
        self.r_int = r_int if r_int is not None else Float(0.0)
        self.transmittance = transmittance
        self.beckmann = beckmann
        self.visible = visible


def _choice(table, field: str, values: set, si, active):
    """A Python bool when every roughplastic spec agrees, else a per-lane Bool."""
    if len(values) == 1:
        return next(iter(values))
    return table.value(field, si, active) > 0.5


def params(table, si, active) -> RoughPlasticParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    found = [settings(s.params) for s in table.specs_of("roughplastic")] or [(True, True, False, 0.1)]
    beck = _choice(table, "roughplastic_beckmann", {f[0] for f in found}, si, active)
    vis = _choice(table, "roughplastic_sample_visible", {f[1] for f in found}, si, active)
    return RoughPlasticParams(
        table.value("diffuse_reflectance", si, active), table.value("specular_reflectance", si, active),
        table.value("alpha", si, active), table.value("plastic_eta", si, active),
        table.value("plastic_specular_weight", si, active),
        plastic.nonlinear_field(table, "roughplastic", si, active),
        table.value("roughplastic_internal_reflectance", si, active),
        lambda mu: table.table_lerp(TABLE, si, mu, active), beck, vis)


def _distr(p: RoughPlasticParams, visible: bool) -> mf.Distribution:
    return mf.Distribution(p.beckmann, p.alpha, None, visible)


def specular_probability(t_i, w) -> Float:
    """``P_s`` from the transmittance at ``wi`` and the sampling weight."""
    t = dr.clip(t_i, 0.0, 1.0)
    a = (1.0 - t) * w
    b = t * (1.0 - w)
    s = a + b
    return dr.select(s > 0.0, a / dr.select(s > 0.0, s, 1.0), w)


def _half(wi, wo, ok):
    return dr.normalize(dr.select(ok, wi + wo, Array3f(0.0, 0.0, 1.0)))


def _eval(p: RoughPlasticParams, wi, wo, t_i, ok):
    cos_i = dr.select(ok, wi.z, 1.0)
    h = _half(wi, wo, ok)
    d = _distr(p, True)
    spec = plastic.fresnel(dr.dot(wi, h), p.eta) * d.D(h) * d.G(wi, wo, h) / (4.0 * cos_i)
    t_o = p.transmittance(dr.select(ok, wo.z, 1.0))
    diff = (INV_PI / dr.square(p.eta)) * wo.z * t_i * t_o
    v = p.specular * spec + plastic.diffuse_albedo(p.diffuse, p.r_int, p.nonlinear) * diff
    return dr.select(ok, v, 0.0)


def _pdf(p: RoughPlasticParams, wi, wo, t_i, ok):
    cos_i = dr.select(ok, wi.z, 1.0)
    h = _half(wi, wo, ok)
    d = _distr(p, True)
    dh = d.D(h)

    def visible():
        return dh * d.G1(wi, h) / (4.0 * cos_i)

    def all_normals():
        c = dr.dot(wo, h)
        return dh * h.z / (4.0 * dr.select(c > 0.0, c, 1.0))

    if isinstance(p.visible, bool):
        spec = visible() if p.visible else all_normals()
    else:
        spec = dr.select(p.visible, visible(), all_normals())
    p_s = specular_probability(t_i, p.spec_weight)
    v = p_s * spec + (1.0 - p_s) * INV_PI * wo.z
    return dr.select(ok, v, 0.0)


def _t_i(p: RoughPlasticParams, wi):
    return p.transmittance(dr.select(wi.z > 0.0, wi.z, 1.0))


def eval(p: RoughPlasticParams, wi: Array3f, wo: Array3f) -> Array3f:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    return _eval(p, wi, wo, _t_i(p, wi), ok)


def pdf(p: RoughPlasticParams, wi: Array3f, wo: Array3f) -> Float:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    return _pdf(p, wi, wo, _t_i(p, wi), ok)


def _sample_normal(p: RoughPlasticParams, wi, u2):
    """The specular lobe's microfacet normal (visible normals or ``D(m) m.z``)."""
    d = _distr(p, True)
    if isinstance(p.visible, bool):
        return d.sample_visible_normal(wi, u2) if p.visible else d.sample_all(u2)
    return dr.select(p.visible, d.sample_visible_normal(wi, u2), d.sample_all(u2))


def sample(p: RoughPlasticParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    front = wi.z > 0.0
    wi_s = dr.select(front, wi, Array3f(0.0, 0.0, 1.0))  # keep the warps finite
    t_i = _t_i(p, wi)
    spec = u1 < specular_probability(t_i, p.spec_weight)
    m = _sample_normal(p, wi_s, u2)
    wo_s = mf.reflect(wi_s, m)
    wo = dr.select(spec, wo_s, square_to_cosine_hemisphere(u2))
    ok = front & (wo.z > 0.0)
    pd = _pdf(p, wi, wo, t_i, ok)
    valid = ok & (pd > 0.0)
    f = _eval(p, wi, wo, t_i, ok)
    weight = dr.select(valid, f / dr.select(valid, pd, 1.0), 0.0)
    n = dr.width(wi)
    return BSDFSample(wo, weight, dr.select(valid, pd, 0.0), valid, dr.zeros(Bool, n), Float(1.0))
