"""Rough dielectric interface (frosted glass): Mitsuba 3's
``roughdielectric`` plugin (Walter et al. 2007, "Microfacet Models for
Refraction through Rough Surfaces"), radiance transport.

Parameters (Mitsuba's names and defaults, :data:`drpt.materials.bsdf_kinds.PARAMS`)
-----------------------------------------------------------------------
``int_ior`` (``"bk7"``), ``ext_ior`` (``"air"``): numbers or names of
:mod:`drpt.materials.iors`; only ``eta = int_ior / ext_ior`` matters (float32, as
Mitsuba). ``specular_reflectance``, ``specular_transmittance``: RGB tints (or
textures) of the reflected and the transmitted part. ``distribution``:
``"beckmann"`` (default) or ``"ggx"``. ``alpha`` (default 0.1), or both
``alpha_u`` (along the shading frame's ``x``) and ``alpha_v`` (along ``y``):
the microfacet widths, clamped below to 1e-4 (Mitsuba's clamp, no upper
clamp). ``sample_visible`` (default True): sample visible normals.
:func:`derive` resolves them into the uploaded fields ``rel_ior``,
``rd_alpha_u``, ``rd_alpha_v``, ``rd_beckmann`` and ``rd_visible`` (0/1).
Unlike Mitsuba (which refuses ``int_ior == ext_ior``), ``eta == 1`` is
accepted: see "index matched" below.

Frame and sides
---------------
The lobe sees the *unflipped* shading frame (``+z`` = shading normal = the
exterior side); ``wi.z > 0``: the viewer is outside, ``wi.z < 0``: inside.
``wi.z == 0`` gives 0 (eval, pdf) and an invalid sample, as Mitsuba. On the
viewer's side ``eta_i`` (``eta`` outside, ``1/eta`` inside) is the relative
IOR of the far side over the near one.

Math (``D``, ``G1``, ``G = G1(wi) G1(wo)`` and the microfacet sampling are
:class:`drpt.render.bsdf.microfacet.Distribution`, Mitsuba's
``MicrofacetDistribution``; ``F`` is
:func:`drpt.render.bsdf.dielectric.fresnel_dielectric`)
------------------------------------------------------------------------
Reflection (``wi.z wo.z > 0``): ``m = normalize(wi + wo)``; transmission:
the generalized half vector ``m = normalize(wi + eta_i wo)``; either is
turned to ``m.z > 0``. Both are 0 unless the microfacet and the macro
surface agree on each direction's side (``dot(wi, m) wi.z > 0`` and
``dot(wo, m) wo.z > 0``; ``G1`` includes this test). With ``F =
F(dot(wi, m), eta)``::

    eval_R = r F D G / (4 |wi.z|)
    eval_T = t (1 - F) D G |dot(wi, m) dot(wo, m)| / (|wi.z| (dot(wi, m) + eta_i dot(wo, m))^2)

(``f |cos wo|``; ``r``, ``t`` the tints). ``eval_T`` is Walter's ``f_t``
times ``1/eta_i^2``: the radiance scaling Mitsuba applies in
``TransportMode::Radiance`` (its ``scale * eta^2 = inv_eta^2 eta^2`` is 1,
computed here exactly). The density of ``sample``::

    pdf = p_m(m) * (F or 1 - F) * |dm/dwo|,
    dm/dwo = 1 / (4 dot(wo, m))                                  (reflection)
           = eta_i^2 dot(wo, m) / (dot(wi, m) + eta_i dot(wo, m))^2  (transmission)

with ``p_m`` the microfacet sampling density for ``wi' = sign(wi.z) wi``:
``sample_visible``: the visible normals ``D_wi'(m) = G1(wi', m) |dot(wi',
m)| D(m) / wi'.z``; else ``D_s(m) m.z`` where ``D_s`` has both widths scaled
by Walter's ``1.2 - 0.2 sqrt(|wi.z|)`` (Mitsuba's trick to tame the weights).

Sampling (Mitsuba's algorithm, with the same ``u1``, ``u2`` it gives
Mitsuba's direction to float rounding when ``sample_visible``): draw ``m``
from ``p_m``; ``(F, cos_t, eta_it, eta_ti) = fresnel(dot(wi, m), eta)``;
``u1 <= F`` reflects (``wo = 2 dot(wi, m) m - wi``), else refracts (``wo =
m (dot(wi, m) eta_ti + cos_t) - eta_ti wi``; total internal reflection has
``F = 1``). Weight ``= eval / pdf``: with visible normals ``(r or t
eta_ti^2) G1(wo, m)``, exactly Mitsuba's; without, ``(r or t eta_ti^2) G
dot(wi, m) D(m) / (wi.z m.z D_s(m))``. Mitsuba 3's own weight omits the
``D(m) / D_s(m)`` factor there, so its ``sample_visible = False`` weights
are not its ``eval / pdf`` (measured at 60 deg, alpha 0.3: ratios 0.89 to
1.12 for GGX, 0.89 to 2.8 for Beckmann; pinned by a test): drpt keeps the
unbiased ``eval / pdf``.
``BSDFSample.eta`` is ``eta_it`` on transmission, 1 on reflection (Mitsuba's
``bs.eta``). A sample whose ``wo`` lands on the wrong side of the
microfacet or the surface (``G1 = 0``) is invalid with weight 0 (Mitsuba
returns weight 0); ``pdf`` then is 0 too.

Index matched (``eta == 1``, refused by Mitsuba): ``F = 0`` and the
transmission lobe collapses onto ``wo = -wi`` (its ``dm/dwo`` is infinite):
the interface is invisible, as Mitsuba's smooth ``dielectric`` at ``eta =
1``. drpt makes it exactly that: eval and pdf 0, ``sample`` returns ``wo =
-wi``, weight ``t``, ``pdf`` 0 and ``delta`` True (a per-lane delta, as
``plastic``'s). This is not the model's limit: for ``eta -> 1`` the
microfacet lobe keeps Smith's masking loss (energy 0.9926 at alpha 0.3,
30 deg, for eta 1 + 2^-23 up to 1.001; it works there, pdfs up to ~1e15
but finite); at exactly 1 drpt is lossless, as the interface it exports
to Mitsuba (:mod:`drpt.export.mitsuba_dielectrics`). Any non-finite
intermediate (tangent directions, a degenerate half vector) gives 0 or an
invalid sample, never NaN or Inf.
"""

