"""Cook-Torrance lobe (drpt/render/bsdf/cook_torrance.py, its GGX the
``Distribution`` of microfacet.py) and its Mitsuba export (twosided(principled)):

* the VNDF sampler and the full sampler match their pdfs (chi-square);
* eval AND pdf equal Mitsuba 3's own ``principled`` eval/pdf (rel. 1e-4;
  measured ~1e-6) -- the lobe is principled's metallic/roughness subset;
* directional albedo equals principled's (sampled by Mitsuba), is <= 1 for
  metals, -> base color for smooth metals; principled's dielectric part is
  NOT energy conserving (documented, pinned here);
* weight == eval/pdf, reciprocity, finiteness at the extremes, bounded
  weights for the seed's hard case.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float, UInt32

from drpt.render.bsdf import cook_torrance as ct
from drpt.render.bsdf import microfacet as mf
from drpt.testing import export_bsdf, mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3

BASE = (0.8, 0.6, 0.4)
HARD = ((0.9, 0.75, 0.3), 0.9, 0.9)  # the seed's hard case: base, metalness, alpha


def _params(base=BASE, alpha=0.3, metal=0.5):
    return ct.CookTorranceParams(Array3f(*base), Float(float(alpha)), Float(float(metal)))


def _dir_np(theta_deg):
    t = np.radians(theta_deg)
    return np.array([np.sin(t), 0.0, np.cos(t)])


def _dir(theta_deg, n=1):
    return Array3f(*(Float(np.full(n, x, np.float32)) for x in _dir_np(theta_deg)))


def _uniform(n, dims, seed):
    return np.random.default_rng(seed).random((dims, n)).astype(np.float32)


def _sphere_dirs(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


# ------------------------------------------------------------- chi-square
# The test bins directions on a (phi, cos theta) grid. ROT maps the normal to
# +y: the horizon (where the pdf jumps to 0) becomes the grid lines phi = 0, pi,
# and the specular peaks (and the visible normals) lie on the equator, where
# the cells are smallest -- never at a pole, where cells are huge in theta.
ROT = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
# Sharper lobes need finer cells and sub-sampling of the pdf integration.
RES = {0.01: (241, 16), 0.1: (121, 8), 0.5: (61, 4), 1.0: (61, 4)}
ANGLES = (0.0, 45.0, 80.0, 89.0)
ALPHAS = (0.01, 0.1, 0.5, 1.0)


def _chi2(sample_func, pdf_func, dim, res, ires, sample_count=200_000):
    mitsuba()

    return spherical_chi2(sample_func, pdf_func, sample_dim=dim, sample_count=sample_count, res=res, ires=ires)


@pytest.mark.mitsuba
@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("theta", ANGLES)
def test_vndf_sampling_matches_pdf(theta, alpha):
    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        m = mf.Distribution(False, alpha).sample_visible_normal(_dir(theta, a.shape[1]), Array2f(a[0], a[1]))
        return to_mitsuba_vec3(ROT @ np.array(m, dtype=np.float64))

    def pdf_func(w):
        m = to_drpt(ROT.T @ np.array(w, dtype=np.float64), Array3f)
        return to_mitsuba_float(np.array(mf.Distribution(False, alpha).pdf_visible(_dir(theta, dr.width(m)), m)))

    ok, msg = _chi2(sample_func, pdf_func, 2, *RES[alpha])
    assert ok, msg


def _lobe_sampler(p, theta, half_vector=False):
    """(sample_func, pdf_func) of the full lobe, over wo or over h = normalize(wi + wo)."""
    mi = mitsuba()

    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        wi = _dir(theta, a.shape[1])
        bs = ct.sample(p, wi, Float(a[0]), Array2f(a[1], a[2]))
        v = dr.normalize(wi + bs.wo) if half_vector else bs.wo
        return (to_mitsuba_vec3(ROT @ np.array(v, dtype=np.float64)),
                mi.Float(np.array(bs.valid).astype(np.float32)))

    def pdf_func(w):
        v = to_drpt(ROT.T @ np.array(w, dtype=np.float64), Array3f)
        wi = _dir(theta, dr.width(v))
        if not half_vector:
            return to_mitsuba_float(np.array(ct.pdf(p, wi, v)))
        # density of h: pdf(wo(h)) |dwo/dh| = pdf(wo) 4 |dot(wo, h)|, on dot(wi, h) > 0
        wo = dr.normalize(mf.reflect(wi, v))
        d = ct.pdf(p, wi, wo) * 4.0 * dr.abs(dr.dot(wo, v))
        return to_mitsuba_float(np.array(dr.select(dr.dot(wi, v) > 0.0, d, 0.0)))

    return sample_func, pdf_func


@pytest.mark.mitsuba
@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("theta", ANGLES)
def test_sampling_matches_pdf(theta, alpha):
    if theta == 89.0 and alpha == 0.01:
        # At 89 degrees the alpha 0.01 lobe is ~2 cos(89) alpha = 4e-4 rad wide
        # across the plane of incidence: no spherical grid resolves it. The
        # same sampler/pdf pair is tested over h instead (next test).
        pytest.skip("lobe too thin for the wo grid; see test_sampling_matches_pdf_half_vector")
    ok, msg = _chi2(*_lobe_sampler(_params(alpha=alpha), theta), 3, *RES[alpha])
    assert ok, msg


@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", ANGLES)
def test_sampling_matches_pdf_half_vector(theta):
    # Sharp lobes seen through h = normalize(wi + wo), where they are ~alpha wide.
    ok, msg = _chi2(*_lobe_sampler(_params(alpha=0.01), theta, half_vector=True), 3, *RES[0.01])
    assert ok, msg


# ---------------------------------------------------- equality with Mitsuba
MI_CASES = [((0.8, 0.6, 0.4), 0.5, 0.3), (HARD[0], HARD[1], HARD[2]), ((0.5, 0.5, 0.5), 0.0, 0.5),
            ((0.2, 0.6, 0.9), 0.3, 0.01), ((1.0, 1.0, 1.0), 1.0, 1e-3), ((0.8, 0.1, 0.1), 0.5, 1.0),
            ((0.3, 0.3, 0.3), 0.0, 0.0), ((0.7, 0.7, 0.2), 0.0, 0.1), ((0.9, 0.2, 0.5), 1.0, 0.05)]


def _principled(mi, base, metal, alpha):
    d = {"type": "principled", "base_color": {"type": "rgb", "value": list(base)},
         "metallic": float(metal), "roughness": math.sqrt(alpha)}
    return mi.load_dict(d)


def _mi_si(mi, wi):
    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[1])
    si.wi = to_mitsuba_vec3(wi)  # local = world: principled reads si.wi only
    return si


@pytest.mark.mitsuba
@pytest.mark.parametrize("base,metal,alpha", MI_CASES)
def test_eval_and_pdf_equal_mitsuba_principled(base, metal, alpha):
    mi = mitsuba()
    n = 10_000
    wi = _sphere_dirs(n, 1)
    wi[2] = np.abs(wi[2])
    wi[:, :50] = -wi[:, :50]  # some viewers below: both give 0 (one-sided)
    wo = _sphere_dirs(n, 2)
    # Half of the wo around the mirror direction, where the specular lobe is.
    near = np.array([-wi[0], -wi[1], wi[2]]) + (0.3 * math.sqrt(alpha) + 1e-3) * _sphere_dirs(n, 3)
    near /= np.linalg.norm(near, axis=0)
    wo[:, ::2] = near[:, ::2]
    wi, wo = wi.astype(np.float32), wo.astype(np.float32)

    p = _params(base, alpha, metal)
    f_d = np.array(ct.eval(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    p_d = np.array(ct.pdf(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    bsdf = _principled(mi, base, metal, alpha)
    ctx = mi.BSDFContext()
    si = _mi_si(mi, wi)
    f_m = np.array(bsdf.eval(ctx, si, to_mitsuba_vec3(wo)))
    p_m = np.array(bsdf.pdf(ctx, si, to_mitsuba_vec3(wo)))

    # principled's pdf is not one-sided: from below (wi.z < 0) it keeps a
    # specular-reflection pdf although its eval there is 0 (spec_trans = 0).
    # twosided never asks it from below, so compare the pdfs above only.
    assert np.all(f_m[:, :50] == 0) and np.any(p_m[:50] > 0)
    p_m[:50] = 0.0
    # drpt's pdf cancels dot(wi, h) / dot(wo, h) = 1 analytically; Mitsuba
    # computes both dots in float32, and near wo ~ -wi they differ. Compare
    # the pdf at 1e-4 where Mitsuba's float32 ratio is within 1e-5 of 1, and
    # within that ratio's error elsewhere.
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=0)
    ratio = np.abs(np.sum(wi * h, axis=0) / np.sum(wo * h, axis=0) - 1.0)
    clean = ratio < 1e-5
    assert clean.mean() > 0.95
    # Relative tolerance 1e-4 (measured: < 1e-6); the floor 1e-7 of the
    # largest value only forgives float32 noise far down the lobe.
    for a, b, lanes in ((f_d, f_m, slice(None)), (p_d, p_m, clean)):
        assert np.all(np.isfinite(a)) and np.all(a >= 0)
        floor = 1e-7 * float(b.max())
        err = np.abs(a - b) / (np.abs(b) + floor)
        assert err[..., lanes].max() < 1e-4, (err.max(), np.unravel_index(err.argmax(), err.shape))
    assert np.all(np.abs(p_d - p_m) <= (2 * ratio + 1e-4) * p_m + 1e-7 * p_m.max())
    assert np.all(f_d[:, :50] == 0) and np.all(p_d[:50] == 0)
    assert (p_d > 0).sum() > n // 3


@pytest.mark.mitsuba
def test_export_is_twosided_principled_and_matches_both_sides():
    mi = mitsuba()
    d = export_bsdf("cook_torrance", True, kd=HARD[0], alpha=HARD[2], metalness=HARD[1])
    assert d["type"] == "twosided" and d["bsdf_0"]["type"] == "principled"
    assert d["bsdf_0"]["roughness"] == pytest.approx(math.sqrt(HARD[2]))
    bsdf = mi.load_dict(d)
    n = 4000
    wi, wo = _sphere_dirs(n, 5), _sphere_dirs(n, 6)
    wo[2] = np.abs(wo[2]) * np.sign(wi[2])  # same side as the viewer
    wi, wo = wi.astype(np.float32), wo.astype(np.float32)
    f_m = np.array(bsdf.eval(mi.BSDFContext(), _mi_si(mi, wi), to_mitsuba_vec3(wo)))
    # drpt's material layer flips the frame to the viewer's side (isotropic
    # lobe: flipping z alone, as twosided does, is equivalent).
    flip = np.array([[1.0], [1.0], [1.0]]) * np.array([1.0, 1.0, 0.0])[:, None]
    flip = flip + np.array([0.0, 0.0, 1.0])[:, None] * np.sign(wi[2])
    base, metal, alpha = HARD
    p = _params(base, alpha, metal)
    f_d = np.array(ct.eval(p, to_drpt(wi * flip, Array3f), to_drpt(wo * flip, Array3f)))
    assert np.allclose(f_d, f_m, rtol=1e-4, atol=1e-7 * f_m.max())
    assert (f_m > 0).mean() > 0.9


# ------------------------------------------------ weights, furnace, symmetry
@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0, 89.0])
@pytest.mark.parametrize("alpha,metal", [(0.01, 0.5), (0.5, 0.0), (1.0, 1.0)])
def test_weight_is_eval_over_mixture_pdf(theta, alpha, metal):
    n = 50_000
    u = _uniform(n, 3, 11)
    p = _params(alpha=alpha, metal=metal)
    wi = _dir(theta)
    bs = ct.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    f = np.array(ct.eval(p, wi, bs.wo))
    pdf = np.array(ct.pdf(p, wi, bs.wo))
    w, bpdf, valid = np.array(bs.weight), np.array(bs.pdf), np.array(bs.valid)
    assert np.array_equal(bpdf, np.where(valid, pdf, 0))  # the full mixture pdf
    assert np.allclose(w[:, valid], f[:, valid] / pdf[valid], rtol=1e-6)
    assert np.all(w[:, ~valid] == 0)
    assert not np.any(np.array(bs.delta)) and np.all(np.array(bs.eta) == 1)
    assert valid.mean() > 0.45  # alpha 1: ~half the reflections go below


def _albedo(p, theta, n=400_000, seed=7):
    u = _uniform(n, 3, seed)
    bs = ct.sample(p, _dir(theta), Float(u[0]), Array2f(u[1], u[2]))
    w = np.array(bs.weight, dtype=np.float64)
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n), w.max(axis=1)


def _albedo_mitsuba(mi, base, metal, alpha, theta, n=400_000, seed=8):
    u = _uniform(n, 3, seed)
    bsdf = _principled(mi, base, metal, alpha)
    si = _mi_si(mi, np.repeat(_dir_np(theta)[:, None], n, axis=1))
    _, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    w = np.array(w, dtype=np.float64)
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n)


@pytest.mark.mitsuba
@pytest.mark.parametrize("base,metal,alpha", [((1.0, 1.0, 1.0), 0.0, 1.0), ((1.0, 1.0, 1.0), 0.5, 0.2),
                                              (HARD[0], HARD[1], HARD[2]),
                                              ((0.9, 0.2, 0.5), 1.0, 0.05)])
def test_albedo_equals_mitsuba_principled(base, metal, alpha):
    # Same model, independent samplers (Mitsuba's VNDF is Heitz 2014's).
    mi = mitsuba()
    p = _params(base, alpha, metal)
    for theta in (0.0, 60.0, 89.0):
        a, ea, _ = _albedo(p, theta)
        b, eb = _albedo_mitsuba(mi, base, metal, alpha, theta)
        assert np.all(np.abs(a - b) <= 4.5 * np.hypot(ea, eb) + 1e-6), (theta, a, b, ea, eb)


@pytest.mark.parametrize("alpha", [0.0, 1e-3, 0.1, 0.5, 1.0])
def test_furnace_metal_at_most_one(alpha):
    # Pure metal: weight = F G1(wo) per sample, so every weight is <= 1.
    p = _params((1.0, 1.0, 1.0), alpha, 1.0)
    for theta in (0.0, 30.0, 60.0, 85.0, 89.9):
        mean, err, wmax = _albedo(p, theta, n=100_000)
        assert np.all(mean <= 1.0 + 1e-6) and np.all(wmax <= 1.0 + 1e-5), (theta, mean, wmax)


def test_smooth_metal_albedo_is_base_color_at_normal_incidence():
    base = (0.9, 0.75, 0.3)
    mean, err, _ = _albedo(_params(base, 1e-3, 1.0), 0.0, n=100_000)
    assert np.allclose(mean, base, rtol=1e-4), mean


def test_principled_dielectric_is_not_energy_conserving():
    # Documented property of principled (Burley diffuse with retro-reflection,
    # not reduced by the specular Fresnel): white, metalness 0, alpha 1 reflects
    # ~1.05 at normal incidence and ~1.6 at grazing. Pinned so that a change
    # of model is noticed; the Mitsuba comparison above shows it is principled's.
    p = _params((1.0, 1.0, 1.0), 1.0, 0.0)
    m0, e0, _ = _albedo(p, 0.0)
    m89, e89, _ = _albedo(p, 89.0)
    assert np.allclose(m0, 1.049, atol=0.005) and np.allclose(m89, 1.571, atol=0.01), (m0, m89)
    # For a mid-grey base it stays below 1 at all angles.
    for theta in (0.0, 45.0, 80.0, 89.9):
        mean, err, _ = _albedo(_params((0.5, 0.5, 0.5), 1.0, 0.0), theta, n=100_000)
        assert np.all(mean < 1.0), (theta, mean)


@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0, 89.0])
def test_hard_case_weights_bounded(theta):
    # Seed's hard case (metalness 0.9, alpha 0.9, base (0.9, 0.75, 0.3)):
    # 1M samples, no firefly -- the largest weight stays near the albedo
    # (measured: max <= 1.01, albedo 0.39 .. 0.67 in red).
    base, metal, alpha = HARD
    mean, _, wmax = _albedo(_params(base, alpha, metal), theta, n=1_000_000)
    assert np.all(wmax <= 1.05 * np.array(base) / 0.9 + 1e-6), (mean, wmax)
    assert np.all(wmax <= 3.0 * mean), (mean, wmax)


@pytest.mark.parametrize("alpha,metal", [(0.0, 0.0), (0.05, 0.3), (0.5, 0.7), (1.0, 1.0)])
def test_reciprocity(alpha, metal):
    n = 10_000
    wi, wo = _sphere_dirs(n, 21), _sphere_dirs(n, 22)
    wi[2], wo[2] = np.abs(wi[2]), np.abs(wo[2])
    near = np.array([-wi[0], -wi[1], wi[2]]) + 0.05 * _sphere_dirs(n, 23)
    near /= np.linalg.norm(near, axis=0)
    wo[:, ::2] = near[:, ::2]
    wo[2] = np.abs(wo[2])
    wi, wo = wi.astype(np.float32), wo.astype(np.float32)
    p = _params(alpha=alpha, metal=metal)
    a = np.array(ct.eval(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    b = np.array(ct.eval(p, to_drpt(wo, Array3f), to_drpt(wi, Array3f)))
    ok = (wi[2] > 0) & (wo[2] > 0)
    fa, fb = a[:, ok] / wo[2, ok], b[:, ok] / wi[2, ok]
    assert np.allclose(fa, fb, rtol=1e-4, atol=1e-6 * fa.max())


# ------------------------------------------------------------- microfacet
@pytest.mark.parametrize("alpha", [1e-4, 0.01, 0.3, 1.0])
def test_microfacet_normalizations(alpha):
    # integral D(m) m.z dm = 1 and integral D_wi(m) dm = 1 (quadrature in
    # t = tan(theta_m)/alpha, phi, which follows the peak for any alpha).
    t = np.linspace(0.0, 2000.0, 400_001)[1:]
    t = np.concatenate([np.linspace(0, 20, 200_001)[1:], t[t > 20]])
    tan_m = alpha * t
    cos_m = 1.0 / np.sqrt(1.0 + tan_m**2)
    # d omega = sin dtheta dphi; dtheta = alpha dt cos^2
    jac = np.sqrt(1 - cos_m**2) * alpha * cos_m**2
    m = Array3f(Float(np.sqrt(1 - cos_m**2).astype(np.float32)), Float(0.0),
                Float(cos_m.astype(np.float32)))
    ggx = mf.Distribution(False, alpha)
    d = np.array(ggx.D(m), dtype=np.float64)
    integral = 2 * np.pi * np.trapezoid(d * cos_m * jac, t)
    assert integral == pytest.approx(1.0, abs=2e-3)
    # G1 limits
    up = Array3f(0.0, 0.0, 1.0)
    assert ggx.G1(up, up)[0] == 1.0
    assert ggx.G1(Array3f(1.0, 0.0, 0.0), up)[0] == 0.0
    g = ggx.G1(Array3f(math.sqrt(1 - 1e-12), 0.0, 1e-6), up)[0]
    assert 0.0 <= g < 2e-6 / alpha + 1e-6
    # pdf_visible integrates to 1 (MC with the sampler's own directions is
    # circular; use uniform hemisphere sampling for broad alpha only).
    if alpha >= 0.3:
        n = 2_000_000
        v = _sphere_dirs(n, 31)
        v[2] = np.abs(v[2])
        for th in (0.0, 60.0, 89.0):
            pv = np.array(ggx.pdf_visible(_dir(th, n), to_drpt(v.astype(np.float32), Array3f)),
                          dtype=np.float64)
            assert pv.mean() * 2 * np.pi == pytest.approx(1.0, abs=0.02)


# ---------------------------------------------------------------- extremes
EXTREME_DIRS = {
    "normal": (0.0, 0.0, 1.0),
    "grazing": (float(np.sqrt(1 - 1e-12)), 0.0, 1e-6),
    "oblique": tuple(float(x) for x in _dir_np(70.0)),
}


@pytest.mark.parametrize("alpha", [0.0, 1e-4, 1e-2, 0.5, 1.0])
@pytest.mark.parametrize("metal", [0.0, 1.0])
@pytest.mark.parametrize("which", list(EXTREME_DIRS))
def test_extremes_finite(alpha, metal, which):
    n = 20_000
    p = _params((1.0, 1.0, 1.0), alpha, metal)
    wi = Array3f(*EXTREME_DIRS[which])
    u = _uniform(n, 3, 31)
    one = 1 - 2**-24
    u[:, :6] = [[0, 0, one, 0.5, 0.99, 0.99], [0, one, 0, 0.5, 0, one], [0, one, one, 0, one, 0]]
    bs = ct.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    w, pdf, valid, wo = np.array(bs.weight), np.array(bs.pdf), np.array(bs.valid), np.array(bs.wo)
    for a in (w, pdf, wo):
        assert np.all(np.isfinite(a))
    assert np.all(w >= 0) and np.all(pdf >= 0)
    assert np.allclose(np.linalg.norm(wo, axis=0), 1.0, atol=1e-5)
    f = np.array(ct.eval(p, wi, bs.wo))
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    ok = valid & (pdf > 0)
    assert np.allclose(w[:, ok], f[:, ok] / pdf[ok], rtol=1e-5, atol=1e-30)
    assert np.all(w[:, ~valid] == 0) and np.all(pdf[~valid] == 0)
    assert np.all(w <= 2.0 * 7.0 + 1e-3)  # (2 - m)(F + c (f_d + f_r)) bound
    # eval/pdf of arbitrary pairs, including grazing wo, the mirror direction, +-z
    g = EXTREME_DIRS["grazing"]
    wos = np.concatenate([_sphere_dirs(1000, 41),
                          np.array([[g[0], 0, g[2]], [-g[0], 0, g[2]],
                                    [-EXTREME_DIRS[which][0], 0, EXTREME_DIRS[which][2]],
                                    [0, 0, 1], [0, 0, -1]]).T], axis=1).astype(np.float32)
    m = wos.shape[1]
    wi_m = Array3f(*(Float(np.full(m, x, np.float32)) for x in EXTREME_DIRS[which]))
    fe = np.array(ct.eval(p, wi_m, to_drpt(wos, Array3f)))
    pe = np.array(ct.pdf(p, wi_m, to_drpt(wos, Array3f)))
    assert np.all(np.isfinite(fe)) and np.all(fe >= 0)
    assert np.all(np.isfinite(pe)) and np.all(pe >= 0)
    # VNDF alone
    ggx = mf.Distribution(False, alpha)
    mm = np.array(ggx.sample_visible_normal(wi, Array2f(u[1], u[2])))
    assert np.all(np.isfinite(mm)) and np.all(mm[2] >= 0)
    pv = np.array(ggx.pdf_visible(wi, to_drpt(mm, Array3f)))
    assert np.all(np.isfinite(pv)) and np.all(pv >= 0)


def test_alpha_zero_is_alpha_1e3():
    # principled's clamp: alpha 0 behaves as alpha 1e-3 in D and G (the
    # retro-reflection term uses sqrt(alpha) unclamped, so compare metals).
    n = 5000
    wi = to_drpt(np.abs(_sphere_dirs(n, 61)).astype(np.float32), Array3f)
    wo = to_drpt(np.abs(_sphere_dirs(n, 62)).astype(np.float32), Array3f)
    a = np.array(ct.eval(_params(alpha=0.0, metal=1.0), wi, wo))
    b = np.array(ct.eval(_params(alpha=1e-3, metal=1.0), wi, wo))
    assert np.array_equal(a, b)


def test_below_surface_is_zero():
    p = _params()
    wi = Array3f(0.0, 0.6, -0.8)
    wo = Array3f(0.0, -0.6, 0.8)
    assert np.all(np.array(ct.eval(p, wi, wo)) == 0) and np.array(ct.pdf(p, wi, wo))[0] == 0
    bs = ct.sample(p, wi, Float(0.3), Array2f(0.3, 0.7))
    assert not bool(bs.valid[0]) and np.all(np.array(bs.weight) == 0) and bs.pdf[0] == 0


def test_params_gather_per_lane():
    table = ct.CookTorranceParams(Array3f([0.1, 0.2], [0.1, 0.2], [0.1, 0.2]), Float([0.1, 0.9]),
                                  Float([0.0, 1.0]))
    g = dr.gather(ct.CookTorranceParams, table, UInt32([1, 0, 1]))
    assert np.allclose(np.array(g.alpha), [0.9, 0.1, 0.9])
    assert np.allclose(np.array(g.metalness), [1, 0, 1])
    assert np.allclose(np.array(g.base_color)[0], [0.2, 0.1, 0.2])
