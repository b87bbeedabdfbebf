"""Mitsuba 3's ``principledthin`` BSDF (``src/bsdfs/principledthin.cpp`` and
``principledhelpers.h``, Mitsuba 3.9): the principled model of a thin sheet
with no inside (leaves, paper, cloth), seen alike from both sides.

Both sides: with ``s = sign(wi.z)``, ``wi' = s wi``, ``wo' = s wo`` (then
``wi'.z > 0``); ``reflect = wo'.z > 0``, ``refract = wo'.z < 0``;
``h = normalize(wi' + (wo'.x, wo'.y, |wo'.z|))`` (the transmitted direction
is the reflected one mirrored through the sheet). ``wi.z = 0`` gives 0.

Parameters: ``c = base_color``, ``r = roughness``, ``aniso = anisotropic``,
``st = spec_trans``, ``dt = diff_trans / 2`` (``diff_trans`` runs 0..2; the others
0..1: :func:`derive` refuses numbers outside, textures are clipped),
``sheen``, ``sheen_tint``, ``flatness``, ``spec_tint``, ``eta`` (a number:
the sheet's IOR, default 1.5) and the sampling rates ``srr``, ``srt``,
``sdt``, ``sdr`` (``specular_reflectance``, ``specular_transmittance``,
``diffuse_transmittance``, ``diffuse_reflectance``, default 1). Lobes (each
traced only when some material of the scene gives its parameter, Mitsuba's
``m_has_*``; the micro/macro compatibility tests as principled's)::

    F = F_diel(wi'.h; eta)
    spec. reflection    st F_thin D G / (4 wi'.z),  GGX (r^2, aniso)
                        F_thin = lerp(F, Schlick(c_tint R0(eta)), spec_tint)
    spec. transmission  st c (1 - F) D' G' / (4 wi'.z),  GGX of the roughness
                        (0.65 eta - 0.35) r
    diffuse             (1 - st)(1 - dt) c/pi |wo'.z| (Burley diffuse and
                        retro-reflection, lerp to the fake subsurface by flatness)
    sheen               sheen (1 - st)(1 - dt) SW(|h.wo'|) c_sheen |wo'.z|
    diffuse transm.     (1 - st) dt c/pi |wo'.z|

Sampling picks specular reflection, specular transmission, diffuse
reflection or diffuse transmission with probabilities proportional to
``st srr / 2``, ``st srt / 2``, ``sdr (1 - st)(1 - dt)``, ``sdt (1 - st) dt``
(visible GGX normals; cosine hemispheres), and weighs the sample by the
whole mixture's ``f / pdf``, as Mitsuba does.
"""

from __future__ import annotations

import math
import numbers

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials.bsdf_kinds import given
from ..warp import INV_PI, concentric_polar, disk_to_cosine_hemisphere, polar_to_disk, square_to_cosine_hemisphere
from . import BSDFSample
from . import microfacet as mf
from .principled import ALPHA_MIN, _schlick, _sw, _tint, fresnel

#: float parameters (textures read as their luminance); ``thin_eta`` is ``eta`` (derive)
FLOATS = ("roughness", "anisotropic", "spec_trans", "sheen", "sheen_tint", "flatness", "spec_tint",
          "diff_trans")
RATES = ("specular_reflectance_sampling_rate", "specular_transmittance_sampling_rate",
         "diffuse_transmittance_sampling_rate", "diffuse_reflectance_sampling_rate")
FIELDS = {"base_color": "rgb", **{n: "float" for n in FLOATS}, "thin_eta": "float",
          **{n: "float" for n in RATES}}
DELTA = False
COLOR = "base_color"
#: the optional parts (Mitsuba's ``m_has_*``): traced when some material gives the parameter
FLAGS = ("anisotropic", "spec_trans", "sheen", "sheen_tint", "flatness", "spec_tint", "diff_trans")


def _upper(name: str) -> float:
    return 2.0 if name == "diff_trans" else 1.0