from __future__ import annotations

import math

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials.bsdf_kinds import defaults
from ...materials.iors import relative_ior
from . import BSDFSample
from .dielectric import fresnel_dielectric, tint, transmission_importance
from .microfacet import Distribution

KIND = "roughdielectric"

#: Per-material values the material table uploads (see :mod:`drpt.render.bsdf`): the tints from
#: the spec's parameters, the rest from :func:`derive` (``rd_beckmann``, ``rd_visible``: 0 or 1).
FIELDS = {"rel_ior": "float", "specular_reflectance": "rgb", "specular_transmittance": "rgb",
          "rd_alpha_u": "float", "rd_alpha_v": "float", "rd_beckmann": "float", "rd_visible": "float"}
DELTA = False


def _alpha(v, name: str) -> float:
    if isinstance(v, bool):
        raise ValueError(f"roughdielectric: {name} must be a number, got {v!r}")
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"roughdielectric: {name} must be a number, got {v!r}") from None
    if not (math.isfinite(x) and x >= 0.0):
        raise ValueError(f"roughdielectric: {name} must be finite and >= 0, got {v!r}")
    return x


def derive(params: dict) -> dict:
    """The uploaded values of one ``roughdielectric`` spec (its params with defaults filled in).

    ``distribution`` must be ``beckmann`` or ``ggx`` (any case); ``alpha_u``
    and ``alpha_v`` come together (then ``alpha`` is ignored) or not at all;
    widths are finite and ``>= 0``. ``ValueError`` otherwise, and for a bad IOR.
    """
    dist = params.get("distribution", "beckmann")
    if not isinstance(dist, str) or dist.lower() not in ("beckmann", "ggx"):
        raise ValueError(f"roughdielectric: distribution must be 'beckmann' or 'ggx', got {dist!r}")
    au, av = params.get("alpha_u"), params.get("alpha_v")
    if (au is None) != (av is None):
        raise ValueError("roughdielectric: alpha_u and alpha_v must be given together")
    if au is None:
        au = av = _alpha(params.get("alpha", 0.1), "alpha")
    else:
        au, av = _alpha(au, "alpha_u"), _alpha(av, "alpha_v")
    return {"rel_ior": relative_ior(params["int_ior"], params["ext_ior"]),
            "rd_alpha_u": au, "rd_alpha_v": av,
            "rd_beckmann": 1.0 if dist.lower() == "beckmann" else 0.0,
            "rd_visible": 1.0 if bool(params.get("sample_visible", True)) else 0.0}


