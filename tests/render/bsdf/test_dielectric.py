"""Smooth dielectric lobe (drpt/render/bsdf/dielectric.py): exact Fresnel
(analytic values, Brewster, total internal reflection), Snell's law,
reflection frequency = F, energy bookkeeping, extremes (IOR 1 and 2.5,
grazing and exactly tangent wi, both sides), the parameters (int_ior /
ext_ior as numbers or Mitsuba's names, the two tints, gathered through a
stand-in material table), and sample-for-sample equality with Mitsuba's
``dielectric`` (several IOR pairs, eta < 1, tints) with a negative control."""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float

from drpt.materials import bsdf_kinds
from drpt.render.bsdf import dielectric
from drpt.testing import mitsuba
from support.dielectric import FakeTable, Spec


def _f(a):
    return Float(np.ascontiguousarray(a, dtype=np.float32))


def _v3(a):
    a = np.asarray(a, dtype=np.float32)
    return Array3f(_f(a[0]), _f(a[1]), _f(a[2]))


def _dirs_at(cos):
    """Unit directions in the xz-plane with the given (signed) cosines."""
    cos = np.asarray(cos, dtype=np.float64)
    return np.stack([np.sqrt(np.maximum(1.0 - cos * cos, 0.0)), np.zeros_like(cos), cos])


def _sample(eta, wi, u):
    wi = np.asarray(wi, dtype=np.float32)
    n = wi.shape[1]
    etas = np.broadcast_to(np.asarray(eta, np.float32), (n,))
    bs = dielectric.sample(dielectric.DielectricParams(_f(etas)), _v3(wi), _f(u),
                           Array2f(_f(np.full(n, 0.5)), _f(np.full(n, 0.5))))
    return {k: np.broadcast_to(np.array(getattr(bs, k)), (3, n) if k in ("wo", "weight") else (n,))
            for k in ("wo", "weight", "pdf", "valid", "delta", "eta")}


def _fresnel(cos, eta):
    f, ct, eit, eti = dielectric.fresnel_dielectric(_f(np.atleast_1d(cos)), _f(np.atleast_1d(eta)))
    return np.array(f), np.array(ct), np.array(eit), np.array(eti)


