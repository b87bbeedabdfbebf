"""Mitsuba's MicrofacetDistribution in drpt (drpt/render/bsdf/microfacet.py:
``Distribution``, Beckmann and GGX, isotropic and anisotropic):

* D, G1, G, both pdfs and both samplers equal ``mi.MicrofacetDistribution``'s
  on thousands of random normals/directions (samplers: same ``u`` -> same
  normal);
* D is normalized (``integral D m.z dm = 1``), the visible-normal density
  integrates to 1 (GGX exactly; Beckmann within its G1 approximation);
* chi-square: sample_visible_normal draws from pdf_visible, sample_all from
  pdf_all, at 0/45/80/89 degrees; a negative control (pdf with a wrong
  alpha) is rejected;
* Beckmann's slope inversion: the exact CDF at the sampled slopes within 5e-7 of
  ``u`` over a dense grid of incidences and ``u`` (two Halley steps fail it);
* finite, non-negative output at alpha 1e-4 and cos 1e-6;
* ``alpha_min`` is the lower clamp of the widths.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.render.bsdf import microfacet as mf
from drpt.render.warp import concentric_polar, polar_to_disk
from drpt.testing import mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3
from support.beckmann import slope_cdf_error

# (beckmann, alpha_u, alpha_v or None for isotropic)
CASES = [(True, 0.1, None), (False, 0.1, None), (True, 0.5, None), (False, 0.5, None),
         (True, 0.1, 0.4), (False, 0.1, 0.4), (True, 1e-3, None), (False, 1.0, 0.05)]


def _ids(c):
    return f"{'beckmann' if c[0] else 'ggx'}-{c[1]}-{c[2]}"


def _sphere(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return (v / np.linalg.norm(v, axis=0)).astype(np.float32)


def _dir_np(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def _dirs(theta_deg, n, phi_deg=0.0):
    return Array3f(*(Float(np.full(n, x, np.float32)) for x in _dir_np(theta_deg, phi_deg)))


def _mi_distr(mi, beck, au, av, visible=True):
    t = mi.MicrofacetType.Beckmann if beck else mi.MicrofacetType.GGX
    if av is None:
        return mi.MicrofacetDistribution(t, au, visible)
    return mi.MicrofacetDistribution(t, au, av, visible)


def _close(a, b, rtol, atol=0.0):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    bad = np.abs(a - b) > atol + rtol * np.abs(b)
    assert not bad.any(), f"{bad.sum()} of {bad.size} differ, e.g. {a[bad][:5]} vs {b[bad][:5]}"


# ---------------------------------------------------------------- vs Mitsuba
@pytest.mark.mitsuba
@pytest.mark.parametrize("case", CASES, ids=_ids)
def test_D_G1_pdf_equal_mitsuba(case):
    mi = mitsuba()
    beck, au, av = case
    n = 20_000
    m = _sphere(n, 1)
    m[2] = np.abs(m[2])
    m[:, :100] *= -1.0  # some normals below
    # half of them near the normal, where D is large
    near = np.array([[0.0], [0.0], [1.0]]) + 2.0 * max(au, av or au) * _sphere(n, 2)
    near /= np.linalg.norm(near, axis=0)
    m[:, 100::2] = near[:, 100::2].astype(np.float32)
    v = _sphere(n, 3)
    v[:, :200] = np.array([[0.0], [0.0], [1.0]], np.float32)  # t = 0
    v[2, 200:400] = 1e-6  # grazing (not renormalized: G1 only needs the ratios)

    d = mf.Distribution(beck, au, av)
    md = _mi_distr(mi, beck, au, av)
    dm, dv = to_drpt(m, Array3f), to_drpt(v, Array3f)
    mm, mv = to_mitsuba_vec3(m), to_mitsuba_vec3(v)
    _close(d.D(dm), md.eval(mm), 2e-5, 1e-30)
    _close(d.G1(dv, dm), md.smith_g1(mv, mm), 1e-5, 1e-7)
    _close(d.G(dv, dm, dm), md.G(mv, mm, mm), 1e-5, 1e-7)
    # pdfs need wi.z > 0 (Mitsuba's pdf_visible is negative below; drpt returns 0)
    wi = _sphere(n, 4)
    wi[2] = np.abs(wi[2]) + 1e-3
    wi /= np.linalg.norm(wi, axis=0)
    dwi, mwi = to_drpt(wi, Array3f), to_mitsuba_vec3(wi)
    _close(d.pdf_visible(dwi, dm), md.pdf(mwi, mm), 5e-5, 1e-30)
    ma = _mi_distr(mi, beck, au, av, visible=False)
    _close(mf.Distribution(beck, au, av, sample_visible=False).pdf(dwi, dm), ma.pdf(mwi, mm), 2e-5, 1e-30)
    assert np.all(np.array(d.pdf_visible(-dwi, dm)) == 0.0)


@pytest.mark.mitsuba
@pytest.mark.parametrize("visible", [True, False], ids=["visible", "all"])
@pytest.mark.parametrize("case", CASES, ids=_ids)
def test_samplers_equal_mitsuba(case, visible):
    """Same u -> the same normal as Mitsuba's sampler, and the same density."""
    mi = mitsuba()
    beck, au, av = case
    n = 20_000
    rng = np.random.default_rng(5)
    u = rng.random((2, n)).astype(np.float32)
    wi = _sphere(n, 6)
    wi[2] = np.abs(wi[2]) + 1e-4
    wi /= np.linalg.norm(wi, axis=0)
    wi[:, :100] = _dir_np(0.0)[:, None]
    wi[:, 100:200] = _dir_np(89.9, 37.0)[:, None]
    d = mf.Distribution(beck, au, av, sample_visible=visible)
    m_d, p_d = d.sample(to_drpt(wi, Array3f), to_drpt(u, Array2f))
    m_d, p_d = np.array(m_d), np.array(p_d)
    md = _mi_distr(mi, beck, au, av, visible)
    m_m, p_m = md.sample(to_mitsuba_vec3(wi), mi.Point2f(u[0], u[1]))
    m_m, p_m = np.array(m_m), np.array(p_m)
    assert np.isfinite(m_d).all() and np.isfinite(p_d).all() and (p_d >= 0).all()
    ok = np.isfinite(m_m).all(axis=0)
    assert ok.mean() > 0.999
    # Mitsuba's azimuth of the stretched wi is inexact within ~1e-3 rad of the
    # pole (it takes sin^2 = 1 - cos^2 in float32); drpt's is exact: skip those
    # (but keep exact normal incidence, where both use azimuth 0).
    au_, av_ = au, av or au
    wp = np.array([au_ * wi[0], av_ * wi[1], wi[2]], np.float64)
    sin2 = (wp[0] ** 2 + wp[1] ** 2) / np.sum(wp ** 2, axis=0)
    ok &= (sin2 > 1e-5) | (sin2 == 0.0) if visible else ok
    if not visible and au < 0.01:
        # Mitsuba's sin theta = sqrt(1 - cos^2) is quantized by float32 at this
        # alpha (errors ~2e-4, a quarter of the lobe width); compare with the
        # exact mapping in float64 instead.
        u64 = u.astype(np.float64)
        cos = 1.0 / np.sqrt(1.0 - au * au * np.log1p(-u64[0])) if beck else \
            1.0 / np.sqrt(1.0 + au * au * u64[0] / (1.0 - u64[0]))
        sin = np.sqrt(1.0 - cos * cos)
        phi = 2.0 * np.pi * u64[1]
        ref = np.array([np.cos(phi) * sin, np.sin(phi) * sin, cos])
        err = np.linalg.norm(m_d - ref, axis=0)
        assert np.quantile(err, 0.999) < 1e-6 and err.max() < 1e-5, (np.quantile(err, 0.999), err.max())
        m_m = ref
    err = np.linalg.norm(m_d[:, ok] - m_m[:, ok], axis=0)
    # float32 rounding; the Beckmann Newton iteration amplifies it a little
    assert np.quantile(err, 0.999) < 1e-4 and err.max() < 3e-3, (np.quantile(err, 0.999), err.max())
    # the density returned is Mitsuba's pdf at drpt's normal
    p_at = np.array(md.pdf(to_mitsuba_vec3(wi), to_mitsuba_vec3(m_d)))
    _close(p_d, p_at, 1e-4, 1e-30)
    good = ok & (p_m > 1e-3)
    assert np.median(np.abs(p_d[good] / p_m[good] - 1.0)) < 1e-3


