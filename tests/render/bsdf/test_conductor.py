"""Conductors: drpt/render/bsdf/conductor.py (Mitsuba's ``conductor``) and
roughconductor.py (Mitsuba's ``roughconductor``), drpt/materials/conductors.py (the
named materials' complex IORs):

* the named-material table equals what the installed Mitsuba loads;
* fresnel_conductor equals mi.fresnel_conductor (incl. eta = k = 0, k = 0);
* conductor's sample and roughconductor's eval, pdf and sample (same u)
  equal Mitsuba's plugins on thousands of random direction pairs (grazing,
  below the horizon) for Au, Cu, Al, Ag, AlSb, none and explicit eta/k,
  Beckmann and GGX, alpha 1e-3 .. 1, anisotropic, sample_visible on and off;
* chi-square of sample against pdf at 0/45/80/89 degrees;
* weight == eval / pdf; white furnace (albedo <= 1, -> 1 for material none
  at small alpha; the non-visible sampler's estimate equals the visible one);
* finite, non-negative output at alpha 0 .. 1, eta 1 .. 4, k 0 .. 10, cos 1e-6;
* negative controls: a wrong alpha fails the equality and the chi-square test;
* params() with a stand-in material table: per-lane selection of the
  distribution / sample_visible / anisotropy equals the single-kind records.
"""

from __future__ import annotations

import os
from types import SimpleNamespace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float, UInt32

from drpt.materials import conductors
from drpt.materials.bsdf_kinds import defaults
from drpt.render.bsdf import REGISTRY, lobe
from drpt.render.bsdf import conductor as cd
from drpt.render.bsdf import roughconductor as rc
from drpt.testing import mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3