class RoughDielectricParams:
    """Per-lane ``eta`` (interior over exterior IOR), tints ``r``, ``t``,
    widths ``alpha_u``, ``alpha_v``; and the trace-time choices: ``beckmann``
    and ``visible`` (Python bools when every lane agrees, else per-lane
    ``Bool``), ``isotropic`` (a Python bool: ``alpha_v`` is ``alpha_u``)."""

    DRJIT_STRUCT = {"eta": Float, "r": Array3f, "t": Array3f, "alpha_u": Float, "alpha_v": Float}

    def __init__(self, eta=None, r=None, t=None, alpha_u=None, alpha_v=None,
                 beckmann=True, visible=True, isotropic=None):
        self.eta = eta if eta is not None else Float(1.5046)
        self.r = r if r is not None else Array3f(1.0)
        self.t = t if t is not None else Array3f(1.0)
        self.alpha_u = alpha_u if alpha_u is not None else Float(0.1)
        if isotropic is None:
            isotropic = alpha_v is None
        self.alpha_v = self.alpha_u if (isotropic or alpha_v is None) else alpha_v
        self.isotropic = bool(isotropic)
        self.beckmann = beckmann
        self.visible = visible


def _choice(values: set, table, field: str, si, active):
    """A Python bool when all specs agree, else the per-lane ``Bool`` of ``field``."""
    if len(values) == 1:
        return next(iter(values))
    return table.value(field, si, active) > 0.5


def params(table, si, active) -> RoughDielectricParams:
    """The parameters of the lanes' materials; traces only the distributions,
    sampling strategies and anisotropy the scene's ``roughdielectric`` specs use."""
    specs = [derive({**defaults(KIND), **s.params}) for s in table.specs_of(KIND)]
    beck = {d["rd_beckmann"] == 1.0 for d in specs} or {True}
    vis = {d["rd_visible"] == 1.0 for d in specs} or {True}
    iso = all(d["rd_alpha_u"] == d["rd_alpha_v"] for d in specs)
    au = table.value("rd_alpha_u", si, active)
    return RoughDielectricParams(
        table.value("rel_ior", si, active),
        tint(table, KIND, "specular_reflectance", si, active),
        tint(table, KIND, "specular_transmittance", si, active),
        au, au if iso else table.value("rd_alpha_v", si, active),
        beckmann=_choice(beck, table, "rd_beckmann", si, active),
        visible=_choice(vis, table, "rd_visible", si, active), isotropic=iso)


# ---------------------------------------------------------------------------
def _distr(p: RoughDielectricParams, scale=None) -> Distribution:
    au, av = p.alpha_u, p.alpha_v
    if scale is not None:
        au = au * scale
        av = au if p.isotropic else av * scale
    return Distribution(p.beckmann, au, None if p.isotropic else av)


def _walter_scale(cos_i: Float) -> Float:
    return 1.2 - 0.2 * dr.sqrt(dr.abs(cos_i))


def _pdf_m(p: RoughDielectricParams, d: Distribution, wi_up: Array3f, m: Array3f) -> Float:
    """The density with which :func:`_sample_m` draws ``m`` for ``wi' = wi_up``."""
    def visible():
        return d.pdf_visible(wi_up, m)

    def all_normals():
        return _distr(p, _walter_scale(wi_up.z)).pdf_all(m)

    if isinstance(p.visible, bool):
        return visible() if p.visible else all_normals()
    return dr.select(p.visible, visible(), all_normals())


def _sample_m(p: RoughDielectricParams, d: Distribution, wi_up: Array3f, u2: Array2f) -> Array3f:
    def visible():
        return d.sample_visible_normal(wi_up, u2)

    def all_normals():
        return _distr(p, _walter_scale(wi_up.z)).sample_all(u2)

    if isinstance(p.visible, bool):
        return visible() if p.visible else all_normals()
    return dr.select(p.visible, visible(), all_normals())


def _finite3(v: Array3f) -> Bool:
    return dr.isfinite(v.x) & dr.isfinite(v.y) & dr.isfinite(v.z)


class _Half:
    """The half vector of ``(wi, wo)`` and what eval and pdf share."""

    def __init__(self, p: RoughDielectricParams, wi: Array3f, wo: Array3f):
        ci, co = wi.z, wo.z
        self.reflect = ci * co > 0.0
        outside = ci > 0.0
        self.eta = dr.select(outside, p.eta, dr.rcp(p.eta))  # eta_i, the viewer's side
        h = wi + wo * dr.select(self.reflect, 1.0, self.eta)
        m = dr.normalize(h)
        self.m = dr.select(m.z < 0.0, -m, m)
        self.dot_i = dr.dot(wi, self.m)
        self.dot_o = dr.dot(wo, self.m)
        self.ok = ((ci != 0.0) & (self.dot_i * ci > 0.0) & (self.dot_o * co > 0.0)
                   & (p.eta != 1.0) & _finite3(self.m))
        self.F = fresnel_dielectric(self.dot_i, p.eta)[0]
        self.denom = dr.square(self.dot_i + self.eta * self.dot_o)