# ---------------------------------------------------------------- integrals
def _hemisphere_grid(alpha_min, n_theta=6000, n_phi=256):
    """Quadrature nodes/weights over the upper hemisphere, theta graded toward the pole."""
    # theta = atan(s), s = k t / (1 - t): dense where the distribution is
    k = 3.0 * alpha_min
    t = (np.arange(n_theta) + 0.5) / n_theta
    s = k * t / (1.0 - t)
    theta = np.arctan(s)
    dtheta = (k / (1.0 - t) ** 2) / (1.0 + s * s) / n_theta
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    w = (np.sin(T) * dtheta[:, None] * (2.0 * np.pi / n_phi)).ravel()
    m = np.array([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)]).reshape(3, -1)
    return m, w


@pytest.mark.parametrize("case", CASES[:6] + [(True, 0.05, 0.3), (False, 0.05, 0.3)], ids=_ids)
def test_D_normalized(case):
    beck, au, av = case
    m, w = _hemisphere_grid(min(au, av or au))
    d = mf.Distribution(beck, au, av)
    Dm = np.array(d.D(to_drpt(m, Array3f)), np.float64)
    assert abs(np.sum(Dm * m[2] * w) - 1.0) < 2e-3


@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0, 89.0])
@pytest.mark.parametrize("case", [(True, 0.1, None), (False, 0.1, None), (True, 0.1, 0.4), (False, 0.1, 0.4)],
                         ids=_ids)
