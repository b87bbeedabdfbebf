"""The ``principledthin`` lobe (drpt/render/bsdf/principledthin.py) against Mitsuba 3's
``principledthin`` plugin:

* eval and pdf equal Mitsuba's on 4000 random (wi, wo) pairs (both sides) per parameter set,
  sets that switch every part on (specular reflection and transmission with spec_tint,
  anisotropy, diffuse transmission, sheen with tint, flatness, the sampling rates); a
  perturbed parameter is caught by the same comparison (negative control);
* chi-square of sample against pdf from both sides, and a wrong pdf is rejected (wrong lobe
  probabilities; the transmission with the reflection's GGX width);
* weight == eval / pdf, finiteness at the extremes; the reader, the exporter and
  ``twosided``'s refusal (it transmits, as in Mitsuba);
* the sampling weight's mean and second moment at Mitsuba's (the same random numbers into
  both samplers): a sampler that matched the pdf but chose its lobes worse would pass the
  chi-square and fail this; drpt with the specular lobes' sampling rates cut is its
  negative control.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.export.mitsuba_bsdf import to_mitsuba
from drpt.materials.bsdf_kinds import defaults
from drpt.materials.spec import BSDFSpec, complete
from drpt.render.bsdf import principledthin as pt
from drpt.testing import mitsuba, spherical_chi2, to_drpt

RED = (0.8, 0.3, 0.2)
CASES = {
    "default": {},
    "diffuse": {"base_color": RED, "roughness": 0.8, "flatness": 0.6},
    "glossy": {"base_color": RED, "spec_trans": 0.6, "eta": 1.33, "roughness": 0.3},
    "all": {"base_color": RED, "roughness": 0.45, "anisotropic": 0.7, "spec_trans": 0.4, "diff_trans": 1.2,
            "sheen": 0.6, "sheen_tint": 0.5, "flatness": 0.4, "spec_tint": 0.6, "eta": 1.6,
            "specular_reflectance_sampling_rate": 0.7, "specular_transmittance_sampling_rate": 1.3,
            "diffuse_transmittance_sampling_rate": 0.9, "diffuse_reflectance_sampling_rate": 1.1},
    "leaf": {"base_color": (0.2, 0.6, 0.1), "diff_trans": 1.5, "roughness": 0.9, "sheen": 0.3},
}


def _params(prm: dict) -> pt.ThinParams:
    p = {**defaults("principledthin"), **prm}
    eta = pt.derive(p)["thin_eta"]

    def f(v):
        return dr.opaque(Float, float(v), 1)

    c = p["base_color"]
    vals = {n: f(p[n]) for n in pt.FLOATS}
    rates = dict(zip(("srr", "srt", "sdt", "sdr"), (f(p[n]) for n in pt.RATES)))
    return pt.ThinParams(base_color=Array3f(f(c[0]), f(c[1]), f(c[2])), eta=f(eta), **vals, **rates,
                         flags=pt.flags_of([p]))


def _mi(mi, prm):
    return mi.load_dict(to_mitsuba(complete(BSDFSpec("principledthin", dict(prm)))))


def _sphere(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def _compare(prm, drpt_prm=None, n=4000):
    mi = mitsuba()
    ref = _mi(mi, prm)
    p = _params(drpt_prm if drpt_prm is not None else prm)
    wi, wo = _sphere(n, 1), _sphere(n, 2)
    # a quarter near the specular reflection and transmission directions
    k = n // 4
    refl = np.stack([-wi[0], -wi[1], wi[2]]) + 0.05 * _sphere(n, 3)
    wo[:, :k] = (refl / np.linalg.norm(refl, axis=0))[:, :k]
    wo[2, k:2 * k] = -wo[2, :k]
    f = np.array(pt.eval(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    pd = np.array(pt.pdf(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f)))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*wi.astype(np.float32))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    fm, pm = ref.eval_pdf(mi.BSDFContext(), si, mi.Vector3f(*wo.astype(np.float32)))
    return f, np.array(fm), pd, np.array(pm)


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", sorted(CASES))
def test_eval_and_pdf_equal_mitsuba(name):
    f, fm, pd, pm = _compare(CASES[name])
    assert np.abs(fm).max() > 0.05 and (pm > 0).mean() > 0.3
    np.testing.assert_allclose(f, fm, rtol=1e-3, atol=1e-5)
    np.testing.assert_allclose(pd, pm, rtol=1e-3, atol=1e-5)


@pytest.mark.mitsuba
@pytest.mark.parametrize("key, value", [("eta", 1.45), ("diff_trans", 1.0), ("anisotropic", 0.5),
                                        ("spec_tint", 0.4), ("sheen_tint", 0.2), ("flatness", 0.2)])
def test_negative_control_perturbed_parameter_is_caught(key, value):
    f, fm, pd, pm = _compare(CASES["all"], {**CASES["all"], key: value})
    assert not (np.allclose(f, fm, rtol=1e-3, atol=1e-5) and np.allclose(pd, pm, rtol=1e-3, atol=1e-5))


def _chi2(prm, side, pdf_prm=None):
    p, q = _params(prm), _params(pdf_prm if pdf_prm is not None else prm)
    wi = np.array([0.5, -0.2, 0.8 * side])
    wi /= np.linalg.norm(wi)
    w = Array3f(*(float(x) for x in wi))

    def sample(u):
        mi = mitsuba()
        u = np.array(u, np.float32)
        bs = pt.sample(p, w, Float(u[0]), Array2f(Float(u[1]), Float(u[2])))
        ok = np.array(bs.valid)
        return mi.Vector3f(*np.array(bs.wo, np.float32)), mi.Float(ok.astype(np.float32))

    def pdf(v):
        mi = mitsuba()
        return mi.Float(np.array(pt.pdf(q, w, to_drpt(np.array(v), Array3f)), np.float32))

    return spherical_chi2(sample, pdf, sample_dim=3, sample_count=400_000, res=61, ires=8, seed=2)


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["diffuse", "glossy", "all", "leaf"])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_sampling_matches_pdf(name, side):
    ok, msg = _chi2(CASES[name], side)
    assert ok, msg


@pytest.mark.mitsuba
def test_chi2_negative_control():
    ok, _ = _chi2(CASES["all"], 1.0, {**CASES["all"], "diff_trans": 0.6})
    assert not ok


@pytest.mark.mitsuba
def test_chi2_negative_control_transmission_width():
    """Sampling draws each lane's visible normal from its lobe's GGX (the transmission's
    roughness scaled by ``0.65 eta - 0.35``): a pdf whose transmission has the reflection's
    width (``eta = 1.35 / 0.65`` makes the scale 1; ``eta`` enters the pdf nowhere else) is
    rejected."""
    ok, _ = _chi2(CASES["glossy"], 1.0, {**CASES["glossy"], "eta": 1.35 / 0.65})
    assert not ok


@pytest.mark.parametrize("name", sorted(CASES))
def test_weight_is_eval_over_pdf_and_finite(name):
    p = _params(CASES[name])
    rng = np.random.default_rng(5)
    n = 20000
    wi = _sphere(n, 6)
    wi[:, :100] = np.array([[1.0], [0.0], [1e-6]])  # grazing
    u = rng.random((3, n)).astype(np.float32)
    bs = pt.sample(p, to_drpt(wi, Array3f), Float(u[0]), Array2f(Float(u[1]), Float(u[2])))
    valid = np.array(bs.valid)
    assert valid.mean() > 0.5
    f = np.array(pt.eval(p, to_drpt(wi, Array3f), bs.wo))
    pdf = np.array(pt.pdf(p, to_drpt(wi, Array3f), bs.wo))
    w = np.array(bs.weight)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(np.isfinite(f)) and np.all(f >= 0)
    np.testing.assert_allclose(w[:, valid], f[:, valid] / pdf[valid], rtol=1e-4, atol=1e-6)


#: the corpus sheet (bsdf_spheres/test_texturedprincipledthin_path.xml) at one of its checker
#: cells: specular transmission, anisotropy, diffuse transmission, sheen
SHEET = {"base_color": (0.7, 0.1, 0.1), "anisotropic": 0.8, "spec_trans": 0.2, "diff_trans": 1.4,
         "sheen": 0.8, "eta": 1.33}


def _weights(prm, drpt_prm, wi, n=200_000):
    """Sampling weights (luminance-free: the channels summed) of ``n`` samples from drpt
    (with ``drpt_prm``) and from Mitsuba (``prm``), the same uniform numbers into both."""
    mi = mitsuba()
    ref = _mi(mi, prm)
    u = np.random.default_rng(11).random((3, n)).astype(np.float32)
    w = np.tile(np.asarray(wi, np.float64)[:, None] / np.linalg.norm(wi), (1, n))
    bs = pt.sample(_params(drpt_prm), to_drpt(w, Array3f), Float(u[0]), Array2f(Float(u[1]), Float(u[2])))
    ours = np.array(bs.weight, np.float64).sum(0)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*w.astype(np.float32))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    _, wm = ref.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    theirs = np.array(wm, np.float64)[:3].sum(0)
    return ours, theirs


def _second_moment_excess(ours, theirs):
    """How far drpt's second moment of the weight is above Mitsuba's (paired samples), in
    units of its allowance: 4 standard errors of the paired difference plus 0.1% of
    Mitsuba's (float rounding: with the same numbers the two samplers give the same
    directions, and the differences are rounding noise). Above 1: more variance."""
    d = ours ** 2 - theirs ** 2
    return d.mean() / (4.0 * d.std(ddof=1) / np.sqrt(len(d)) + 1e-3 * np.mean(theirs ** 2))


@pytest.mark.mitsuba
@pytest.mark.parametrize("wi", [(0.5, -0.2, 0.8), (0.9, 0.1, 0.2), (0.3, 0.4, -0.6)])
def test_sampling_weight_variance_is_mitsubas(wi):
    """The estimator f / pdf of drpt's sampler has Mitsuba's mean (within 4 standard
    errors) and no larger second moment (:func:`_second_moment_excess`), so no more variance."""
    ours, theirs = _weights(SHEET, SHEET, wi)
    assert theirs.mean() > 0.1
    se = np.sqrt(ours.var() / len(ours))
    assert abs(ours.mean() - theirs.mean()) < 4 * se, (ours.mean(), theirs.mean())
    x = _second_moment_excess(ours, theirs)
    assert x < 1.0, f"second moment {np.mean(ours ** 2):.4g} against Mitsuba's {np.mean(theirs ** 2):.4g}"


@pytest.mark.mitsuba
def test_sampling_weight_variance_negative_control():
    """drpt sampling the specular lobes a twentieth as often (the sampling rates 0.05:
    eval and pdf stay consistent, so the estimator stays unbiased) has a larger second
    moment than Mitsuba's at the default rates (1.60 against 0.90): the test must catch it."""
    cut = {**SHEET, "specular_reflectance_sampling_rate": 0.05, "specular_transmittance_sampling_rate": 0.05}
    ours, theirs = _weights(SHEET, cut, (0.5, -0.2, 0.8))
    assert _second_moment_excess(ours, theirs) > 1.0