def derive(params: dict) -> dict:
    """Host side: checks (a number outside its range -- [0, 2] for ``diff_trans``, [0, 1]
    for the others -- is refused; a texture's values are clipped to it), and ``eta`` as the
    field ``thin_eta``."""
    for name in FLOATS:
        v = params.get(name, 0.0)
        if isinstance(v, numbers.Real) and not (0.0 <= v <= _upper(name)):
            raise ValueError(f"principledthin: {name} = {v!r} is outside [0, {_upper(name):g}]")
    eta = params.get("eta", 1.5)
    if not (isinstance(eta, numbers.Real) and math.isfinite(eta) and eta > 0.0):
        raise ValueError(f"principledthin: eta = {eta!r} must be a number > 0")
    for name in RATES:
        v = params.get(name, 1.0)
        if not (isinstance(v, numbers.Real) and math.isfinite(v) and v >= 0.0):
            raise ValueError(f"principledthin: {name} = {v!r} must be a number >= 0")
    return {"thin_eta": float(eta)}


class ThinParams:
    DRJIT_STRUCT = {"base_color": Array3f, **{n: Float for n in FLOATS}, "eta": Float,
                    "srr": Float, "srt": Float, "sdt": Float, "sdr": Float}
    flags: frozenset = frozenset(FLAGS)

    def __init__(self, base_color=None, roughness=None, anisotropic=None, spec_trans=None, sheen=None,
                 sheen_tint=None, flatness=None, spec_tint=None, diff_trans=None, eta=None, srr=None,
                 srt=None, sdt=None, sdr=None, flags=None):
        def f(v, d):
            return v if v is not None else Float(d)

        self.base_color = base_color if base_color is not None else Array3f(0.5)
        self.roughness = f(roughness, 0.5)
        self.anisotropic, self.spec_trans, self.sheen = f(anisotropic, 0.0), f(spec_trans, 0.0), f(sheen, 0.0)
        self.sheen_tint, self.flatness, self.spec_tint = f(sheen_tint, 0.0), f(flatness, 0.0), f(spec_tint, 0.0)
        self.diff_trans = f(diff_trans, 0.0)
        self.eta = f(eta, 1.5)
        self.srr, self.srt, self.sdt, self.sdr = f(srr, 1.0), f(srt, 1.0), f(sdt, 1.0), f(sdr, 1.0)
        if flags is not None:
            self.flags = frozenset(flags)


def flags_of(specs) -> frozenset:
    ps = [getattr(s, "params", s) for s in specs]
    return frozenset(n for n in FLAGS if any(given(p.get(n, 0.0)) for p in ps))


def params(table, si, active) -> ThinParams:
    flags = flags_of(table.specs_of("principledthin"))
    n = dr.width(si.material)
    vals = {"base_color": table.value("base_color", si, active),
            "roughness": dr.clip(table.value("roughness", si, active), 0.0, 1.0),
            "eta": table.value("thin_eta", si, active)}
    for name in FLOATS[1:]:
        vals[name] = dr.clip(table.value(name, si, active), 0.0, _upper(name)) if name in flags \
            else dr.zeros(Float, n)
    for short, name in zip(("srr", "srt", "sdt", "sdr"), RATES):
        vals[short] = table.value(name, si, active)
    return ThinParams(**vals, flags=flags)


# ------------------------------------------------------------------ helpers
def _alphas(aniso: Float, r: Float, anisotropic: bool):
    r2 = dr.square(r)
    if not anisotropic:
        a = dr.maximum(ALPHA_MIN, r2)
        return a, None
    aspect = dr.sqrt(1.0 - 0.9 * aniso)
    return dr.maximum(ALPHA_MIN, r2 / aspect), dr.maximum(ALPHA_MIN, r2 * aspect)


def _distribution(p: ThinParams, transmit: Bool) -> mf.Distribution:
    """The GGX of the specular reflection, or where ``transmit`` that of the specular
    transmission (roughness scaled by ``0.65 eta - 0.35``). A direction is either reflected
    or transmitted, so one distribution per lane serves both lobes: its ``D``, ``G`` and
    visible normals are those of the lane's lobe, to the float."""
    r = dr.select(transmit, (0.65 * p.eta - 0.35) * p.roughness, p.roughness)
    return mf.Distribution(False, *_alphas(p.anisotropic, r, "anisotropic" in p.flags))