def _sphere(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return (v / np.linalg.norm(v, axis=0)).astype(np.float32)


def _dir_np(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def _dirs(theta_deg, n, phi_deg=0.0):
    return Array3f(*(Float(np.full(n, x, np.float32)) for x in _dir_np(theta_deg, phi_deg)))


def _close(a, b, rtol, atol=0.0, what=""):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    bad = np.abs(a - b) > atol + rtol * np.abs(b)
    assert not bad.any(), f"{what}: {bad.sum()} of {bad.size} differ, e.g. {a[bad][:4]} vs {b[bad][:4]}"


# ------------------------------------------------------------ spec -> records
def _spec(kind, **kw):
    p = defaults(kind)
    p.update(kw)
    return p


def _record(kind, p):
    """The lobe's parameter record for one material (width 1, broadcast)."""
    d = lobe(kind).derive(dict(p))
    r = Array3f(*(float(x) for x in np.broadcast_to(np.asarray(p["specular_reflectance"], float), (3,))))
    eta, k = Array3f(*d["cond_eta"]), Array3f(*d["cond_k"])
    if kind == "conductor":
        return cd.ConductorParams(r, eta, k)
    iso = p.get("alpha_u") is None
    return rc.RoughConductorParams(r, eta, k, Float(float(d["alpha_u"])),
                                   None if iso else Float(float(d["alpha_v"])),
                                   d["beckmann"] > 0.5, d["visible"] > 0.5)


def _rgb(v):
    return {"type": "rgb", "value": [float(x) for x in np.broadcast_to(np.asarray(v, float), (3,))]}


def _mi_bsdf(mi, kind, p):
    d = {"type": kind, **conductors.mitsuba_ior(p)}
    if p["specular_reflectance"] != (1.0, 1.0, 1.0):
        d["specular_reflectance"] = _rgb(p["specular_reflectance"])
    for key in ("eta", "k"):
        if key in d:
            d[key] = _rgb(d[key])
    if kind == "roughconductor":
        d["distribution"] = p["distribution"]
        d["sample_visible"] = bool(p["sample_visible"])
        if p.get("alpha_u") is None:
            d["alpha"] = float(p["alpha"])
        else:
            d["alpha_u"], d["alpha_v"] = float(p["alpha_u"]), float(p["alpha_v"])
    return mi.load_dict(d)


def _mi_si(mi, wi):
    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[1])
    si.wi = to_mitsuba_vec3(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    return si


ROUGH = [
    dict(material="Au", distribution="beckmann", alpha=0.1),
    dict(material="Cu", distribution="ggx", alpha=0.3),
    dict(material="Al", distribution="beckmann", alpha=1e-3),
    dict(material="Ag", distribution="ggx", alpha=1.0),
    dict(material="none", distribution="ggx", alpha=0.05, specular_reflectance=(0.9, 0.5, 0.2)),
    dict(eta=(1.5, 0.8, 0.3), k=(3.0, 2.5, 2.0), distribution="beckmann", alpha=0.5, sample_visible=False),
    dict(material="Au", distribution="ggx", alpha_u=0.05, alpha_v=0.4),
    dict(material="Cu", distribution="beckmann", alpha_u=0.3, alpha_v=0.08, sample_visible=False),
    dict(material="AlSb", distribution="ggx", alpha=0.2),
    dict(eta=1.2, distribution="ggx", alpha=0.02, sample_visible=False),
]


def _rid(c):
    m = c.get("material", "eta" if "eta" in c else "")
    a = c.get("alpha", (c.get("alpha_u"), c.get("alpha_v")))
    return f"{m}-{c['distribution']}-{a}-{'vis' if c.get('sample_visible', True) else 'all'}"


def _pairs(n, alpha, seed=1):
    """wi: mostly above, some grazing, some below; wo: half near the mirror direction."""
    wi = _sphere(n, seed)
    wi[2] = np.abs(wi[2])
    wi[:, :n // 50] *= -1.0
    g = slice(n // 50, n // 25)
    wi[2, g] = 1e-3
    wi[:, g] /= np.linalg.norm(wi[:, g], axis=0)
    wo = _sphere(n, seed + 1)
    near = np.array([-wi[0], -wi[1], wi[2]]) + (2.0 * alpha + 1e-3) * _sphere(n, seed + 2)
    near /= np.linalg.norm(near, axis=0)
    wo[:, ::2] = near[:, ::2]
    return wi.astype(np.float32), wo.astype(np.float32)


# ------------------------------------------------------------------ facts
@pytest.mark.mitsuba
def test_named_materials_equal_mitsuba():
    mi = mitsuba()
    ior_dir = os.path.join(os.path.dirname(mi.__file__), "data", "ior")
    names = {f.split(".")[0] for f in os.listdir(ior_dir) if f.endswith(".eta.spd")}
    assert names == set(conductors.MATERIALS)
    level = mi.log_level()
    mi.set_log_level(mi.LogLevel.Error)  # out-of-gamut clamping warnings
    try:
        for name, (eta, k) in conductors.MATERIALS.items():
            p = mi.traverse(mi.load_dict({"type": "conductor", "material": name}))
            assert np.array_equal(np.array(p["eta.value"], np.float32).ravel(), np.float32(eta)), name
            assert np.array_equal(np.array(p["k.value"], np.float32).ravel(), np.float32(k)), name
    finally:
        mi.set_log_level(level)


def test_resolve_rules():
    assert conductors.resolve({"material": "none"}) == ((0.0,) * 3, (1.0,) * 3)
    assert conductors.resolve({"material": "Au"}) == conductors.MATERIALS["Au"]
    assert conductors.resolve({"material": "Au", "eta": 1.5}) == ((1.5,) * 3, conductors.MATERIALS["Au"][1])
    assert conductors.resolve({"eta": (1, 2, 3)}) == ((1.0, 2.0, 3.0), (1.0,) * 3)  # k defaults to 1
    assert conductors.mitsuba_ior({"material": "Cu"}) == {"material": "Cu"}
    assert "material" not in conductors.mitsuba_ior({"material": "Cu", "k": 2.0})
    for bad in ({"material": "Unobtainium"}, {"eta": -1.0}, {"k": float("nan")}, {"eta": (1, 2)}):
        with pytest.raises(ValueError):
            conductors.resolve(bad)
    with pytest.raises(ValueError):
        rc.derive(_spec("roughconductor", alpha_u=0.1))
    with pytest.raises(ValueError):
        rc.derive(_spec("roughconductor", distribution="phong"))
    d = rc.derive(_spec("roughconductor", distribution="GGX", alpha=0.3, sample_visible=False))
    assert (d["alpha_u"], d["alpha_v"], d["beckmann"], d["visible"]) == (0.3, 0.3, 0.0, 0.0)
    assert REGISTRY["conductor"] == "conductor" and REGISTRY["roughconductor"] == "roughconductor"
    assert lobe("conductor").DELTA and not lobe("roughconductor").DELTA


@pytest.mark.mitsuba
def test_fresnel_equals_mitsuba():
    mi = mitsuba()
    rng = np.random.default_rng(3)
    n = 20_000
    c = rng.random(n).astype(np.float32)
    c[:100] = 0.0
    c[100:200] = 1.0
    c[200:300] = 1e-6
    eta = (rng.random(n) * 4.0).astype(np.float32)
    k = (rng.random(n) * 10.0).astype(np.float32)
    k[::3] = 0.0
    ours = np.array(cd.fresnel_conductor(Float(c), Float(eta), Float(k)))
    theirs = np.array(mi.fresnel_conductor(mi.Float(c), mi.Complex2f(mi.Float(eta), mi.Float(k))))
    ok = np.isfinite(theirs)
    assert ok.mean() > 0.99
    _close(ours[ok], theirs[ok], 1e-5, 1e-6, "F")
    assert np.isfinite(ours).all() and (ours >= 0).all() and (ours <= 1.0 + 1e-6).all()
    # the limits where Mitsuba divides 0 by 0
    z = Float(0.0)
    assert np.allclose(np.array(cd.fresnel_conductor(Float(1.0), z, z)), 1.0)  # eta = k = 0: R_p = R_s
    assert np.allclose(np.array(cd.fresnel_conductor(Float(0.0), Float(1.0), z)), 0.0)  # index matched
    assert np.allclose(np.array(cd.fresnel_conductor(Float(0.3, 1.0), z, Float(1.0))), 1.0)  # "none"


# ------------------------------------------------------------------ conductor
CONDUCTOR = [dict(material=m) for m in ("Au", "Cu", "Al", "Ag", "none", "AlSb")] + [
    dict(eta=(0.2, 0.9, 1.1), k=(3.9, 2.4, 2.1), specular_reflectance=(0.8, 0.7, 0.6))]


@pytest.mark.mitsuba
@pytest.mark.parametrize("case", CONDUCTOR, ids=lambda c: c.get("material", "eta"))
def test_conductor_sample_equals_mitsuba(case):
    mi = mitsuba()
    p = _spec("conductor", **case)
    wi, _ = _pairs(10_000, 0.1)
    bs = cd.sample(_record("conductor", p), to_drpt(wi, Array3f), Float(0.5), Array2f(0.5, 0.5))
    b = _mi_bsdf(mi, "conductor", p)
    mbs, mw = b.sample(mi.BSDFContext(), _mi_si(mi, wi), mi.Float(0.5), mi.Point2f(0.5, 0.5))
    mw = np.array(mw)
    ok = np.isfinite(mw).all(axis=0)
    assert ok.mean() > 0.999  # (Mitsuba: NaN for eta = k = 0 at normal incidence)
    valid = np.array(bs.valid)
    assert np.array_equal(valid, wi[2] > 0) and (mw[:, ~valid] == 0).all()  # Mitsuba: pdf 1, weight 0
    _close(np.array(bs.wo)[:, valid], np.array(mbs.wo)[:, valid], 0.0, 1e-7, "wo")
    _close(np.array(bs.weight)[:, ok], mw[:, ok], 1e-5, 1e-6, "weight")
    assert np.array(bs.delta).all() and (np.array(bs.pdf) == 0).all()
    w = np.array(bs.weight)
    assert np.isfinite(w).all() and (w >= 0).all() and (w <= 1.0 + 1e-6).all()
    z = np.array(cd.eval(_record("conductor", p), to_drpt(wi, Array3f), to_drpt(wi, Array3f)))
    assert (z == 0).all()


# ------------------------------------------------------------------ roughconductor vs Mitsuba
@pytest.mark.mitsuba
@pytest.mark.parametrize("case", ROUGH, ids=_rid)
def test_rough_eval_pdf_equal_mitsuba(case):
    mi = mitsuba()
    p = _spec("roughconductor", **case)
    alpha = max(p["alpha"] if p.get("alpha_u") is None else max(p["alpha_u"], p["alpha_v"]), 1e-3)
    wi, wo = _pairs(10_000, alpha)
    rec = _record("roughconductor", p)
    dwi, dwo = to_drpt(wi, Array3f), to_drpt(wo, Array3f)
    f_d, p_d = np.array(rc.eval(rec, dwi, dwo)), np.array(rc.pdf(rec, dwi, dwo))
    b = _mi_bsdf(mi, "roughconductor", p)
    ctx, si = mi.BSDFContext(), _mi_si(mi, wi)
    f_m = np.array(b.eval(ctx, si, to_mitsuba_vec3(wo)))
    p_m = np.array(b.pdf(ctx, si, to_mitsuba_vec3(wo)))
    ok = np.isfinite(f_m).all(axis=0)
    assert ok.mean() > 0.999
    assert (f_m[:, ok] > 0).any(axis=0).mean() > 0.3  # the test sees the lobe
    scale = np.max(f_m[:, ok])
    _close(f_d[:, ok], f_m[:, ok], 2e-4, 1e-6 * scale, "eval")
    _close(p_d, p_m, 2e-4, 1e-6 * np.max(p_m), "pdf")
    for a in (f_d, p_d):
        assert np.isfinite(a).all() and (a >= 0).all()
    below = (wi[2] <= 0) | (wo[2] <= 0)
    assert (f_d[:, below] == 0).all() and (p_d[below] == 0).all()


@pytest.mark.mitsuba
@pytest.mark.parametrize("case", ROUGH, ids=_rid)
def test_rough_sample_equals_mitsuba(case):
    """Same u -> the same wo, weight and pdf as Mitsuba's sample (where its normals are exact)."""
    mi = mitsuba()
    p = _spec("roughconductor", **case)
    n = 10_000
    wi, _ = _pairs(n, 0.1, seed=7)
    wi[2] = np.maximum(wi[2], 0.05)  # away from the pole's and horizon's float32 trouble
    wi /= np.linalg.norm(wi, axis=0)
    sin2 = wi[0] ** 2 + wi[1] ** 2
    wi = wi[:, sin2 > 1e-2]
    u = np.random.default_rng(8).random((2, wi.shape[1])).astype(np.float32)
    bs = rc.sample(_record("roughconductor", p), to_drpt(wi, Array3f), Float(0.5), to_drpt(u, Array2f))
    b = _mi_bsdf(mi, "roughconductor", p)
    mbs, mw = b.sample(mi.BSDFContext(), _mi_si(mi, wi), mi.Float(0.5), mi.Point2f(u[0], u[1]))
    v_d = np.array(bs.valid)
    v_m = (np.array(mbs.pdf) > 0) & (np.array(mw) > 0).any(axis=0) & (np.array(mbs.wo)[2] > 0)
    both = v_d & v_m
    assert (v_d != v_m).mean() < 2e-3 and both.mean() > 0.3
    wo_d, wo_m = np.array(bs.wo)[:, both], np.array(mbs.wo)[:, both]
    err = np.linalg.norm(wo_d - wo_m, axis=0)
    if (p.get("alpha") or 1.0) < 0.01 and p["sample_visible"]:
        # At alpha 1e-3 the stretched wi is within 1e-3 rad of the pole, where
        # Mitsuba's azimuth (sin^2 = 1 - cos^2 in float32, forced to 0 below
        # 4 eps) is inexact: a few % of its normals are rotated about the
        # normal within the (nearly isotropic) lobe. Bound that by the lobe width.
        assert np.quantile(err, 0.9) < 1e-6 and err.max() < 10.0 * p["alpha"]
    else:
        assert np.quantile(err, 0.99) < 2e-4
    close = err < 1e-5
    assert close.mean() > 0.9
    w_m = np.array(mw)[:, both][:, close]
    _close(np.array(bs.weight)[:, both][:, close], w_m, 1e-3, 1e-3 * w_m.max(), "weight")
    _close(np.array(bs.pdf)[both][close], np.array(mbs.pdf)[both][close], 1e-2, 1e-6, "pdf")


# ------------------------------------------------------------------ weight, furnace, extremes
@pytest.mark.parametrize("case", ROUGH, ids=_rid)
def test_weight_is_eval_over_pdf(case):
    p = _spec("roughconductor", **case)
    rec = _record("roughconductor", p)
    n = 20_000
    rng = np.random.default_rng(4)
    for theta in (0.0, 45.0, 80.0, 89.0):
        wi = _dirs(theta, n, 30.0)
        bs = rc.sample(rec, wi, Float(0.5), to_drpt(rng.random((2, n)), Array2f))
        v = np.array(bs.valid)
        f, pd = np.array(rc.eval(rec, wi, bs.wo)), np.array(rc.pdf(rec, wi, bs.wo))
        w = np.array(bs.weight)
        assert np.isfinite(w).all() and (w >= 0).all() and np.isfinite(np.array(bs.pdf)).all()
        assert (w[:, ~v] == 0).all()
        ok = v & (pd > 1e-6 * pd.max())
        _close(w[:, ok], (f / np.where(pd > 0, pd, 1.0))[:, ok], 2e-3, 1e-6, f"weight {theta}")
        # sample's pdf is at the sampled normal m, pdf() at h = normalize(wi + wo(m)):
        # at alpha 1e-3 D is so sharp that h's float32 rounding moves it ~0.3 %.
        sharp = (p.get("alpha") or 1.0) < 0.01
        _close(np.array(bs.pdf)[ok], pd[ok], 2e-2 if sharp else 2e-3, 0.0, f"pdf {theta}")
        assert np.median(np.abs(np.array(bs.pdf)[ok] / pd[ok] - 1.0)) < (2e-3 if sharp else 1e-4)


def _albedo(p, theta, n=400_000, seed=0):
    rec = _record("roughconductor", p)
    u = np.random.default_rng(seed).random((2, n))
    bs = rc.sample(rec, _dirs(theta, n, 30.0), Float(0.5), to_drpt(u, Array2f))
    w = np.array(bs.weight, np.float64)
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n)


def _albedo_mitsuba(p, theta, n=400_000, seed=2):
    mi = mitsuba()
    u = np.random.default_rng(seed).random((2, n)).astype(np.float32)
    wi = np.repeat(_dir_np(theta, 30.0)[:, None], n, axis=1).astype(np.float32)
    _, w = _mi_bsdf(mi, "roughconductor", p).sample(mi.BSDFContext(), _mi_si(mi, wi), mi.Float(0.5),
                                                     mi.Point2f(u[0], u[1]))
    w = np.nan_to_num(np.array(w, np.float64))
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n)


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0, 89.0])
@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
def test_furnace(dist, theta):
    # material none, white: albedo = the microfacet model's own energy, <= 1
    for alpha in (1e-3, 0.1, 0.5, 1.0):
        a_vis, e_vis = _albedo(_spec("roughconductor", distribution=dist, alpha=alpha), theta)
        a_all, e_all = _albedo(_spec("roughconductor", distribution=dist, alpha=alpha, sample_visible=False),
                               theta, seed=1)
        assert (a_vis <= 1.0 + 1e-6).all() and (a_all <= 1.0 + 4 * e_all + 1e-3).all(), (alpha, a_vis, a_all)
        # both samplers estimate the same integral
        assert (np.abs(a_vis - a_all) < 5 * np.hypot(e_vis, e_all) + 2e-3).all(), (alpha, a_vis, a_all)
        # energy goes missing only through G1(wo) and reflections below the horizon
        if alpha <= 0.1 and theta <= 45.0:
            assert (a_vis > 0.98).all(), (alpha, a_vis)
        if alpha == 1e-3 and theta <= 80.0:
            assert (a_vis > 0.995).all(), (alpha, a_vis)
        if alpha in (0.1, 0.5):  # and equals Mitsuba's own estimate
            a_mi, e_mi = _albedo_mitsuba(_spec("roughconductor", distribution=dist, alpha=alpha), theta)
            assert (np.abs(a_vis - a_mi) < 5 * np.hypot(e_vis, e_mi) + 1e-3).all(), (alpha, a_vis, a_mi)
    # a real metal reflects less than the perfect one, and no more than 1
    a_au, _ = _albedo(_spec("roughconductor", material="Au", distribution=dist, alpha=0.3), theta)
    a_none, _ = _albedo(_spec("roughconductor", distribution=dist, alpha=0.3), theta)
    assert (a_au <= a_none + 1e-6).all() and a_au[2] < 0.6 * a_au[0]