def eval(p: RoughDielectricParams, wi: Array3f, wo: Array3f) -> Array3f:
    h = _Half(p, wi, wo)
    d = _distr(p)
    dg = d.D(h.m) * d.G(wi, wo, h.m)
    abs_ci = dr.abs(wi.z)
    val_r = h.F * dg / (4.0 * abs_ci)
    val_t = dr.abs((1.0 - h.F) * dg * h.dot_i * h.dot_o / (abs_ci * h.denom))
    val = dr.select(h.reflect, val_r, val_t)
    ok = h.ok & dr.isfinite(val) & (val > 0.0)
    return dr.select(ok, dr.select(h.reflect, p.r, p.t) * val, 0.0)


def importance_scale(p: RoughDielectricParams, wi: Array3f, wo: Array3f) -> Float:
    """The factor from :func:`eval`'s radiance-mode value to importance mode's (a light
    subpath's vertex: Mitsuba's ``TransportMode::Importance``): ``eta_i^2`` on transmission
    (``eta_i`` the IOR ratio seen from ``wi``'s side: the radiance scaling eval leaves in
    is undone), 1 on reflection: :func:`~drpt.render.bsdf.dielectric.transmission_importance`."""
    return transmission_importance(p.eta, wi, wo)


def pdf(p: RoughDielectricParams, wi: Array3f, wo: Array3f) -> Float:
    h = _Half(p, wi, wo)
    d = _distr(p)
    wi_up = dr.select(wi.z < 0.0, -wi, wi)
    dwh_dwo = dr.select(h.reflect, dr.rcp(4.0 * h.dot_o), dr.square(h.eta) * h.dot_o / h.denom)
    prob = _pdf_m(p, d, wi_up, h.m) * dr.select(h.reflect, h.F, 1.0 - h.F) * dr.abs(dwh_dwo)
    ok = h.ok & dr.isfinite(prob) & (prob > 0.0)
    return dr.select(ok, prob, 0.0)


def sample(p: RoughDielectricParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    ci = wi.z
    active = ci != 0.0
    wi_up = dr.select(ci < 0.0, -wi, wi)
    d = _distr(p)
    m = _sample_m(p, d, wi_up, u2)
    pdf_m = _pdf_m(p, d, wi_up, m)

    dot_i = dr.dot(wi, m)
    F, cos_t, eta_it, eta_ti = fresnel_dielectric(dot_i, p.eta)
    refl = u1 <= F
    wo_r = 2.0 * dot_i * m - wi
    wo_t = m * dr.fma(dot_i, eta_ti, cos_t) - wi * eta_ti
    wo = dr.select(refl, wo_r, wo_t)
    dot_o = dr.dot(wo, m)
    dwh_dwo = dr.select(refl, dr.rcp(4.0 * dot_o),
                        dr.square(eta_it) * dot_o / dr.square(dot_i + eta_it * dot_o))
    prob = pdf_m * dr.select(refl, F, 1.0 - F) * dr.abs(dwh_dwo)

    # eval / pdf (see the module docs)
    def visible():
        return d.G1(wo, m)

    def all_normals():
        ds = _distr(p, _walter_scale(ci))
        return d.G(wi, wo, m) * dot_i * d.D(m) / (ci * m.z * ds.D(m))

    if isinstance(p.visible, bool):
        g = visible() if p.visible else all_normals()
    else:
        g = dr.select(p.visible, visible(), all_normals())
    tint_w = dr.select(refl, p.r, p.t * dr.square(eta_ti))

    matched = active & (p.eta == 1.0)  # index matched: the interface is not there
    smooth = (active & ~matched & (pdf_m > 0.0) & dr.isfinite(prob) & (prob > 0.0)
              & dr.isfinite(g) & (g > 0.0) & _finite3(wo))
    valid = smooth | matched
    weight = dr.select(smooth, tint_w * g, 0.0)
    weight = dr.select(matched, p.t, weight)
    wo = dr.select(matched, -wi, dr.select(smooth, wo, Array3f(0.0, 0.0, 1.0)))
    return BSDFSample(wo, Array3f(weight), dr.select(smooth, prob, 0.0), valid, matched,
                      dr.select(matched | refl, 1.0, eta_it))