def test_visible_pdf_normalized(case, theta):
    """integral D_wi(m) dm = 1: exact for GGX's G1, ~0.35 % for Beckmann's rational G1."""
    beck, au, av = case
    m, w = _hemisphere_grid(min(au, av or au))
    d = mf.Distribution(beck, au, av)
    dm = to_drpt(m, Array3f)
    p = np.array(d.pdf_visible(_dirs(theta, m.shape[1], 30.0), dm), np.float64)
    assert abs(np.sum(p * w) - 1.0) < (5e-3 if beck else 2e-3)


def test_extremes_finite():
    n = 4096
    u = np.random.default_rng(9).random((2, n)).astype(np.float32)
    u[:, :4] = [[0.0, 1.0, 0.0, 1.0], [0.0, 1.0, 1.0, 0.0]]
    u[:, 4:8] = [[1 - 6e-8] * 4, [0.25, 0.75, 0.5, 0.0]]
    for beck in (True, False):
        for au, av in ((1e-4, None), (1.0, None), (1e-4, 1.0), (0.0, 0.0), (1.0, 1e-4)):
            for vis in (True, False):
                d = mf.Distribution(beck, au, av, sample_visible=vis)
                for theta in (0.0, 45.0, 89.9999):
                    wi = _dirs(theta, n, 20.0)
                    m, p = d.sample(wi, to_drpt(u, Array2f))
                    arrs = [np.array(m), np.array(p), np.array(d.D(m)), np.array(d.G1(wi, m)),
                            np.array(d.pdf_visible(wi, m))]
                    for a in arrs:
                        assert np.isfinite(a).all(), (beck, au, av, vis, theta)
                        assert (a[-1] >= 0).all() if a.ndim == 1 else True
                    assert (np.array(p) >= 0).all() and (np.array(d.D(m)) >= 0).all()
    # cos 1e-6
    d = mf.Distribution(True, 1e-4)
    v = Array3f(Float(np.sqrt(1 - 1e-12)), Float(0.0), Float(1e-6))
    assert np.isfinite(np.array(d.G1(v, Array3f(0.0, 0.0, 1.0)))).all()
    # Beckmann's visible normals down to cos 1e-30 (the slope sampler clamps cos at 1e-12;
    # without the clamp most normals are NaN below cos ~1e-23)
    for cos in (1e-12, 1e-25, 1e-30):
        wi = Array3f(Float(np.full(n, 1.0, np.float32)), Float(np.zeros(n, np.float32)),
                     Float(np.full(n, cos, np.float32)))
        for alpha in (1.0, 2.0):
            m = mf.Distribution(True, alpha).sample_visible_normal(wi, to_drpt(u, Array2f))
            assert np.isfinite(np.array(m)).all(), (cos, alpha)


def test_alpha_min_is_the_lower_clamp():
    """``alpha_min`` replaces Mitsuba's 1e-4 clamp (cook_torrance passes principled's
    1e-3): alpha 0 then is alpha 1e-3 exactly, and not the default clamp's 1e-4."""
    m = _sphere(2000, 13)
    m[2] = np.abs(m[2])
    wi = _sphere(2000, 14)
    wi[2] = np.abs(wi[2]) + 0.01
    wi /= np.linalg.norm(wi, axis=0)
    dm, dwi = to_drpt(m, Array3f), to_drpt(wi, Array3f)
    u = Array2f(Float(np.linspace(0.01, 0.99, 2000)), Float(np.linspace(0.98, 0.02, 2000)))
    clamped, ref, default = (mf.Distribution(False, 0.0, alpha_min=1e-3), mf.Distribution(False, 1e-3),
                             mf.Distribution(False, 0.0))
    for f in (lambda d: d.D(dm), lambda d: d.G1(dwi, dm), lambda d: d.sample_visible_normal(dwi, u)):
        assert np.array_equal(np.array(f(clamped)), np.array(f(ref)))
    assert not np.array_equal(np.array(clamped.D(dm)), np.array(default.D(dm)))  # negative control


