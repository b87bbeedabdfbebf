"""Smooth plastic: Mitsuba 3's ``plastic`` plugin (``src/bsdfs/plastic.cpp``).

A diffuse base under a smooth dielectric coating of relative IOR
``eta = int_ior / ext_ior``. Light either reflects specularly off the
coating (a Dirac lobe, weight ``F``) or enters, scatters diffusely in the
base (possibly bouncing between base and coating: the ``1 / (1 - ...)``
term) and leaves through the coating. One-sided, as Mitsuba's plugin: zero
unless ``wi.z > 0`` and ``wo.z > 0`` (``twosided`` makes it two-sided).

Parameters (Mitsuba's names and defaults, :data:`drpt.materials.bsdf_kinds.PARAMS`)
-------------------------------------------------------------------------
``diffuse_reflectance`` ``rho_d`` (rgb or texture, 0.5),
``specular_reflectance`` ``k_s`` (rgb or texture, 1; a tint of the specular
lobe only, not physical), ``int_ior`` (polypropylene 1.49), ``ext_ior``
(air 1.000277): numbers or Mitsuba's names (:func:`resolve_ior`),
``nonlinear`` (False).

Formulas
--------
``F(c) = fresnel(c, eta)``: exact unpolarized dielectric Fresnel reflectance
(:func:`drpt.render.bsdf.dielectric.fresnel_dielectric`: Mitsuba's
``fresnel`` with ``cos_t^2`` written as ``eta_ti^2 c^2 + 1 - eta_ti^2``, the
same value to float32 rounding; 0 when ``eta == 1``). ``F_i = F(wi.z)``,
``F_o = F(wo.z)``.

Diffuse (the only part ``eval``/``pdf`` return; the specular one is a Dirac)::

    rho' = rho_d / (1 - Fdr_int)           (linear, default)
    rho' = rho_d / (1 - rho_d Fdr_int)     (nonlinear = true)
    eval(wi, wo) = rho' (1 - F_i) (1 - F_o) / eta^2  wo.z / pi

``Fdr_int`` is the internal diffuse Fresnel reflectance, computed host side
in :func:`derive` as Mitsuba's ``fresnel_diffuse_reflectance(1 / eta)``
(:func:`fresnel_diffuse_reflectance`: Egan & Hilgeman's 1973 fit for an
argument < 1, d'Eon & Irving's 2011 fit otherwise) -- **except for eta > 2**
(see below).

Specular: ``wo = (-wi.x, -wi.y, wi.z)`` with ``f cos / pdf = F_i k_s``.

Sampling (Mitsuba's, lobe chosen with ``u1``)::

    w   = mean(k_s) / (mean(rho_d) + mean(k_s))      (host side, derive)
    P_s = F_i w / (F_i w + (1 - F_i)(1 - w)),   P_d = 1 - P_s

``u1 < P_s``: the specular direction, ``delta = True``, weight
``F_i k_s / P_s``, ``pdf = 0`` (drpt's convention for Dirac samples;
Mitsuba's ``bs.pdf`` there is ``P_s``). Else a cosine-weighted direction
(``u2``, the concentric map, as Mitsuba's ``square_to_cosine_hemisphere``),
``pdf = P_d wo.z / pi`` -- exactly what :func:`pdf` returns -- and weight
``eval / pdf``. ``mean`` is Mitsuba's ``Texture::mean``: the channel mean of
an rgb value, the mean *luminance* (Rec. 709 weights 0.212671, 0.715160,
0.072169) of a bitmap's linear texels (:func:`texture_mean`).

Where drpt differs from Mitsuba (only outside its valid range)
--------------------------------------------------------------
* ``eta > 2``: Egan & Hilgeman's fit overestimates ``Fdr_int`` (Mitsuba's own
  comment: 9.5% error in 2..5); it reaches 1 at ``eta = 3.847`` and exceeds
  it beyond, where Mitsuba's plastic returns infinite or *negative* values;
  already at ``eta = 3`` it inflates the diffuse part by 25% (Mitsuba's
  albedo of a white plastic at normal incidence: 1.036 at eta 2.5, 1.19 at
  3, 9.9 at 3.8). drpt uses ``Fdr_int = 1 - (1 - Fdr_ext(eta)) / eta^2``
  there (the exact relation between internal and external diffuse
  reflectance, with Mitsuba's accurate d'Eon-Irving fit for ``Fdr_ext``), so
  a white plastic's albedo is 1 to the fits' accuracy (within 0.12% for
  every eta in [1, 4]; Mitsuba's is 1.0014 at the default eta). The switch
  at ``eta = 2`` changes ``1 / (1 - Fdr_int)`` by 0.06%. For ``eta <= 2``
  (and every ``eta < 1``) drpt uses Mitsuba's value exactly.
* ``1 - Fdr_int rho_d`` (nonlinear) is clamped to >= 1e-4, which only matters
  for reflectances above ``1 / Fdr_int`` (> 1.04 at any IOR), where Mitsuba
  returns negative values.
* ``w`` when both means are 0 (Mitsuba: NaN) is 0.5, and ``P_s`` when its
  denominator is 0 (``eta = 1`` and a black diffuse: the BSDF is 0) is
  ``w``.

At ``eta == 1`` there is no specular reflection (``F = 0``) and ``Fdr_int``
is Mitsuba's 2.1e-4 (the fit's value), so the plastic is ``rho_d / pi`` to
2e-4. Any ``int_ior``, ``ext_ior`` > 0 is accepted (Mitsuba refuses only
negative ones; 0 is refused here as it would divide by zero).
"""

