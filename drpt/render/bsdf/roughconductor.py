"""Rough conductor: Mitsuba 3's ``roughconductor`` plugin
(``src/bsdfs/roughconductor.cpp``), eval, pdf and sample formula for formula.

A microfacet reflection lobe (Walter et al. 2007) with a Beckmann or GGX
distribution of widths ``alpha_u``, ``alpha_v``
(:class:`drpt.render.bsdf.microfacet.Distribution`, Mitsuba's
``MicrofacetDistribution``: its ``D``, separable Smith ``G``, its clamp
``alpha >= 1e-4``), the conductor Fresnel term
:func:`drpt.render.bsdf.conductor.fresnel_conductor` (complex IOR
``eta + i k`` per RGB channel) and a ``specular_reflectance`` tint ``r``.

Parameters (Mitsuba's names and defaults, :data:`drpt.materials.bsdf_kinds.PARAMS`):
``distribution`` (``"beckmann"`` | ``"ggx"``, default beckmann), ``alpha``
(0.1) or both ``alpha_u`` and ``alpha_v`` (anisotropic: ``alpha_u`` along the
shading frame's ``x``, ``alpha_v`` along ``y``), ``sample_visible`` (True),
``material`` / ``eta`` / ``k`` (see :mod:`drpt.materials.conductors`),
``specular_reflectance``. ``alpha``, ``alpha_u``, ``alpha_v`` and
``specular_reflectance`` may be textures (a roughness texture is read as its
luminance). :func:`derive` (host side) resolves the IOR and the alphas and
encodes the two string/bool choices as the float fields ``beckmann`` and
``visible``.

Formulas (local frame, ``wi`` toward the viewer, ``wo`` toward the light;
one-sided: everything is 0 unless ``wi.z > 0`` and ``wo.z > 0``)::

    h      = normalize(wi + wo)
    eval   = F_c(dot(wi, h)) r D(h) G1(wi, h) G1(wo, h) / (4 wi.z)     (= f wo.z)
    pdf    = D(h) G1(wi, h) / (4 wi.z)                   (sample_visible)
           = D(h) h.z / (4 dot(wo, h))                    (otherwise)

``eval`` is 0 where ``D(h) = 0`` and ``pdf`` is 0 unless ``dot(wi, h) > 0``
and ``dot(wo, h) > 0`` (Mitsuba's conditions). ``sample``: a normal ``m``
from the distribution's sampler (visible normals of ``wi``, or ``D(m)
m.z``), ``wo = reflect(wi, m)``, invalid if the density is 0 or ``wo.z <=
0``; its ``pdf`` is the normal's density over ``4 dot(wo, m)`` and::

    weight = F_c(dot(wi, m)) r G1(wo, m)                              (sample_visible)
           = F_c(dot(wi, m)) r G(wi, wo, m) dot(wi, m) / (wi.z m.z)   (otherwise)

which is ``eval / pdf`` at ``wo`` (``h = m`` up to rounding). ``F_c``,
``r`` <= 1 and ``G1`` <= 1 bound the visible-sampling weight by 1.

Differences from Mitsuba: none in the formulas. The samplers' numerics
differ slightly where Mitsuba's lose precision (see
:class:`~drpt.render.bsdf.microfacet.Distribution`), the returned ``pdf`` is
the normal's density evaluated at the sampled normal (Mitsuba's non-visible
sampler uses its closed form in ``u``), and the Fresnel term takes its limit
where Mitsuba's divides 0 by 0.

Trace-time choices (from ``table.specs_of("roughconductor")``): only the
distributions present are traced (a per-lane select when a scene has both),
the same for ``sample_visible``; a scene without ``alpha_u``/``alpha_v``
traces the isotropic code (one alpha).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials import conductors
from . import BSDFSample
from .conductor import reflectance, unit_fresnel
from .microfacet import Distribution, reflect

FIELDS = {"specular_reflectance": "rgb", "cond_eta": "rgb", "cond_k": "rgb",
          "alpha_u": "float", "alpha_v": "float", "beckmann": "float", "visible": "float"}
DELTA = False


def _distribution_name(params: dict) -> str:
    d = str(params.get("distribution", "beckmann") or "beckmann").lower()
    if d not in ("beckmann", "ggx"):
        raise ValueError(f"distribution must be 'beckmann' or 'ggx', not {params.get('distribution')!r}")
    return d


def derive(params: dict) -> dict:
    """Host side: IOR, alphas (``alpha`` for both unless ``alpha_u``/``alpha_v``:
    both are then required, as Mitsuba), and the choices as floats."""
    eta, k = conductors.resolve(params)
    au, av = params.get("alpha_u"), params.get("alpha_v")
    if (au is None) != (av is None):
        raise ValueError("roughconductor: both 'alpha_u' and 'alpha_v' must be given")
    if au is None:
        au = av = params.get("alpha", 0.1)
    for name, v in (("alpha_u", au), ("alpha_v", av)):
        if isinstance(v, (int, float)) and not (v == v and 0.0 <= v < float("inf")):
            raise ValueError(f"roughconductor: {name} must be finite and >= 0, not {v}")
    return {"cond_eta": eta, "cond_k": k, "alpha_u": au, "alpha_v": av,
            "beckmann": 1.0 if _distribution_name(params) == "beckmann" else 0.0,
            "visible": 1.0 if params.get("sample_visible", True) else 0.0}


class RoughConductorParams:
    """Per-lane ``r``, ``eta``, ``k`` (Array3f), ``alpha_u``, ``alpha_v``
    (Float; ``alpha_v`` None: isotropic), and the choices ``beckmann``,
    ``visible``: Python bools (traced once) or per-lane Bools."""

    DRJIT_STRUCT = {"r": Array3f, "eta": Array3f, "k": Array3f, "alpha_u": Float}

    def __init__(self, r=None, eta=None, k=None, alpha_u=None, alpha_v=None, beckmann=True, visible=True,
                 unit: bool = False):
        self.r = r if r is not None else Array3f(1.0)
        self.eta = eta if eta is not None else Array3f(0.0)
        self.k = k if k is not None else Array3f(1.0)
        self.alpha_u = alpha_u if alpha_u is not None else Float(0.1)
        self.alpha_v = alpha_v
        self.beckmann = beckmann
        self.visible = visible
        self.unit = unit  # F = 1 for every roughconductor (conductor.unit_fresnel)

    def distribution(self, visible: bool) -> Distribution:
        return Distribution(self.beckmann, self.alpha_u, self.alpha_v, sample_visible=visible)


def _choice(specs, key, default, truth, field, table, si, active):
    """A trace-time choice: the Python bool when all specs agree, else the per-lane Bool of ``field``."""
    vals = {truth(s.params.get(key, default)) for s in specs}
    if len(vals) == 1:
        return vals.pop()
    return table.value(field, si, active) > 0.5


def params(table, si, active) -> RoughConductorParams:
    """The lanes' parameters, gathered from the material table."""
    specs = table.specs_of("roughconductor")
    beck = _choice(specs, "distribution", "beckmann", lambda d: str(d).lower() == "beckmann",
                   "beckmann", table, si, active)
    vis = _choice(specs, "sample_visible", True, bool, "visible", table, si, active)
    iso = all(s.params.get("alpha_u") is None for s in specs)
    au = table.value("alpha_u", si, active)
    av = None if iso else table.value("alpha_v", si, active)
    return RoughConductorParams(table.value("specular_reflectance", si, active),
                                table.value("cond_eta", si, active), table.value("cond_k", si, active),
                                au, av, beck, vis, unit_fresnel(specs))