def test_visible_normal_from_the_callers_disk_point():
    """``sample_visible_normal(wi, u, disk)`` with ``disk`` the point of the warp module's
    ``concentric_polar(u)`` (what a lobe sharing one ``sincos`` between warps passes) is the
    normal drawn from ``u`` alone, to the float; another point (the same disk point
    mirrored about the diagonal) changes some normals (negative control); Beckmann refuses
    a disk point."""
    wi = _sphere(4000, 21)
    wi[2] = np.abs(wi[2]) + 0.01
    wi /= np.linalg.norm(wi, axis=0)
    dwi = to_drpt(wi, Array3f)
    rng = np.random.default_rng(22)
    u = Array2f(Float(rng.random(4000, dtype=np.float32)), Float(rng.random(4000, dtype=np.float32)))
    d = mf.Distribution(False, 0.3, 0.1)
    disk = polar_to_disk(*concentric_polar(u))
    assert np.array_equal(np.array(d.sample_visible_normal(dwi, u, disk)), np.array(d.sample_visible_normal(dwi, u)))
    other = Array2f(disk.y, disk.x)
    assert not np.array_equal(np.array(d.sample_visible_normal(dwi, u, other)),
                              np.array(d.sample_visible_normal(dwi, u)))
    with pytest.raises(ValueError):
        mf.Distribution(True, 0.3).sample_visible_normal(dwi, u, disk)


# ---------------------------------------------------------------- chi-square
# The normal maps to +y: the distribution's peak lies on the chi2 grid's equator.
ROT = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
ANGLES = (0.0, 45.0, 80.0, 89.0)


def _chi2(sample_func, pdf_func, res=121, ires=8, sample_count=200_000):
    mitsuba()

    return spherical_chi2(sample_func, pdf_func, sample_dim=2, sample_count=sample_count, res=res, ires=ires)


def _funcs(d, theta, pdf_d=None):
    pdf_d = pdf_d or d

    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        wi = _dirs(theta, a.shape[1], 30.0)
        m = d.sample_visible_normal(wi, Array2f(a[0], a[1])) if d.sample_visible else d.sample_all(Array2f(a[0], a[1]))
        return to_mitsuba_vec3(ROT @ np.array(m, dtype=np.float64))

    def pdf_func(w):
        m = to_drpt(ROT.T @ np.array(w, dtype=np.float64), Array3f)
        return to_mitsuba_float(np.array(pdf_d.pdf(_dirs(theta, dr.width(m), 30.0), m)))

    return sample_func, pdf_func


CHI2_CASES = [(True, 0.1, None), (False, 0.1, None), (True, 0.5, None), (False, 0.5, None),
              (True, 0.1, 0.4), (False, 0.1, 0.4)]


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", ANGLES)
@pytest.mark.parametrize("case", CHI2_CASES, ids=_ids)
def test_vndf_chi2(case, theta):
    beck, au, av = case
    ok, msg = _chi2(*_funcs(mf.Distribution(beck, au, av), theta))
    assert ok, msg


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("case", CHI2_CASES, ids=_ids)
def test_all_normals_chi2(case):
    beck, au, av = case
    ok, msg = _chi2(*_funcs(mf.Distribution(beck, au, av, sample_visible=False), 0.0))
    assert ok, msg


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("beck", [True, False], ids=["beckmann", "ggx"])
def test_chi2_negative_control(beck):
    """The chi-square test rejects a density 10 % too wide (alpha 0.11 vs 0.1) at 45 degrees."""
    ok, _ = _chi2(*_funcs(mf.Distribution(beck, 0.1), 45.0, pdf_d=mf.Distribution(beck, 0.11)))
    assert not ok


# ---------------------------------------------------------------- Beckmann slope inversion
def _beckmann_slope_cdf_error():
    """:func:`support.beckmann.slope_cdf_error` of drpt's sampler (x by the Halley
    inversion, y by ``erfinv(2 u - 1)``)."""
    def slopes(cos, u):
        n = mf.Distribution(True, 1.0)._slopes11_beckmann(cos, u)
        return -n.x, n.y
    return slope_cdf_error(slopes)


def test_beckmann_slope_inversion_error():
    """The sampled slopes' exact CDF is within 5e-7 of ``u`` everywhere (near the float32
    floor; the errors of drpt's and Mitsuba's steps on this grid: docs/performance.md,
    "Beckmann's sampler")."""
    ex, ey = _beckmann_slope_cdf_error()
    assert ex < 5e-7 and ey < 5e-7, (ex, ey)


def test_beckmann_slope_inversion_negative_control(monkeypatch):
    """Two Halley steps instead of three: the bound is broken."""
    monkeypatch.setattr(mf, "_HALLEY_STEPS", 2)
    ex, _ = _beckmann_slope_cdf_error()
    assert ex > 5e-7, ex