def test_twosided_refuses_principledthin_as_mitsuba():
    with pytest.raises(ValueError, match="transmissive BSDF 'principledthin'"):
        complete(BSDFSpec("twosided", {}, [BSDFSpec("principledthin", {})]))


def test_derive_refuses_bad_parameters():
    with pytest.raises(ValueError, match="eta"):
        pt.derive({"eta": 0.0})
    with pytest.raises(ValueError, match="sampling_rate"):
        pt.derive({"diffuse_reflectance_sampling_rate": -1.0})
    with pytest.raises(ValueError, match=r"diff_trans = 2.5 is outside \[0, 2\]"):
        pt.derive({"diff_trans": 2.5})
    with pytest.raises(ValueError, match=r"sheen = -0.1 is outside \[0, 1\]"):
        pt.derive({"sheen": -0.1})
    assert pt.derive({"diff_trans": 2.0, "eta": 1.2}) == {"thin_eta": 1.2}


# ------------------------------------------------------------------ renders against Mitsuba
@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("control", [False, True], ids=["as written", "diff_trans dropped"])
def test_thin_sheets_render_like_mitsuba(control):
    """``tests/data/xml/thin.xml`` (a leaf lit from behind, a textured anisotropic sheet)
    rendered by drpt and by Mitsuba from the same file: 8x8 block z-test and the image mean's
    z (as tests/scene/mitsuba/test_mitsuba_xml.py). The negative control, the leaf without its diffuse
    transmission, must fail it."""
    from dataclasses import replace

    from drpt.testing import block_z
    from support.xml import XML, load, mean_z, render_xml_both

    scene, _ = load("thin")
    if control:
        for m in scene.materials:
            if m.bsdf.kind == "principledthin" and "diff_trans" in m.bsdf.params:
                m.bsdf = replace(m.bsdf, params={**m.bsdf.params, "diff_trans": 0.0})
    r, ref, var = render_xml_both(scene, XML / "thin.xml", 256)
    z = np.abs(block_z(r.image, r.variance, ref, var)).max()
    zm = np.abs(mean_z(r, ref, var)).max()
    if control:
        assert z > 6 or zm > 6, f"max |z| {z:.2f}, mean z {zm:.2f} (should fail)"
    else:
        assert ref.mean() > 0.05 and z < 4.5 and zm < 4.0, f"max |z| {z:.2f}, mean z {zm:.2f}"