def test_extremes_finite():
    """alpha 0 .. 1 (anisotropic too), eta 1 .. 4, k 0 .. 10, cos(wi) 1 .. 1e-6, every
    combination in one wide launch per traced variant (distribution, sampler, anisotropy)."""
    alphas = [(0.0, 0.0), (1e-4, 1e-4), (1e-3, 1e-3), (1.0, 1.0), (1e-4, 1.0), (1.0, 1e-4)]
    iors = [(1.0, 0.0), (4.0, 0.0), (1.0, 1e-3), (0.0, 10.0), (4.0, 10.0), (0.0, 0.0)]
    thetas = [0.0, 60.0, float(np.degrees(np.arccos(1e-6)))]
    combos = np.array([(a[0], a[1], e, k, t) for a in alphas for e, k in iors for t in thetas], np.float64)
    m = 512  # samples per combination
    c = np.repeat(combos, m, axis=0).T
    n = c.shape[1]
    rng = np.random.default_rng(12)
    u = to_drpt(rng.random((2, n)), Array2f)
    wo = _sphere(n, 13)
    wo[2, ::7] = 1e-6
    wo /= np.linalg.norm(wo, axis=0)
    dwo = to_drpt(wo, Array3f)
    t, ph = np.radians(c[4]), np.radians(10.0)
    wi = to_drpt(np.array([np.sin(t) * np.cos(ph), np.sin(t) * np.sin(ph), np.cos(t)]), Array3f)
    eta, k = Array3f(Float(c[2]), Float(c[2]), Float(c[2])), Array3f(Float(c[3]), Float(c[3]), Float(c[3]))
    for beck in (True, False):
        for vis in (True, False):
            for aniso in (False, True):
                rec = rc.RoughConductorParams(Array3f(1.0), eta, k, Float(c[0]), Float(c[1]) if aniso else None,
                                              beck, vis)
                bs = rc.sample(rec, wi, Float(0.5), u)
                outs = [rc.eval(rec, wi, dwo), rc.pdf(rec, wi, dwo), bs.weight, bs.pdf,
                        rc.eval(rec, wi, bs.wo), rc.pdf(rec, wi, bs.wo)]
                dr.eval(*outs, bs.wo)
                for a in outs + [bs.wo]:
                    a = np.array(a)
                    bad = ~np.isfinite(a) if a.ndim == 1 else ~np.isfinite(a).all(axis=0)
                    assert not bad.any(), (beck, vis, aniso, combos[np.unique(np.nonzero(bad)[0] // m)][:3])
                for a in outs[:4]:
                    a = np.array(a)
                    assert (a >= 0).all(), (beck, vis, aniso)
    for e, kk in iors:
        rec = _record("conductor", _spec("conductor", eta=e, k=kk))
        for theta in thetas:
            w = np.array(cd.sample(rec, _dirs(theta, 8), Float(0.5), Array2f(0.5, 0.5)).weight)
            assert np.isfinite(w).all() and (w >= 0).all()


# ------------------------------------------------------------------ chi-square
ROT = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # normal -> +y (peaks on the equator)


def _chi2(sample_func, pdf_func, res=121, ires=8, sample_count=200_000):
    mitsuba()

    return spherical_chi2(sample_func, pdf_func, sample_dim=2, sample_count=sample_count, res=res, ires=ires)


def _funcs(rec, theta, pdf_rec=None):
    mi = mitsuba()
    pdf_rec = pdf_rec or rec

    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        bs = rc.sample(rec, _dirs(theta, a.shape[1], 30.0), Float(0.5), Array2f(a[0], a[1]))
        return (to_mitsuba_vec3(ROT @ np.array(bs.wo, dtype=np.float64)),
                mi.Float(np.array(bs.valid).astype(np.float32)))

    def pdf_func(w):
        v = to_drpt(ROT.T @ np.array(w, dtype=np.float64), Array3f)
        return to_mitsuba_float(np.array(rc.pdf(pdf_rec, _dirs(theta, dr.width(v), 30.0), v)))

    return sample_func, pdf_func


def _cid(c):
    return f"{c['distribution']}-{c.get('alpha', (c.get('alpha_u'), c.get('alpha_v')))}"


CHI2 = [dict(distribution=d, **a) for d in ("beckmann", "ggx")
        for a in (dict(alpha=0.1), dict(alpha=0.5), dict(alpha_u=0.1, alpha_v=0.4))]


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0, 89.0])
@pytest.mark.parametrize("case", CHI2, ids=_cid)
def test_chi2_visible(case, theta):
    ok, msg = _chi2(*_funcs(_record("roughconductor", _spec("roughconductor", material="Cu", **case)), theta))
    assert ok, msg


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", [0.0, 60.0, 85.0])
@pytest.mark.parametrize("case", CHI2, ids=_cid)
def test_chi2_all_normals(case, theta):
    p = _spec("roughconductor", material="Au", sample_visible=False, **case)
    ok, msg = _chi2(*_funcs(_record("roughconductor", p), theta))
    assert ok, msg


# ------------------------------------------------------------------ negative controls
@pytest.mark.mitsuba
def test_negative_control_equality():
    """The equality test's tolerance catches a 10 % alpha error."""
    mi = mitsuba()
    p = _spec("roughconductor", material="Au", distribution="ggx", alpha=0.1)
    wrong = _spec("roughconductor", material="Au", distribution="ggx", alpha=0.11)
    wi, wo = _pairs(10_000, 0.1)
    b = _mi_bsdf(mi, "roughconductor", p)
    f_m = np.array(b.eval(mi.BSDFContext(), _mi_si(mi, wi), to_mitsuba_vec3(wo)))
    f_d = np.array(rc.eval(_record("roughconductor", wrong), to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    with pytest.raises(AssertionError):
        _close(f_d, f_m, 2e-4, 1e-6 * np.max(f_m), "eval")


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
def test_negative_control_chi2(dist):
    p = _spec("roughconductor", distribution=dist, alpha=0.1)
    wrong = _spec("roughconductor", distribution=dist, alpha=0.11)
    ok, _ = _chi2(*_funcs(_record("roughconductor", p), 45.0, pdf_rec=_record("roughconductor", wrong)))
    assert not ok


# ------------------------------------------------------------------ params() and trace-time choices
class _Table:
    """Stand-in for the material table: one row per spec, ``value`` gathers by ``si.material``."""

    def __init__(self, kind, specs):
        self.kind, self.mod = kind, lobe(kind)
        self.specs = [SimpleNamespace(kind=kind, params=_spec(kind, **s)) for s in specs]
        self.vals = [dict(s.params, **self.mod.derive(dict(s.params))) for s in self.specs]

    def specs_of(self, kind):
        return self.specs if kind == self.kind else []

    def value(self, name, si, active):
        t = self.mod.FIELDS[name]
        w = 3 if t == "rgb" else 1
        arr = np.array([np.broadcast_to(np.asarray(v[name], float), (w,)) for v in self.vals], np.float32)
        if w == 3:
            return dr.gather(Array3f, Array3f(*(Float(arr[:, i]) for i in range(3))), si.material, active)
        return dr.gather(Float, Float(arr[:, 0]), si.material, active)


MIXED = [dict(material="Au", distribution="beckmann", alpha=0.2),
         dict(material="Cu", distribution="ggx", alpha_u=0.05, alpha_v=0.3),
         dict(distribution="ggx", alpha=0.4, sample_visible=False),
         dict(eta=1.5, k=2.0, distribution="beckmann", alpha_u=0.3, alpha_v=0.1, sample_visible=False)]


@pytest.mark.parametrize("subset", [[0], [0, 1], [0, 1, 2, 3], [2, 3]], ids=str)
def test_params_per_lane_equals_single(subset):
    specs = [MIXED[i] for i in subset]
    table = _Table("roughconductor", specs)
    n = 4000
    mat = np.arange(n) % len(specs)
    si = SimpleNamespace(material=UInt32(mat.astype(np.uint32)))
    rec = rc.params(table, si, dr.full(dr.auto.Bool, True, n))
    if len(subset) == 1:
        assert rec.beckmann is True and rec.visible is True and rec.alpha_v is None
    wi, wo = _pairs(n, 0.2, seed=21)
    u = np.random.default_rng(22).random((2, n))
    dwi, dwo, du = to_drpt(wi, Array3f), to_drpt(wo, Array3f), to_drpt(u, Array2f)
    f, pd = np.array(rc.eval(rec, dwi, dwo)), np.array(rc.pdf(rec, dwi, dwo))
    bs = rc.sample(rec, dwi, Float(0.5), du)
    for j, s in enumerate(specs):
        one = _record("roughconductor", _spec("roughconductor", **s))
        sel = mat == j
        _close(f[:, sel], np.array(rc.eval(one, dwi, dwo))[:, sel], 1e-5, 1e-7, "eval")
        _close(pd[sel], np.array(rc.pdf(one, dwi, dwo))[sel], 1e-5, 1e-7, "pdf")
        b1 = rc.sample(one, dwi, Float(0.5), du)
        _close(np.array(bs.wo)[:, sel], np.array(b1.wo)[:, sel], 1e-5, 1e-6, "wo")
        _close(np.array(bs.weight)[:, sel], np.array(b1.weight)[:, sel], 1e-5, 1e-6, "weight")
    # the conductor lobe's params()
    ct = _Table("conductor", [dict(material="Au"), dict(material="none", specular_reflectance=(0.5, 0.5, 0.5))])
    si2 = SimpleNamespace(material=UInt32(np.array([0, 1], np.uint32)))
    crec = cd.params(ct, si2, dr.full(dr.auto.Bool, True, 2))
    w = np.array(cd.sample(crec, _dirs(0.0, 2), Float(0.5), Array2f(0.5, 0.5)).weight)
    assert np.allclose(w[:, 1], 0.5) and w[0, 0] > w[2, 0]


def test_unit_fresnel_is_an_exact_one():
    """``material="none"`` (eta 0, k 1): fresnel_conductor is exactly 1 at every float32
    cosine, so the lobes skip it (conductor.unit_fresnel, a trace-time choice) and their
    values are the same floats. Negative control: a named metal's or another eta's
    reflectance is not 1, and unit_fresnel says so."""
    cos = np.concatenate([[0.0, 1.0, 1e-6, 1e-30, 0.5, np.nextafter(np.float32(1), np.float32(0))],
                          np.random.default_rng(31).random(100000)]).astype(np.float32)
    one = np.array(cd.fresnel_conductor(Float(cos), Array3f(0.0), Array3f(1.0)))
    assert np.array_equal(one, np.ones_like(one))
    none = [SimpleNamespace(params=_spec("roughconductor", alpha=a)) for a in (0.005, 0.2)]
    assert cd.unit_fresnel(none) and cd.unit_fresnel([SimpleNamespace(params=_spec("conductor", eta=0.0))])
    for other in (dict(material="Au"), dict(eta=0.5), dict(eta=1.5, k=0.5)):
        spec = SimpleNamespace(params=_spec("roughconductor", **other))
        assert not cd.unit_fresnel(none + [spec])
        eta, k = conductors.resolve(spec.params)
        f = np.array(cd.fresnel_conductor(Float(cos[:1000]), Array3f(*eta), Array3f(*k)))
        assert not np.array_equal(f, np.ones_like(f))
    assert not cd.unit_fresnel([])
    # the lobes' values with and without the skip, bit for bit
    n = 4000
    table = _Table("roughconductor", [dict(alpha=0.05), dict(alpha=0.3, distribution="ggx")])
    si = SimpleNamespace(material=UInt32((np.arange(n) % 2).astype(np.uint32)))
    rec = rc.params(table, si, dr.full(dr.auto.Bool, True, n))
    assert rec.unit
    wi, wo = _pairs(n, 0.2, seed=32)
    u = np.random.default_rng(33).random((2, n))
    dwi, dwo, du = to_drpt(wi, Array3f), to_drpt(wo, Array3f), to_drpt(u, Array2f)
    skip = [np.array(rc.eval(rec, dwi, dwo)), np.array(rc.sample(rec, dwi, Float(0.5), du).weight)]
    rec.unit = False
    full = [np.array(rc.eval(rec, dwi, dwo)), np.array(rc.sample(rec, dwi, Float(0.5), du).weight)]
    assert all(np.array_equal(a, b) for a, b in zip(skip, full)) and skip[0].max() > 0
    ct = _Table("conductor", [dict(specular_reflectance=(0.5, 0.25, 1.0))])
    crec = cd.params(ct, SimpleNamespace(material=UInt32(np.zeros(3, np.uint32))), dr.full(dr.auto.Bool, True, 3))
    assert crec.unit
    assert np.array_equal(np.array(cd.sample(crec, _dirs(30.0, 3), Float(0.5), Array2f(0.5, 0.5)).weight)[:, 0],
                          np.float32([0.5, 0.25, 1.0]))