def _probabilities(p: ThinParams):
    """(spec. reflection, spec. transmission, diffuse reflection, diffuse transmission)."""
    st = p.spec_trans if "spec_trans" in p.flags else Float(0.0)
    dt = 0.5 * p.diff_trans if "diff_trans" in p.flags else Float(0.0)
    zero = dr.zeros(Float, dr.width(p.roughness))
    psr = st * p.srr * 0.5 if "spec_trans" in p.flags else zero
    pst = st * p.srt * 0.5 if "spec_trans" in p.flags else zero
    pdr = p.sdr * (1.0 - st) * (1.0 - dt)
    pdt = p.sdt * (1.0 - st) * dt if "diff_trans" in p.flags else zero
    tot = psr + pst + pdr + pdt
    inv = dr.select(tot > 0.0, dr.rcp(dr.select(tot > 0.0, tot, 1.0)), 0.0)
    return psr * inv, pst * inv, pdr * inv, pdt * inv


class _Geometry:
    def __init__(self, wi: Array3f, wo: Array3f):
        self.active = wi.z != 0.0
        self.wi = dr.mulsign(wi, wi.z)
        self.wo = dr.mulsign(wo, wi.z)
        self.cos_i = self.wi.z
        self.cos_o = self.wo.z
        self.reflect = self.cos_o > 0.0
        self.refract = self.cos_o < 0.0
        wo_r = Array3f(self.wo.x, self.wo.y, dr.abs(self.wo.z))
        self.wo_r = wo_r
        v = self.wi + wo_r
        ok = dr.squared_norm(v) > 0.0
        self.h = dr.normalize(dr.select(ok, v, Array3f(0.0, 0.0, 1.0)))
        wi_h, wo_h = dr.dot(self.wi, self.h), dr.dot(self.wo, self.h)
        self.compat_r = ok & (wi_h > 0.0) & (wo_h > 0.0)
        self.compat_t = ok & (wi_h > 0.0) & (wo_h < 0.0)


def eval(p: ThinParams, wi: Array3f, wo: Array3f) -> Array3f:
    g = _Geometry(wi, wo)
    fl = p.flags
    c = p.base_color
    st = p.spec_trans if "spec_trans" in fl else Float(0.0)
    dt = 0.5 * p.diff_trans if "diff_trans" in fl else Float(0.0)
    safe_i = dr.select(g.active, g.cos_i, 1.0)
    abs_o = dr.abs(g.cos_o)
    value = Array3f(0.0)
    if "spec_trans" in fl:
        dist = _distribution(p, g.refract)
        D, G = dist.D(g.h), dist.G(g.wi, g.wo, g.h)
        F = fresnel(dr.dot(g.wi, g.h), p.eta)[0]
        on = g.active & (st > 0.0) & g.reflect & g.compat_r
        if "spec_tint" in fl:
            r0 = dr.square((p.eta - 1.0) / (p.eta + 1.0))
            f_thin = dr.lerp(Array3f(F), _schlick(_tint(c) * r0, dr.dot(g.wi, g.h), p.eta), p.spec_tint)
        else:
            f_thin = Array3f(F)
        value += dr.select(on, f_thin * (st * D * G / (4.0 * safe_i)), 0.0)
        on = g.active & g.refract & (st > 0.0) & g.compat_t
        t = st * (1.0 - F) * D * G / (4.0 * safe_i)
        value += dr.select(on, c * t, 0.0)

    on = g.active & g.reflect & (st < 1.0) & (dt < 1.0)
    fo, fi = _sw(abs_o), _sw(g.cos_i)
    f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
    cos_d = dr.dot(g.h, g.wo)
    rr = 2.0 * p.roughness * dr.square(cos_d)
    f = f_diff + rr * (fo + fi + fo * fi * (rr - 1.0))
    if "flatness" in fl:
        fss90 = 0.5 * rr
        fss = dr.lerp(1.0, fss90, fo) * dr.lerp(1.0, fss90, fi)
        sum_io = dr.select(on, abs_o + g.cos_i, 1.0)
        f_ss = 1.25 * (fss * (1.0 / sum_io - 0.5) + 0.5)
        f = dr.lerp(f, f_ss, p.flatness)
    value += dr.select(on, c * ((1.0 - st) * g.cos_o * INV_PI * (1.0 - dt) * f), 0.0)
    if "sheen" in fl:
        w = p.sheen * (1.0 - st) * _sw(dr.abs(cos_d)) * (1.0 - dt) * abs_o
        c_sheen = dr.lerp(Array3f(1.0), _tint(c), p.sheen_tint) if "sheen_tint" in fl else Array3f(1.0)
        value += dr.select(on, c_sheen * w, 0.0)
    if "diff_trans" in fl:
        on = g.active & g.refract & (st < 1.0) & (dt > 0.0)
        value += dr.select(on, c * ((1.0 - st) * dt * INV_PI * abs_o), 0.0)
    return dr.select(g.active, value, 0.0)