from __future__ import annotations

from typing import Any

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Float

from ...materials.bsdf_kinds import PARAMS
from ...materials.iors import lookup_ior
from ..texture import load_rgb
from ..warp import INV_PI, square_to_cosine_hemisphere
from . import BSDFSample
from .dielectric import fresnel_dielectric

#: Per-material values the material table uploads (see :mod:`drpt.render.bsdf`).
#: The ``plastic_*`` ones come from :func:`derive` (shared with ``roughplastic``).
FIELDS = {
    "diffuse_reflectance": "rgb",
    "specular_reflectance": "rgb",
    "plastic_eta": "float",
    "plastic_fdr_int": "float",
    "plastic_specular_weight": "float",
    "plastic_nonlinear": "float",
}
DELTA = False
#: The field the Whitted ambient term multiplies (the diffuse base).
COLOR = "diffuse_reflectance"

#: Above this eta drpt replaces Mitsuba's Fdr_int fit by the exact relation (module docs).
FDR_FIT_MAX_ETA = 2.0
#: Rec. 709 luminance weights Mitsuba's ``luminance`` uses (a bitmap's mean).
LUMINANCE = (0.212671, 0.715160, 0.072169)


# ---------------------------------------------------------------- host side
def resolve_ior(value: Any, name: str = "ior") -> float:
    """An IOR given as a number or one of Mitsuba's names (:func:`drpt.materials.iors.lookup_ior`)."""
    return lookup_ior(value, name)


def flag(value: Any, name: str) -> bool:
    """A boolean parameter (bool, 0/1, or the strings 'true'/'false')."""
    if isinstance(value, str):
        low = value.strip().lower()
        if low in ("true", "1", "yes"):
            return True
        if low in ("false", "0", "no"):
            return False
        raise ValueError(f"{name}: expected true or false, got {value!r}")
    return bool(value)


def fresnel_diffuse_reflectance(eta: float) -> float:
    """Mitsuba's ``fresnel_diffuse_reflectance(eta)`` (``fresnel.h``): the
    hemispherical average of the Fresnel reflectance seen from the side where
    the relative IOR (far / near) is ``eta``. Egan & Hilgeman (1973) for
    ``eta < 1``, d'Eon & Irving (2011) otherwise."""
    eta = float(eta)
    inv = 1.0 / eta
    if eta < 1.0:
        return 0.0636 * inv + eta * (eta * -1.4399 + 0.7099) + 0.6681
    c = (0.919317, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881)
    r = 0.0
    for k in reversed(c):
        r = r * inv + k
    return r


def internal_fdr(eta: float) -> float:
    """``Fdr_int`` of a coating of relative IOR ``eta`` (see the module docs)."""
    if eta <= FDR_FIT_MAX_ETA:
        return fresnel_diffuse_reflectance(1.0 / eta)
    return 1.0 - (1.0 - fresnel_diffuse_reflectance(eta)) / (eta * eta)


def texture_mean(value: Any) -> float:
    """Mitsuba's ``Texture::mean`` of a parameter value: a float itself, the
    mean of an rgb triple's channels, a bitmap's mean linear luminance."""
    if hasattr(value, "color0"):  # a checkerboard: Mitsuba's .5 (mean(color0) + mean(color1))
        return 0.5 * (float(np.mean(value.color0)) + float(np.mean(value.color1)))
    path = getattr(value, "path", None)
    if path is not None:
        img = load_rgb(path).astype(np.float64)
        return float(np.mean(img @ np.asarray(LUMINANCE)))
    if isinstance(value, (int, float)):
        return float(value)
    arr = np.asarray(value, dtype=np.float64).ravel()
    if arr.size not in (1, 3) or not np.all(np.isfinite(arr)):
        raise ValueError(f"expected a float, an rgb triple or a texture, got {value!r}")
    return float(arr.mean())


def coating(params: dict, kind: str = "plastic") -> tuple[float, float]:
    """``(eta, w)``: the relative IOR and the specular sampling weight of a
    plastic spec's (defaults-filled) params; shared with ``roughplastic``."""
    p = {**PARAMS[kind], **params}
    eta = resolve_ior(p["int_ior"], "int_ior") / resolve_ior(p["ext_ior"], "ext_ior")
    d_mean = texture_mean(p["diffuse_reflectance"])
    s_mean = texture_mean(p["specular_reflectance"])
    total = d_mean + s_mean
    w = s_mean / total if total > 0.0 else 0.5
    return eta, w