def _fresnel(p, cos):
    return reflectance(p, dr.clip(cos, 0.0, 1.0))


def eval(p: RoughConductorParams, wi: Array3f, wo: Array3f) -> Array3f:
    active = (wi.z > 0.0) & (wo.z > 0.0)
    h = dr.normalize(wi + wo)
    d = p.distribution(True)
    D = d.D(h)
    active &= D != 0.0
    v = D * d.G(wi, wo, h) / (4.0 * dr.select(active, wi.z, 1.0))
    return dr.select(active, _fresnel(p, dr.dot(wi, h)) * v, 0.0)


def _pdf_with(d: Distribution, wi, wo, h, active):
    if d.sample_visible:
        v = d.D(h) * d.G1(wi, h) / (4.0 * dr.select(active, wi.z, 1.0))
    else:
        v = d.D(h) * h.z / (4.0 * dr.select(active, dr.dot(wo, h), 1.0))
    return dr.select(active, v, 0.0)


def _by_visible(p, f):
    """``f(distribution)`` for the lanes' ``sample_visible`` choice."""
    if isinstance(p.visible, bool):
        return f(p.distribution(p.visible))
    return dr.select(p.visible, f(p.distribution(True)), f(p.distribution(False)))


def pdf(p: RoughConductorParams, wi: Array3f, wo: Array3f) -> Float:
    h = dr.normalize(wi + wo)
    active = (wi.z > 0.0) & (wo.z > 0.0) & (dr.dot(wi, h) > 0.0) & (dr.dot(wo, h) > 0.0)
    return _by_visible(p, lambda d: _pdf_with(d, wi, wo, h, active))


def _sample_with(d: Distribution, p, wi, u2):
    m, pm = d.sample(wi, u2)
    wo = reflect(wi, m)
    cos_om = dr.dot(wo, m)
    valid = (wi.z > 0.0) & (pm > 0.0) & (wo.z > 0.0) & (cos_om > 0.0)
    if d.sample_visible:
        w = d.G1(wo, m)
    else:
        w = d.G(wi, wo, m) * dr.dot(wi, m) / (dr.select(valid, wi.z * m.z, 1.0))
    pdf_ = pm / (4.0 * dr.select(valid, cos_om, 1.0))
    weight = _fresnel(p, dr.dot(wi, m)) * w
    return wo, dr.select(valid, weight, 0.0), dr.select(valid, pdf_, 0.0), valid


def sample(p: RoughConductorParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    n = dr.width(wi)
    if isinstance(p.visible, bool):
        wo, weight, pdf_, valid = _sample_with(p.distribution(p.visible), p, wi, u2)
    else:
        a = _sample_with(p.distribution(True), p, wi, u2)
        b = _sample_with(p.distribution(False), p, wi, u2)
        wo, weight, pdf_, valid = (dr.select(p.visible, x, y) for x, y in zip(a, b))
    return BSDFSample(wo, weight, pdf_, Bool(valid), dr.full(Bool, False, n), dr.full(Float, 1.0, n))