def pdf(p: ThinParams, wi: Array3f, wo: Array3f) -> Float:
    g = _Geometry(wi, wo)
    psr, pst, pdr, pdt = _probabilities(p)
    v = Float(0.0)
    if "spec_trans" in p.flags:
        pv = _distribution(p, g.refract).pdf_visible(g.wi, g.h)
        jac = dr.abs(dr.rcp(4.0 * dr.dot(g.wo_r, g.h)))
        on = g.compat_r & g.reflect
        v += dr.select(on, psr * pv * jac, 0.0)
        on = g.compat_t & g.refract
        v += dr.select(on, pst * pv * jac, 0.0)
    v += dr.select(g.reflect, pdr * INV_PI * g.cos_o, 0.0)
    if "diff_trans" in p.flags:
        v += dr.select(g.refract, pdt * INV_PI * (-g.cos_o), 0.0)
    return dr.select(g.active & dr.isfinite(v), v, 0.0)


def sample(p: ThinParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    n_lanes = max(dr.width(wi), dr.width(u1), dr.width(u2))
    active = wi.z != 0.0
    wi_up = dr.select(active, dr.mulsign(wi, wi.z), Array3f(0.0, 0.0, 1.0))
    psr, pst, pdr, _ = _probabilities(p)
    pick_sr = u1 < psr
    pick_st = (u1 >= psr) & (u1 < psr + pst)
    pick_dt = u1 >= psr + pst + pdr
    ok = Bool(active)
    if "spec_trans" in p.flags:
        # one concentric disk point (one sincos) for the cosine hemisphere of a diffuse
        # lobe and the visible-normal sampler of a specular one (both map u2 so)
        disk = polar_to_disk(*concentric_polar(u2))
        hemi = disk_to_cosine_hemisphere(disk)
        wo = hemi  # diffuse reflection
        # one visible normal, of the picked lobe's distribution
        m = _distribution(p, pick_st).sample_visible_normal(wi_up, u2, disk)
        wo_r = 2.0 * dr.dot(wi_up, m) * m - wi_up
        ok &= ~pick_sr | ((dr.dot(wi_up, m) > 0.0) & (dr.dot(wo_r, m) > 0.0) & (wo_r.z > 0.0))
        wo_t = Array3f(wo_r.x, wo_r.y, -wo_r.z)
        ok &= ~pick_st | ((dr.dot(wi_up, m) > 0.0) & (dr.dot(wo_t, -m) > 0.0) & (wo_t.z < 0.0))
        wo = dr.select(pick_sr, wo_r, dr.select(pick_st, wo_t, wo))
    else:
        hemi = square_to_cosine_hemisphere(u2)
        wo = hemi  # diffuse reflection
    if "diff_trans" in p.flags:
        wo = dr.select(pick_dt, -hemi, wo)
    else:
        ok &= ~pick_dt
    wo = dr.mulsign(wo, wi.z)
    wo = dr.select(ok, wo, Array3f(0.0, 0.0, 1.0))
    pdf_v = pdf(p, wi, wo)
    ok &= pdf_v > 0.0
    f = eval(p, wi, wo)
    weight = dr.select(ok, f / dr.select(ok, pdf_v, 1.0), 0.0)
    return BSDFSample(wo, weight, dr.select(ok, pdf_v, 0.0), ok, dr.zeros(Bool, n_lanes),
                      dr.full(Float, 1.0, n_lanes))