def _reference_fresnel(theta_i, n1, n2):
    """Textbook Fresnel in terms of angles (float64), independent of the kernel."""
    s = n1 / n2 * np.sin(theta_i)
    tir = s >= 1.0
    theta_t = np.arcsin(np.minimum(s, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (np.sin(theta_i - theta_t) / np.sin(theta_i + theta_t)) ** 2
        rp = (np.tan(theta_i - theta_t) / np.tan(theta_i + theta_t)) ** 2
    normal = theta_i == 0
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    r = np.where(normal, r0, 0.5 * (rs + rp))
    return np.where(tir, 1.0, r)


# ------------------------------------------------------------------ Fresnel
@pytest.mark.parametrize("n", [1.2, 1.33, 1.5, 2.0, 2.5])
def test_normal_incidence(n):
    want = ((n - 1) / (n + 1)) ** 2
    f, ct, eit, eti = _fresnel([1.0, -1.0], [n, n])
    np.testing.assert_allclose(f, [want, want], rtol=1e-5)
    np.testing.assert_allclose(ct, [-1.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(eit, [n, 1 / n], rtol=1e-6)
    np.testing.assert_allclose(eti, [1 / n, n], rtol=1e-6)


@pytest.mark.parametrize("n", [1.33, 1.5, 2.5])
def test_against_angle_formulas(n):
    theta = np.linspace(0.0, np.pi / 2 - 1e-3, 400)
    # outside: n1 = 1, n2 = n; inside: n1 = n, n2 = 1 (includes TIR)
    f_out, ct_out, *_ = _fresnel(np.cos(theta), np.full_like(theta, n))
    f_in, ct_in, *_ = _fresnel(-np.cos(theta), np.full_like(theta, n))
    np.testing.assert_allclose(f_out, _reference_fresnel(theta, 1.0, n), atol=2e-6, rtol=2e-5)
    np.testing.assert_allclose(f_in, _reference_fresnel(theta, n, 1.0), atol=2e-6, rtol=2e-5)
    # signed transmitted cosines: opposite side to wi
    assert np.all(ct_out <= 0.0) and np.all(ct_in >= 0.0)


@pytest.mark.parametrize("n", [1.33, 1.5, 2.5])
def test_brewster_angle(n):
    # Outside: tan(theta_B) = n; inside: tan(theta_B) = 1/n. R_p = 0 there, so F = R_s / 2,
    # and with theta_i + theta_t = 90 deg, R_s = cos^2(2 theta_B).
    for cos_sign, tb in ((1.0, math.atan(n)), (-1.0, math.atan(1.0 / n))):
        f, *_ = _fresnel([cos_sign * math.cos(tb)], [n])
        rs = math.cos(2 * tb) ** 2
        assert f[0] == pytest.approx(0.5 * rs, rel=1e-4, abs=1e-7)
        # and it is a minimum of R_p: F just around theta_B exceeds R_s(theta)/2
        for d in (-0.01, 0.01):
            fd, *_ = _fresnel([cos_sign * math.cos(tb + d)], [n])
            n1, n2 = (1.0, n) if cos_sign > 0 else (n, 1.0)
            tt = math.asin(n1 / n2 * math.sin(tb + d))
            rs_d = (math.sin(tb + d - tt) / math.sin(tb + d + tt)) ** 2
            assert fd[0] > 0.5 * rs_d


@pytest.mark.parametrize("n", [1.33, 1.5, 2.5])
def test_total_internal_reflection(n):
    crit = math.asin(1.0 / n)
    theta = np.concatenate([np.linspace(crit + 1e-3, np.pi / 2, 50), [np.pi / 2 - 1e-6]])
    f, ct, *_ = _fresnel(-np.cos(theta), np.full_like(theta, n))
    np.testing.assert_array_equal(f, 1.0)
    np.testing.assert_array_equal(ct, 0.0)
    # just below the critical angle some light gets out
    f2, ct2, *_ = _fresnel([-math.cos(crit - 1e-2)], [n])
    assert f2[0] < 1.0 and ct2[0] > 0.0
    # sampling under TIR always reflects with weight 1
    wi = _dirs_at(-np.cos(theta))
    s = _sample(n, wi, np.full(theta.size, 0.999999))
    assert np.all(s["wo"][2] < 0) and np.all(s["weight"] == 1.0) and np.all(s["eta"] == 1.0)


# ------------------------------------------------------------------ sampling
@pytest.mark.parametrize("n", [1.5, 2.5])
@pytest.mark.parametrize("cos", [0.9, 0.3, 0.05, -0.95, -0.6])
def test_snell_and_reflection_geometry(n, cos):
    rng = np.random.default_rng(3)
    m = 2000
    phi = rng.uniform(0, 2 * np.pi, m)
    s = math.sqrt(1 - cos * cos)
    wi = np.stack([s * np.cos(phi), s * np.sin(phi), np.full(m, cos)])
    u = rng.random(m)
    out = _sample(n, wi, u)
    wo = out["wo"].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=0), 1.0, atol=2e-6)
    refl = wo[2] * cos > 0
    # reflection: mirror about the normal
    np.testing.assert_allclose(wo[:, refl], (wi * np.array([[-1], [-1], [1]]))[:, refl], atol=1e-6)
    # refraction: n_i sin_i = n_t sin_t, opposite azimuth, other side
    tr = ~refl
    if tr.any():
        n_i, n_t = (1.0, n) if cos > 0 else (n, 1.0)
        sin_t = np.hypot(wo[0, tr], wo[1, tr])
        np.testing.assert_allclose(n_t * sin_t, n_i * s, atol=2e-6)
        # coplanar with the normal, on the far side of it
        dot_xy = wo[0, tr] * wi[0, tr] + wo[1, tr] * wi[1, tr]
        np.testing.assert_allclose(dot_xy, -sin_t * s, atol=2e-6)
        assert np.all(np.sign(wo[2, tr]) == -np.sign(cos))
    assert np.all(out["delta"]) and np.all(out["valid"]) and np.all(out["pdf"] == 0.0)


@pytest.mark.parametrize("n", [1.33, 1.5, 2.5])
@pytest.mark.parametrize("cos", [1.0, 0.5, 0.1, -0.9, -0.5])
def test_reflection_frequency_is_fresnel(n, cos):
    m = 200_000
    u = np.random.default_rng(11).random(m)
    wi = _dirs_at(np.full(m, cos))
    out = _sample(n, wi, u)
    k = int(np.count_nonzero(out["wo"][2] * cos > 0))
    f = float(_fresnel([cos], [n])[0][0])
    if f in (0.0, 1.0):
        assert k == (m if f == 1.0 else 0)
        return
    z = (k - m * f) / math.sqrt(m * f * (1 - f))
    assert abs(z) < 4.0, (k / m, f, z)


@pytest.mark.parametrize("n", [1.0, 1.33, 1.5, 2.5])
@pytest.mark.parametrize("cos", [1.0, 0.7, 0.2, 1e-3, -1.0, -0.8, -0.3])
def test_energy(n, cos):
    """Expected weight is F + (1 - F) eta_ti^2; with the eta^2 correction the
    interface neither creates nor loses energy (expectation 1)."""
    m = 100_000
    u = (np.arange(m) + 0.5) / m  # stratified: expectation up to O(1/m)
    wi = _dirs_at(np.full(m, cos))
    out = _sample(n, wi, u)
    f, _, eit, eti = (x[0] for x in _fresnel([cos], [n]))
    w = out["weight"].astype(np.float64)
    np.testing.assert_array_equal(w[0], w[1])
    np.testing.assert_array_equal(w[0], w[2])
    assert w[0].mean() == pytest.approx(f + (1 - f) * eti ** 2, abs=2e-5)
    assert (w[0] * out["eta"].astype(np.float64) ** 2).mean() == pytest.approx(1.0, abs=1e-5)
    # the weights themselves: 1 on reflection, eta_ti^2 on refraction
    refl = out["wo"][2] * cos > 0
    np.testing.assert_allclose(w[0, refl], 1.0)
    np.testing.assert_allclose(w[0, ~refl], eti ** 2, rtol=1e-6)
    np.testing.assert_allclose(out["eta"][~refl], eit, rtol=1e-6)
    np.testing.assert_array_equal(out["eta"][refl], 1.0)


def test_index_matched_passes_straight_through():
    rng = np.random.default_rng(5)
    v = rng.normal(size=(3, 5000))
    v /= np.linalg.norm(v, axis=0)
    v[:, :4] = _dirs_at([1e-6, -1e-6, 0.0, -0.0])
    out = _sample(1.0, v, rng.random(5000))
    np.testing.assert_allclose(out["wo"], -v.astype(np.float32), atol=1e-6)
    np.testing.assert_array_equal(out["weight"], 1.0)
    np.testing.assert_array_equal(out["eta"], 1.0)
    f, *_ = _fresnel(v[2], np.ones(5000))
    np.testing.assert_array_equal(f, 0.0)


@pytest.mark.parametrize("n", [1.0, 1.0001, 1.5, 2.5, 4.0, 0.25])
def test_extremes_are_finite(n):
    cos = np.array([1.0, -1.0, 1e-6, -1e-6, 0.0, -0.0, 1e-30, -1e-30, 0.5, -0.5])
    wi = _dirs_at(cos)
    for u in (0.0, 0.5, 1.0 - 2 ** -24):
        out = _sample(n, wi, np.full(cos.size, u))
        for k in ("wo", "weight", "eta"):
            assert np.all(np.isfinite(out[k])), (k, out[k])
        assert np.all(out["weight"] >= 0.0)
        np.testing.assert_allclose(np.linalg.norm(out["wo"], axis=0), 1.0, atol=1e-5)
    f, ct, eit, eti = _fresnel(cos, np.full(cos.size, n))
    assert np.all(np.isfinite(f)) and np.all((f >= 0) & (f <= 1))
    assert np.all(np.isfinite(ct)) and np.all(np.isfinite(eit)) and np.all(np.isfinite(eti))
    if n != 1.0:
        # exactly tangent wi: everything reflects (grazing limit of Fresnel)
        assert f[4] == 1.0 and f[5] == 1.0


def test_eval_pdf_are_zero():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(2, 3, 100))
    p = dielectric.DielectricParams(Float(1.5))
    assert np.all(np.array(dielectric.eval(p, _v3(a), _v3(b))) == 0.0)
    assert np.all(np.array(dielectric.pdf(p, _v3(a), _v3(b))) == 0.0)


# ------------------------------------------------------------------ parameters
def test_derive_relative_ior():
    assert dielectric.derive({"int_ior": 1.5, "ext_ior": 1.0}) == {"rel_ior": 1.5}
    # Mitsuba's defaults (bk7 in air) and names, divided in float32 as Mitsuba does
    d = dielectric.derive(bsdf_kinds.defaults("dielectric"))
    assert d["rel_ior"] == float(np.float32(np.float32(1.5046) / np.float32(1.000277)))
    assert dielectric.derive({"int_ior": "Water", "ext_ior": "vacuum"})["rel_ior"] == float(np.float32(1.333))
    assert dielectric.derive({"int_ior": 1.0, "ext_ior": "water"})["rel_ior"] == pytest.approx(1 / 1.333, rel=1e-7)
    for bad in ({"int_ior": -1.5, "ext_ior": 1.0}, {"int_ior": 0.0, "ext_ior": 1.0},
                {"int_ior": 1.5, "ext_ior": float("nan")}, {"int_ior": "glas", "ext_ior": 1.0},
                {"int_ior": 1.5, "ext_ior": float("inf")}, {"int_ior": None, "ext_ior": 1.0}):
        with pytest.raises(ValueError):
            dielectric.derive(bad)


def test_fields_and_params_from_table():
    assert dielectric.FIELDS == {"rel_ior": "float", "specular_reflectance": "rgb",
                                 "specular_transmittance": "rgb"}
    assert dielectric.DELTA
    specs = [Spec("dielectric", {"int_ior": 1.5, "ext_ior": 1.0, "specular_reflectance": (0.5, 0.25, 1.0)}),
             Spec("dielectric", {"int_ior": 2.0, "ext_ior": 1.0, "specular_transmittance": (0.1, 0.2, 0.3)})]
    table = FakeTable(specs, dielectric)
    p = dielectric.params(table, table.si([1, 0, 1]), Bool(True))
    np.testing.assert_allclose(np.array(p.eta), [2.0, 1.5, 2.0])
    np.testing.assert_allclose(np.array(p.r), [[1, 0.5, 1], [1, 0.25, 1], [1, 1, 1]])
    np.testing.assert_allclose(np.array(p.t), [[0.1, 1, 0.1], [0.2, 1, 0.2], [0.3, 1, 0.3]], rtol=1e-6)
    # all tints white: nothing gathered for them (constant 1)
    table = FakeTable([Spec("dielectric", {"int_ior": 1.5, "ext_ior": 1.0})], dielectric)
    p = dielectric.params(table, table.si([0, 0]), Bool(True))
    assert table.asked == ["rel_ior"] and dr.width(p.r) == 1 and np.all(np.array(p.r) == 1.0)


@pytest.mark.parametrize("n", [1.5, 2.5])
def test_tints_scale_weights(n):
    m = 4000
    rng = np.random.default_rng(9)
    v = rng.normal(size=(3, m))
    v /= np.linalg.norm(v, axis=0)
    u = rng.random(m)
    r, t = (0.9, 0.5, 0.25), (0.2, 0.7, 1.0)
    plain = _sample(n, v, u)
    p = dielectric.DielectricParams(_f(np.full(m, n)), Array3f(*r), Array3f(*t))
    bs = dielectric.sample(p, _v3(v), _f(u), Array2f(0.5, 0.5))
    w = np.array(bs.weight)
    np.testing.assert_array_equal(np.array(bs.wo), plain["wo"])
    refl = plain["wo"][2] * v[2] > 0
    np.testing.assert_allclose(w[:, refl], np.array(r)[:, None] * plain["weight"][:, refl], rtol=1e-6)
    np.testing.assert_allclose(w[:, ~refl], np.array(t)[:, None] * plain["weight"][:, ~refl], rtol=1e-6)


# ------------------------------------------------------------------ Mitsuba
MITSUBA_CASES = [
    {"int_ior": 1.0, "ext_ior": 1.0},
    {"int_ior": 1.33, "ext_ior": 1.0},
    {"int_ior": 1.5, "ext_ior": 1.0},
    {"int_ior": 2.5, "ext_ior": 1.0},
    {"int_ior": "bk7", "ext_ior": "air"},  # Mitsuba's defaults
    {"int_ior": "air", "ext_ior": "water"},  # eta < 1: a bubble
    {"int_ior": "diamond", "ext_ior": 1.2, "specular_reflectance": (0.9, 0.5, 0.2),
     "specular_transmittance": (0.3, 0.6, 1.0)},
]


def _mitsuba_dict(params: dict) -> dict:
    d = {"type": "dielectric"}
    for k, v in params.items():
        d[k] = {"type": "rgb", "value": list(v)} if isinstance(v, tuple) else v
    return d


@pytest.mark.mitsuba
@pytest.mark.parametrize("case", range(len(MITSUBA_CASES)))
def test_equals_mitsuba_dielectric(case):
    mi = mitsuba()
    params = MITSUBA_CASES[case]
    full = {**bsdf_kinds.defaults("dielectric"), **params}
    n = dielectric.derive(full)["rel_ior"]
    m = 10_000
    rng = np.random.default_rng(100 + case)
    v = rng.normal(size=(3, m))
    v /= np.linalg.norm(v, axis=0)
    v[:, :6] = _dirs_at([1e-6, -1e-6, 1.0, -1.0, 0.0, 0.02])
    v = v.astype(np.float32)
    u = rng.random(m).astype(np.float32)
    r, t = full["specular_reflectance"], full["specular_transmittance"]
    p = dielectric.DielectricParams(_f(np.full(m, n)), Array3f(*r), Array3f(*t))
    bs_o = dielectric.sample(p, _v3(v), _f(u), Array2f(0.5, 0.5))
    ours = {k: np.broadcast_to(np.array(getattr(bs_o, k)), (3, m) if k in ("wo", "weight") else (m,))
            for k in ("wo", "weight", "eta")}

    bsdf = mi.load_dict(_mitsuba_dict(params))
    assert float(mi.traverse(bsdf)["eta"]) == n  # same float32 relative IOR
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(v[0], v[1], v[2])
    bs, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(u), mi.Point2f(0.5, 0.5))
    mwo, mw = np.array(bs.wo), np.array(w)
    m_refl = np.array(bs.sampled_type) == int(mi.BSDFFlags.DeltaReflection)
    o_refl = ours["wo"][2] * v[2] > 0
    o_refl[v[2] == 0] = (ours["wo"][:, v[2] == 0] == v[:, v[2] == 0] * [[-1], [-1], [1]]).all(0) \
        & (n != 1.0)
    # Same lobe choice except (possibly) where u is within rounding of F.
    f = _fresnel(v[2], np.full(m, n))[0]
    near = np.abs(u - f) < 1e-6
    assert np.all((m_refl == o_refl) | near)
    same = m_refl == o_refl
    assert same.mean() > 0.999
    np.testing.assert_allclose(ours["wo"][:2, same], mwo[:2, same], atol=2e-6)
    # z of a refracted direction: compare cos_t^2. Mitsuba computes it as
    # 1 - eta_ti^2 (1 - cos_i^2), which cancels near grazing when eta_ti ~ 1 (up
    # to ~1e-4 off in z at cos ~ 1e-3); drpt's 1 - eta_ti^2 + eta_ti^2 cos_i^2 does not.
    z, mz = ours["wo"][2, same].astype(np.float64), mwo[2, same].astype(np.float64)
    np.testing.assert_allclose(z * z, mz * mz, atol=4e-7)
    assert np.all((np.sign(z) == np.sign(mz)) | (np.abs(z) < 1e-3))
    np.testing.assert_allclose(ours["weight"][:, same], mw[:, same], rtol=2e-6, atol=1e-7)
    np.testing.assert_allclose(ours["eta"][same], np.array(bs.eta)[same], rtol=1e-6)
    assert np.all(np.array(bs.sampled_type)[same & ~m_refl] ==
                  int(mi.BSDFFlags.DeltaTransmission))
    # the tints really reach the weights (not only white cases)
    if r != bsdf_kinds.WHITE:
        assert np.any(np.abs(mw[0, same & m_refl] - mw[2, same & m_refl]) > 0.1)


@pytest.mark.mitsuba
def test_mitsuba_comparison_catches_a_wrong_tint():
    """Negative control: swapping the two tints (a plausible slip) is caught by
    the comparison above (weights differ from Mitsuba's)."""
    mi = mitsuba()
    m = 2000
    v = _dirs_at(np.linspace(-0.99, 0.99, m)).astype(np.float32)
    u = np.random.default_rng(1).random(m).astype(np.float32)
    r, t = (0.9, 0.5, 0.2), (0.3, 0.6, 1.0)
    p = dielectric.DielectricParams(_f(np.full(m, 1.5)), Array3f(*t), Array3f(*r))  # swapped
    w = np.array(dielectric.sample(p, _v3(v), _f(u), Array2f(0.5, 0.5)).weight)
    bsdf = mi.load_dict(_mitsuba_dict({"int_ior": 1.5, "ext_ior": 1.0, "specular_reflectance": r,
                                       "specular_transmittance": t}))
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(v[0], v[1], v[2])
    _, mw = bsdf.sample(mi.BSDFContext(), si, mi.Float(u), mi.Point2f(0.5, 0.5))
    assert not np.allclose(w, np.array(mw), rtol=2e-6, atol=1e-7)