def derive(params: dict) -> dict:
    """The ``plastic_*`` fields of one material (host side, numpy only)."""
    eta, w = coating(params)
    nl = flag({**PARAMS["plastic"], **params}["nonlinear"], "nonlinear")
    return {"plastic_eta": eta, "plastic_fdr_int": internal_fdr(eta),
            "plastic_specular_weight": w, "plastic_nonlinear": 1.0 if nl else 0.0}


# ---------------------------------------------------------------- device side
class PlasticParams:
    """Per-lane parameters: ``diffuse`` (rho_d), ``specular`` (k_s), ``eta``,
    ``fdr_int``, ``spec_weight`` (w) and ``nonlinear`` (1.0 or 0.0)."""

    DRJIT_STRUCT = {"diffuse": Array3f, "specular": Array3f, "eta": Float, "fdr_int": Float,
                    "spec_weight": Float, "nonlinear": Float}

    def __init__(self, diffuse=None, specular=None, eta=None, fdr_int=None, spec_weight=None,
                 nonlinear=None):
        self.diffuse = diffuse if diffuse is not None else Array3f(0.5)
        self.specular = specular if specular is not None else Array3f(1.0)
        self.eta = eta if eta is not None else Float(1.49 / 1.000277)
        self.fdr_int = fdr_int if fdr_int is not None else Float(internal_fdr(1.49 / 1.000277))
        self.spec_weight = spec_weight if spec_weight is not None else Float(2.0 / 3.0)
        self.nonlinear = nonlinear if nonlinear is not None else Float(0.0)


def nonlinear_field(table, kind: str, si, active):
    """The ``plastic_nonlinear`` of the lanes of ``kind`` (``plastic`` or
    ``roughplastic``): a literal 0/1 when every spec of that kind agrees (no
    gather traced), else the per-lane field."""
    flags = {flag({**PARAMS[kind], **s.params}["nonlinear"], "nonlinear") for s in table.specs_of(kind)}
    if flags == {False}:
        return Float(0.0)
    if flags == {True}:
        return Float(1.0)
    return table.value("plastic_nonlinear", si, active)


def params(table, si, active) -> PlasticParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return PlasticParams(table.value("diffuse_reflectance", si, active),
                         table.value("specular_reflectance", si, active),
                         table.value("plastic_eta", si, active),
                         table.value("plastic_fdr_int", si, active),
                         table.value("plastic_specular_weight", si, active),
                         nonlinear_field(table, "plastic", si, active))


def fresnel(cos_theta, eta) -> Float:
    """``F(cos_theta)`` of the coating (0 for ``eta == 1``)."""
    return fresnel_dielectric(cos_theta, eta)[0]


def diffuse_albedo(rho: Array3f, fdr_int, nonlinear) -> Array3f:
    """``rho'``: the base's reflectance with the internal bounces summed."""
    x = dr.select(Float(nonlinear) > 0.5, rho * fdr_int, Array3f(Float(fdr_int)))
    return rho / dr.maximum(1.0 - x, 1e-4)


def specular_probability(f_i, w) -> Float:
    """``P_s = F_i w / (F_i w + (1 - F_i)(1 - w))`` (``w`` where both are 0)."""
    a = f_i * w
    b = (1.0 - f_i) * (1.0 - w)
    s = a + b
    return dr.select(s > 0.0, a / dr.select(s > 0.0, s, 1.0), w)


def _diffuse_value(p: PlasticParams, f_i, wo) -> Array3f:
    """``rho' (1 - F_i)(1 - F_o) / eta^2 wo.z / pi`` (no side test)."""
    f_o = fresnel(wo.z, p.eta)
    s = (1.0 - f_i) * (1.0 - f_o) * INV_PI * wo.z / dr.square(p.eta)
    return diffuse_albedo(p.diffuse, p.fdr_int, p.nonlinear) * s


def eval(p: PlasticParams, wi: Array3f, wo: Array3f) -> Array3f:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    f_i = fresnel(wi.z, p.eta)
    return dr.select(ok, _diffuse_value(p, f_i, wo), 0.0)


def pdf(p: PlasticParams, wi: Array3f, wo: Array3f) -> Float:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    p_d = 1.0 - specular_probability(fresnel(wi.z, p.eta), p.spec_weight)
    return dr.select(ok, p_d * INV_PI * wo.z, 0.0)


def sample(p: PlasticParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    front = wi.z > 0.0
    f_i = fresnel(wi.z, p.eta)
    p_s = specular_probability(f_i, p.spec_weight)
    spec = front & (u1 < p_s)

    wo_d = square_to_cosine_hemisphere(u2)
    p_d = 1.0 - p_s
    pdf_d = p_d * INV_PI * wo_d.z
    ok_d = front & ~spec & (pdf_d > 0.0)
    w_d = _diffuse_value(p, f_i, wo_d) / dr.select(ok_d, pdf_d, 1.0)
    w_s = p.specular * (f_i / dr.select(spec, p_s, 1.0))

    wo = dr.select(spec, Array3f(-wi.x, -wi.y, wi.z), wo_d)
    weight = dr.select(spec, w_s, dr.select(ok_d, w_d, 0.0))
    return BSDFSample(wo, weight, dr.select(ok_d, pdf_d, 0.0), spec | ok_d, spec, Float(1.0))
