"""Modified Phong lobe (drpt/render/bsdf/phong.py) and its Mitsuba twin
(drpt/export/mitsuba_phong.py): both samplers match their pdfs (chi-square),
the two agree on eval and pdf, weights are eval/pdf, energy is conserved,
f is reciprocal, extremes stay finite, and Mitsuba renders twosided(drpt_phong)."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.export import mitsuba_phong
from drpt.render.bsdf import phong
from drpt.testing import export_bsdf, mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3

KD = (0.25, 0.3, 0.15)
KS = (0.5, 0.45, 0.6)  # max(kd + ks) = 0.75


def _params(kd=KD, ks=KS, ns=10.0):
    return phong.PhongParams(Array3f(*kd), Array3f(*ks), Float(float(ns)))


def _dir_np(theta_deg):
    t = np.radians(theta_deg)
    return np.array([np.sin(t), 0.0, np.cos(t)])


def _dir(theta_deg):
    return Array3f(*(float(x) for x in _dir_np(theta_deg)))


def _uniform(n, dims, seed):
    return np.random.default_rng(seed).random((dims, n)).astype(np.float32)


def _sphere_dirs(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def _mi_bsdf(mi, kd=KD, ks=KS, ns=10.0):
    mitsuba_phong.register()
    return mi.load_dict({"type": "drpt_phong", "kd": {"type": "rgb", "value": list(kd)},
                         "ks": {"type": "rgb", "value": list(ks)}, "ns": float(ns)})


def _chi2(sample_func, pdf_func, sample_count=200_000, res=61, ires=4):
    """Mitsuba's ChiSquareTest on the sphere; ``sample_func`` returns (wo, weight)
    (weight 0 = failed sample, left out of the histogram)."""
    mitsuba()

    return spherical_chi2(sample_func, pdf_func, sample_dim=3, sample_count=sample_count, res=res, ires=ires)


# ------------------------------------------------------------- chi-square
# Lobe width ~ 1/sqrt(ns): the pdf integration over the 3-degree cells needs
# finer sub-sampling for the sharp lobes.
CHI2_GRID = [(th, ns) for th in (0.0, 30.0, 60.0, 85.0, 89.9) for ns in (1.0, 10.0, 100.0, 1000.0)]


def _ires(ns):
    return 4 if ns <= 10 else (8 if ns <= 100 else 16)


def _tilt(theta):
    """Rotation applied to the sphere in the chi-square test. At normal
    incidence the lobe peaks at the pole of the test's (cos theta, phi) grid,
    where the trapezoid integration of a sharp pdf overestimates its mass
    (PDF sum 1.23 for ns = 1000): tilt by 50 degrees about x there. Elsewhere
    the identity keeps the horizon on a grid line."""
    if theta > 1.0:
        return np.eye(3)
    a = np.radians(50.0)
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


@pytest.mark.mitsuba
@pytest.mark.parametrize("theta,ns", CHI2_GRID)
def test_drpt_sampling_matches_pdf(theta, ns):
    p = _params(ns=ns)
    wi_np = _dir_np(theta)
    rot = _tilt(theta)

    def sample_func(u):
        mi = mitsuba()
        a = np.array(u, dtype=np.float32)
        n = a.shape[1]
        wi = Array3f(*(Float(np.full(n, x, np.float32)) for x in wi_np))
        bs = phong.sample(p, wi, Float(a[0]), Array2f(a[1], a[2]))
        w = np.array(bs.valid).astype(np.float32)
        return to_mitsuba_vec3(rot @ np.array(bs.wo, dtype=np.float64)), mi.Float(w)

    def pdf_func(w):
        wo = to_drpt(rot.T @ np.array(w, dtype=np.float64), Array3f)
        n = dr.width(wo)
        wi = Array3f(*(Float(np.full(n, x, np.float32)) for x in wi_np))
        return to_mitsuba_float(np.array(phong.pdf(p, wi, wo)))

    ok, msg = _chi2(sample_func, pdf_func, ires=_ires(ns))
    assert ok, msg


@pytest.mark.mitsuba
@pytest.mark.parametrize("theta,ns", [(0.0, 1.0), (60.0, 10.0), (85.0, 100.0), (89.9, 1000.0),
                                      (30.0, 1000.0)])
def test_mitsuba_plugin_sampling_matches_pdf(theta, ns):
    mitsuba()
    mitsuba_phong.register()
    from mitsuba.chi2 import BSDFAdapter

    d = {"type": "drpt_phong", "kd": {"type": "rgb", "value": list(KD)},
         "ks": {"type": "rgb", "value": list(KS)}, "ns": ns}
    sample_func, pdf_func = BSDFAdapter("drpt_phong", d, wi=[float(x) for x in _dir_np(theta)])
    ok, msg = _chi2(sample_func, pdf_func, ires=_ires(ns))
    assert ok, msg


# ----------------------------------------------- drpt vs Mitsuba: eval, pdf
@pytest.mark.mitsuba
@pytest.mark.parametrize("ns", [0.0, 1.0, 7.5, 100.0, 1000.0])
@pytest.mark.parametrize("kd,ks", [(KD, KS), ((0.0, 0.0, 0.0), (0.9, 0.7, 0.5)),
                                   ((0.6, 0.5, 0.4), (0.0, 0.0, 0.0))])
def test_eval_pdf_match_mitsuba(ns, kd, ks):
    mi = mitsuba()
    n = 10_000
    wi = _sphere_dirs(n, 1)
    wi[2] = np.abs(wi[2])
    wi[:, :50] = -wi[:, :50]  # some viewers below the surface: both must give 0
    wo = _sphere_dirs(n, 2)
    # Half of the wo near the specular peak, where the lobe matters.
    near = np.array([-wi[0], -wi[1], wi[2]]) + 0.1 * _sphere_dirs(n, 3)
    near /= np.linalg.norm(near, axis=0)
    wo[:, ::2] = near[:, ::2]
    wi, wo = wi.astype(np.float32), wo.astype(np.float32)

    p = _params(kd, ks, ns)
    f_d = np.array(phong.eval(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    p_d = np.array(phong.pdf(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))

    bsdf = _mi_bsdf(mi, kd, ks, ns)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(wi)
    ctx = mi.BSDFContext()
    f_m = np.array(bsdf.eval(ctx, si, to_mitsuba_vec3(wo)))
    p_m = np.array(bsdf.pdf(ctx, si, to_mitsuba_vec3(wo)))
    f_m2, p_m2 = bsdf.eval_pdf(ctx, si, to_mitsuba_vec3(wo))
    assert np.array_equal(np.array(f_m2), f_m) and np.array_equal(np.array(p_m2), p_m)

    # Float64 reference of the formulas, from the float32 inputs.
    w64, o64 = wi.astype(np.float64), wo.astype(np.float64)
    ok = (w64[2] > 0) & (o64[2] > 0)
    c = w64[2] * o64[2] - w64[0] * o64[0] - w64[1] * o64[1]
    cn = np.where(c > 0, np.maximum(c, 1e-300) ** ns, 0.0)
    kd_, ks_ = np.array(kd)[:, None], np.array(ks)[:, None]
    f_ref = np.where(ok, (kd_ / np.pi + ks_ * (ns + 2) / (2 * np.pi) * cn) * o64[2], 0.0)
    lum = np.array([0.2126, 0.7152, 0.0722])
    tot = float(lum @ np.array(kd) + lum @ np.array(ks))
    p_s = float(lum @ np.array(ks)) / tot if tot > 0 else 0.0
    p_ref = np.where(ok, p_s * (ns + 1) / (2 * np.pi) * cn + (1 - p_s) * o64[2] / np.pi, 0.0)

    # 1e-4 relative; cos^n turns a 1-ulp difference in cos(alpha) into ns ulps,
    # so the tolerance grows as 2 ns eps32 beyond ns = 400. The floor covers
    # values far down the lobe, 1e-6 of the peak.
    rtol = max(1e-4, 2 * ns * 2.0**-23)
    for a, b, ref in ((f_d, f_m, f_ref), (p_d, p_m, p_ref)):
        assert np.all(np.isfinite(a)) and np.all(a >= 0)
        floor = 1e-6 * max(float(ref.max()), 1e-30)
        for x, y in ((a, b), (a, ref), (b, ref)):
            assert np.allclose(x, y, rtol=rtol, atol=floor), \
                np.max(np.abs(x - y) / (np.abs(y) + floor))
    assert np.all(f_d[:, :50] == 0) and np.all(p_d[:50] == 0)
    assert (p_d > 0).sum() > n // 3


@pytest.mark.mitsuba
def test_mitsuba_plugin_weight_and_contexts():
    mi = mitsuba()
    bsdf = _mi_bsdf(mi, ns=20.0)
    n = 20_000
    u = _uniform(n, 3, 5)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(np.repeat(_dir_np(40.0)[:, None], n, axis=1))
    ctx = mi.BSDFContext()
    bs, w = bsdf.sample(ctx, si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    f, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    w, f, pdf, bpdf = np.array(w), np.array(f), np.array(pdf), np.array(bs.pdf)
    ok = bpdf > 0
    assert np.all(np.isfinite(w)) and np.all(w >= 0)
    assert np.allclose(bpdf, pdf, rtol=1e-6)
    assert np.allclose(w[:, ok], f[:, ok] / pdf[ok], rtol=1e-5)
    assert np.all(w[:, ~ok] == 0)
    comp = np.array(bs.sampled_component)
    assert set(np.unique(comp)) == {0, 1}
    # Component 1 alone (diffuse): Lambert eval, cosine pdf.
    ctx_d = mi.BSDFContext()
    ctx_d.component = 1
    ctx_d.type_mask = mi.BSDFFlags.DiffuseReflection
    wo_np = _sphere_dirs(1000, 9)
    wo_np[2] = np.abs(wo_np[2])
    wo = to_mitsuba_vec3(wo_np)
    si1 = dr.zeros(mi.SurfaceInteraction3f, 1000)
    si1.wi = to_mitsuba_vec3(np.repeat(_dir_np(40.0)[:, None], 1000, axis=1))
    fd, pd = bsdf.eval_pdf(ctx_d, si1, wo)
    cz = np.array(wo.z)
    assert np.allclose(np.array(fd), np.array(KD)[:, None] * cz / np.pi, rtol=1e-5)
    assert np.allclose(np.array(pd), cz / np.pi, rtol=1e-5)


# ------------------------------------------------ weights, furnace, symmetry
@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0])
@pytest.mark.parametrize("ns", [1.0, 30.0])
def test_weight_is_eval_over_mixture_pdf(theta, ns):
    n = 50_000
    u = _uniform(n, 3, 11)
    p = _params(ns=ns)
    wi = _dir(theta)
    bs = phong.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    f = np.array(phong.eval(p, wi, bs.wo))
    pdf = np.array(phong.pdf(p, wi, bs.wo))
    w, bpdf, valid = np.array(bs.weight), np.array(bs.pdf), np.array(bs.valid)
    assert np.array_equal(bpdf, np.where(valid, pdf, 0))  # the full mixture pdf
    assert np.allclose(w[:, valid], f[:, valid] / pdf[valid], rtol=1e-6)
    assert np.all(w[:, ~valid] == 0) and np.all(np.array(bs.wo.z)[~valid] <= 0)
    assert not np.any(np.array(bs.delta)) and np.all(np.array(bs.eta) == 1)


def _albedo(p, theta, n=400_000, seed=7):
    u = _uniform(n, 3, seed)
    bs = phong.sample(p, _dir(theta), Float(u[0]), Array2f(u[1], u[2]))
    w = np.array(bs.weight, dtype=np.float64)
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n)


@pytest.mark.parametrize("kd,ks", [((0.4, 0.2, 0.0), (0.6, 0.8, 1.0)), ((0.0,) * 3, (1.0,) * 3)])
@pytest.mark.parametrize("ns", [0.0, 1.0, 10.0, 1000.0])
def test_furnace_albedo_at_most_one(kd, ks, ns):
    p = _params(kd, ks, ns)
    for theta in (0.0, 30.0, 60.0, 85.0, 89.9):
        mean, err = _albedo(p, theta)
        assert np.all(mean <= 1.0 + 4 * err + 1e-6), (theta, mean, err)
    if kd == (0.0,) * 3:
        # At normal incidence the normalized lobe reflects exactly ks.
        mean, err = _albedo(p, 0.0)
        assert np.allclose(mean, 1.0, atol=4 * err.max() + 1e-4), (mean, err)


@pytest.mark.parametrize("theta", [0.0, 60.0, 89.9])
def test_furnace_diffuse_only_is_kd(theta):
    kd = (0.8, 0.5, 0.25)
    mean, _ = _albedo(_params(kd, (0.0,) * 3, 50.0), theta, n=50_000)
    assert np.allclose(mean, kd, rtol=1e-5)


@pytest.mark.parametrize("ns", [0.0, 3.0, 200.0])
def test_reciprocity(ns):
    n = 10_000
    wi = _sphere_dirs(n, 21)
    wo = _sphere_dirs(n, 22)
    wi[2], wo[2] = np.abs(wi[2]), np.abs(wo[2])
    near = np.array([-wi[0], -wi[1], wi[2]]) + 0.05 * _sphere_dirs(n, 23)
    near /= np.linalg.norm(near, axis=0)
    wo[:, ::2] = near[:, ::2]
    wo[2] = np.abs(wo[2])
    wi, wo = wi.astype(np.float32), wo.astype(np.float32)
    p = _params(ns=ns)
    a = np.array(phong.eval(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    b = np.array(phong.eval(p, to_drpt(wo, Array3f), to_drpt(wi, Array3f)))
    ok = (wi[2] > 0) & (wo[2] > 0)
    fa, fb = a[:, ok] / wo[2, ok], b[:, ok] / wi[2, ok]
    assert np.allclose(fa, fb, rtol=1e-5)


# ---------------------------------------------------------------- extremes
EXTREME_DIRS = {
    "normal": (0.0, 0.0, 1.0),
    "grazing": (float(np.sqrt(1 - 1e-12)), 0.0, 1e-6),
    "oblique": tuple(float(x) for x in _dir_np(70.0)),
}


@pytest.mark.parametrize("ns", [0.0, 1.0, 1e4, 1e6])
@pytest.mark.parametrize("kd,ks", [(KD, KS), ((0.0,) * 3, (1.0,) * 3), ((1.0,) * 3, (0.0,) * 3),
                                   ((0.0,) * 3, (0.0,) * 3)])
@pytest.mark.parametrize("which", list(EXTREME_DIRS))
def test_extremes_finite(ns, kd, ks, which):
    n = 20_000
    p = _params(kd, ks, ns)
    wi = Array3f(*EXTREME_DIRS[which])
    u = _uniform(n, 3, 31)
    u[:, :4] = [[0, 0, 1 - 2**-24, 0.5], [0, 1 - 2**-24, 0, 0.5], [0, 1 - 2**-24, 1 - 2**-24, 0]]
    bs = phong.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    w, pdf, valid = np.array(bs.weight), np.array(bs.pdf), np.array(bs.valid)
    wo = np.array(bs.wo)
    for a in (w, pdf, wo):
        assert np.all(np.isfinite(a))
    assert np.all(w >= 0) and np.all(pdf >= 0)
    assert np.allclose(np.linalg.norm(wo, axis=0), 1.0, atol=1e-5)
    f = np.array(phong.eval(p, wi, bs.wo))
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    ok = valid & (pdf > 0)
    assert np.allclose(w[:, ok], f[:, ok] / pdf[ok], rtol=1e-5, atol=1e-30)
    assert np.all(w[:, ~valid] == 0)
    # eval/pdf of arbitrary pairs, including the grazing wo and the mirror direction
    wos = np.concatenate([_sphere_dirs(1000, 41),
                          np.array([[EXTREME_DIRS["grazing"][0], 0, 1e-6],
                                    [-EXTREME_DIRS[which][0], 0, EXTREME_DIRS[which][2]],
                                    [0, 0, 1], [0, 0, -1]]).T], axis=1).astype(np.float32)
    m = wos.shape[1]
    wi_m = Array3f(*(Float(np.full(m, x, np.float32)) for x in EXTREME_DIRS[which]))
    fe = np.array(phong.eval(p, wi_m, to_drpt(wos, Array3f)))
    pe = np.array(phong.pdf(p, wi_m, to_drpt(wos, Array3f)))
    assert np.all(np.isfinite(fe)) and np.all(fe >= 0)
    assert np.all(np.isfinite(pe)) and np.all(pe >= 0)
    if kd == (0.0,) * 3 and ks == (0.0,) * 3:
        assert np.all(w == 0) and np.all(fe == 0)


def test_ks_zero_is_lambert_exactly():
    from drpt.render.bsdf import diffuse

    kd = Array3f(0.7, 0.5, 0.2)
    p = phong.PhongParams(kd, Array3f(0.0), Float(42.0))
    n = 10_000
    u = _uniform(n, 3, 51)
    wi = dr.normalize(Array3f(0.3, -0.2, 0.9))
    bs = phong.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    dp = diffuse.DiffuseParams(kd)
    ref = diffuse.sample(dp, wi, Float(u[0]), Array2f(u[1], u[2]))
    assert np.array_equal(np.array(bs.wo), np.array(ref.wo))
    assert np.array_equal(np.array(bs.valid), np.array(ref.valid))
    assert np.allclose(np.array(bs.weight), np.array(ref.weight), rtol=1e-6)
    assert np.array_equal(np.array(bs.pdf), np.array(ref.pdf))
    wo = to_drpt(_sphere_dirs(n, 52).astype(np.float32), Array3f)
    assert np.array_equal(np.array(phong.eval(p, wi, wo)), np.array(diffuse.eval(dp, wi, wo)))
    assert np.array_equal(np.array(phong.pdf(p, wi, wo)), np.array(diffuse.pdf(dp, wi, wo)))


def test_below_surface_is_zero():
    p = _params()
    wi = Array3f(0.0, 0.6, -0.8)
    wo = Array3f(0.0, -0.6, 0.8)
    assert np.all(np.array(phong.eval(p, wi, wo)) == 0) and np.array(phong.pdf(p, wi, wo))[0] == 0
    bs = phong.sample(p, wi, Float(0.3), Array2f(0.3, 0.7))
    assert not bool(bs.valid[0]) and np.all(np.array(bs.weight) == 0) and bs.pdf[0] == 0


def test_params_gather_per_lane():
    # PhongParams is a Dr.Jit struct: the material layer can gather it per lane.
    table = phong.PhongParams(Array3f([0.1, 0.2], [0.1, 0.2], [0.1, 0.2]), Array3f(0.5, 0.4, 0.3),
                              Float([5.0, 50.0]))
    g = dr.gather(phong.PhongParams, table, dr.llvm.UInt32([1, 0, 1]))
    assert np.allclose(np.array(g.ns), [50, 5, 50])
    assert np.allclose(np.array(g.kd)[0], [0.2, 0.1, 0.2])


# ------------------------------------------------------- Mitsuba: plugin
@pytest.mark.mitsuba
@pytest.mark.parametrize("ns", [0.0, 1.0, 1e4, 1e6])
@pytest.mark.parametrize("kd,ks", [(KD, KS), ((0.0,) * 3, (1.0,) * 3), ((1.0,) * 3, (0.0,) * 3)])
def test_mitsuba_plugin_extremes_finite(ns, kd, ks):
    mi = mitsuba()
    bsdf = _mi_bsdf(mi, kd, ks, ns)
    ctx = mi.BSDFContext()
    n = 20_000
    u = _uniform(n, 3, 71)
    u[:, :3] = [[0, 0, 0.5], [0, 1 - 2**-24, 0.5], [0, 1 - 2**-24, 0]]
    for wi in EXTREME_DIRS.values():
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f(*wi)
        bs, w = bsdf.sample(ctx, si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
        f, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
        for a in (np.array(w), np.array(bs.pdf), np.array(bs.wo), np.array(f), np.array(pdf)):
            assert np.all(np.isfinite(a))
        assert np.all(np.array(w) >= 0) and np.all(np.array(bs.pdf) >= 0)
    kd_diffuse = bsdf.eval_diffuse_reflectance(dr.zeros(mi.SurfaceInteraction3f, 1))
    assert np.allclose(np.array(kd_diffuse)[:, 0], kd)


@pytest.mark.mitsuba
@pytest.mark.parametrize("ns", [2.0, 1e3, 1e6])
def test_same_random_numbers_same_directions(ns):
    # Same lobe choice and the same warps (concentric cosine map, Duff frame):
    # with equal random numbers both samplers give the same directions and
    # weights. Not part of the spec (chi-square and eval/pdf are), a drift alarm.
    mi = mitsuba()
    bsdf = _mi_bsdf(mi, ns=ns)
    n = 50_000
    u = _uniform(n, 3, 81)
    wi = _dir_np(50.0)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*(float(x) for x in wi))
    bs_m, w_m = bsdf.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    bs_d = phong.sample(_params(ns=ns), _dir(50.0), Float(u[0]), Array2f(u[1], u[2]))
    assert np.allclose(np.array(bs_m.wo), np.array(bs_d.wo), atol=2e-5)
    both = np.array(bs_d.valid) & (np.array(bs_m.pdf) > 0)
    assert both.mean() > 0.6
    if ns <= 1e3:  # beyond, cos^n turns 1e-7 of direction into percents of weight
        assert np.allclose(np.array(w_m)[:, both], np.array(bs_d.weight)[:, both], rtol=1e-3)


@pytest.mark.mitsuba
def test_register_idempotent_and_to_mitsuba():
    mi = mitsuba()
    mitsuba_phong.register()
    mitsuba_phong.register()
    d = export_bsdf("phong", True, kd=(0.3, 0.2, 0.1), ks=(0.5, 0.5, 0.5), ns=25.0)
    assert d["type"] == "twosided" and d["bsdf_0"]["type"] == "drpt_phong"
    assert d["bsdf_0"]["ns"] == 25.0
    bsdf = mi.load_dict(d)
    assert bsdf.flags() & int(mi.BSDFFlags.BackSide)  # twosided made it two-sided


@pytest.mark.mitsuba
def test_twosided_python_bsdf_mirrors_back_side():
    mi = mitsuba()
    mitsuba_phong.register()
    two = mi.load_dict(export_bsdf("phong", True, kd=KD, ks=KS, ns=15.0))
    one = _mi_bsdf(mi, KD, KS, 15.0)
    n = 5000
    wi = _sphere_dirs(n, 61).astype(np.float32)
    wi[2] = np.abs(wi[2])
    wo = _sphere_dirs(n, 62).astype(np.float32)
    wo[2] = np.abs(wo[2])
    ctx = mi.BSDFContext()
    flip = np.array([[1], [1], [-1]], np.float32)
    si_f = dr.zeros(mi.SurfaceInteraction3f, n)
    si_f.wi = to_mitsuba_vec3(wi)
    si_b = dr.zeros(mi.SurfaceInteraction3f, n)
    si_b.wi = to_mitsuba_vec3(wi * flip)
    f1, p1 = one.eval_pdf(ctx, si_f, to_mitsuba_vec3(wo))
    fb, pb = two.eval_pdf(ctx, si_b, to_mitsuba_vec3(wo * flip))
    assert np.allclose(np.array(fb), np.array(f1), rtol=1e-6)
    assert np.allclose(np.array(pb), np.array(p1), rtol=1e-6)
    u = _uniform(n, 3, 63)
    bs1, w1 = one.sample(ctx, si_f, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    bsb, wb = two.sample(ctx, si_b, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    assert np.allclose(np.array(bsb.wo), np.array(bs1.wo) * flip, atol=1e-6)
    assert np.allclose(np.array(wb), np.array(w1), rtol=1e-6)


def _sphere_scene(mi, material, spp=16, res=24):
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": {"type": "perspective", "fov": 30.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
        "ball": {"type": "sphere", "radius": 1.0, "bsdf": material},
        "quad": {"type": "rectangle", "bsdf": material,
                 "to_world": mi.ScalarTransform4f().translate([0, -1.5, 0]).rotate([1, 0, 0], -90)
                 @ mi.ScalarTransform4f().scale(0.7)},
    }


@pytest.mark.mitsuba
def test_mitsuba_render_twosided_phong():
    mi = mitsuba()
    mitsuba_phong.register()
    # ks = 0: a convex object in a white furnace reflects exactly kd.
    lam = export_bsdf("phong", True, kd=(0.5, 0.5, 0.5), ks=(0.0,) * 3, ns=10)
    ref = {"type": "twosided", "material": {"type": "diffuse",
                                             "reflectance": {"type": "rgb", "value": 0.5}}}
    img = np.array(mi.render(mi.load_dict(_sphere_scene(mi, lam)), seed=1))
    img_ref = np.array(mi.render(mi.load_dict(_sphere_scene(mi, ref)), seed=1))
    assert np.all(np.isfinite(img))
    # Same random numbers, same lobe choice: Mitsuba's own diffuse, sample for sample
    # (the quad is seen from both sides, so twosided is exercised).
    assert np.allclose(img, img_ref, rtol=1e-5, atol=1e-6)
    # The sphere in a white furnace reflects kd = 0.5 (NEE + MIS: noisy, unbiased).
    scene = mi.load_dict({k: v for k, v in _sphere_scene(mi, lam, spp=64).items() if k != "quad"})
    img = np.array(mi.render(scene, seed=3))[..., 0]
    # Pixels well inside the sphere's silhouette (it spans 0.76 of the half-width).
    x = (np.arange(img.shape[0]) + 0.5) / img.shape[0] * 2 - 1
    ball = (x[:, None] ** 2 + x[None, :] ** 2) < 0.6**2
    assert ball.sum() > 100 and abs(img[ball].mean() - 0.5) < 0.01, img[ball].mean()
    # Glossy, energy conserving: finite, nothing brighter than the environment
    # (up to the variance of 16 spp).
    shiny = export_bsdf("phong", True, kd=(0.2, 0.3, 0.1), ks=(0.7, 0.6, 0.8),
                        ns=50)
    img = np.array(mi.render(mi.load_dict(_sphere_scene(mi, shiny)), seed=2))
    assert np.all(np.isfinite(img)) and np.all(img >= 0)
    assert 0.3 < img.mean() <= 1.0 + 1e-3
