"""Perfect mirror lobe (drpt/render/bsdf/mirror.py) and the specular exporter
(drpt/export/mitsuba_bsdf.py): direction, weight, extremes, and equality
with Mitsuba's ``conductor`` (material="none", specular_reflectance)."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.render.bsdf import mirror
from drpt.testing import export_bsdf, mitsuba

R = (0.9, 0.6, 0.25)


def _f(a):
    return Float(np.ascontiguousarray(a, dtype=np.float32))


def _v3(a):
    a = np.asarray(a, dtype=np.float32)
    return Array3f(_f(a[0]), _f(a[1]), _f(a[2]))


def _sample(wi, r=R, u=None):
    wi = np.asarray(wi, dtype=np.float32)
    n = wi.shape[1]
    u = np.full(n, 0.5) if u is None else u
    p = mirror.MirrorParams(Array3f(*[_f(np.full(n, c)) for c in r]))
    bs = mirror.sample(p, _v3(wi), _f(u), Array2f(_f(u), _f(u)))
    return {k: np.broadcast_to(np.array(getattr(bs, k)), (3, n) if k in ("wo", "weight") else (n,))
            for k in ("wo", "weight", "pdf", "valid", "delta", "eta")}


def _sphere(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def test_direction_and_weight():
    v = _sphere(4000, 1)
    v[2] = np.abs(v[2])
    v[:, 0] = (0.0, 0.0, 1.0)
    out = _sample(v)
    np.testing.assert_allclose(out["wo"], v * np.array([[-1], [-1], [1]]), atol=1e-7)
    # angle of incidence = angle of reflection, coplanar, opposite azimuth
    np.testing.assert_allclose(out["wo"][2], v[2], atol=1e-7)
    np.testing.assert_allclose(out["weight"], np.array(R, np.float32)[:, None].repeat(4000, 1))
    assert out["valid"].all() and out["delta"].all()
    assert np.all(out["pdf"] == 0.0) and np.all(out["eta"] == 1.0)


def test_below_surface_is_zero():
    v = _sphere(1000, 2)
    v[2] = -np.abs(v[2])
    v[:, 0] = (1.0, 0.0, 0.0)  # exactly tangent
    v[:, 1] = (1.0, 0.0, -0.0)
    out = _sample(v)
    assert not out["valid"].any()
    assert np.all(out["weight"] == 0.0)
    assert np.all(np.isfinite(out["wo"]))


def test_extremes():
    cos = np.array([1e-6, 1e-30, 1.0, 0.5])
    v = np.stack([np.sqrt(1 - cos * cos), np.zeros(4), cos])
    out = _sample(v, r=(1.0, 0.0, 1.0))
    assert out["valid"].all()
    assert np.all(np.isfinite(out["wo"])) and np.all(np.isfinite(out["weight"]))
    np.testing.assert_allclose(np.linalg.norm(out["wo"], axis=0), 1.0, atol=1e-6)
    assert np.all(out["wo"][2] > 0)
    np.testing.assert_array_equal(out["weight"][:, 0], [1.0, 0.0, 1.0])


def test_eval_pdf_zero():
    a, b = _sphere(50, 3), _sphere(50, 4)
    p = mirror.MirrorParams(Array3f(*R))
    assert np.all(np.array(mirror.eval(p, _v3(a), _v3(b))) == 0.0)
    assert np.all(np.array(mirror.pdf(p, _v3(a), _v3(b))) == 0.0)


def test_export_dicts():
    from drpt.errors import DrptError

    d = export_bsdf("mirror", True, ks=R)
    assert d == {"type": "twosided", "bsdf_0": {
        "type": "conductor", "material": "none",
        "specular_reflectance": {"type": "rgb", "value": list(R)}}}
    assert export_bsdf("dielectric", int_ior=1.33, ext_ior=1.0) == {
        "type": "dielectric", "int_ior": 1.33, "ext_ior": 1.0,
        "specular_reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
        "specular_transmittance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    with pytest.raises(DrptError):
        export_bsdf("dielectric", int_ior=float("nan"))


@pytest.mark.mitsuba
def test_equals_mitsuba_conductor():
    mi = mitsuba()
    n = 10_000
    v = _sphere(n, 7).astype(np.float32)
    u = np.random.default_rng(8).random(n).astype(np.float32)
    bsdf = mi.load_dict(export_bsdf("mirror", True, ks=R))
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(v[0], v[1], v[2])
    bs, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(u), mi.Point2f(u, u))
    mwo, mw = np.array(bs.wo), np.array(w)
    assert np.all(np.array(bs.sampled_type) == int(mi.BSDFFlags.DeltaReflection))

    # Front side: the lobe itself. Back side: twosided flips the frame, as
    # drpt's material layer does before calling the lobe.
    front = v[2] > 0
    zflip = np.stack([np.ones(n), np.ones(n), np.where(front, 1.0, -1.0)]).astype(np.float32)
    out = _sample(v * zflip, u=u)
    wo = out["wo"] * zflip
    np.testing.assert_allclose(wo, mwo, atol=1e-7)
    np.testing.assert_allclose(out["weight"], mw, rtol=1e-6)
    # the bare conductor (one-sided) is zero below, as the lobe is
    cond = mi.load_dict(export_bsdf("mirror", ks=R))
    _, w1 = cond.sample(mi.BSDFContext(), si, mi.Float(u), mi.Point2f(u, u))
    np.testing.assert_allclose(_sample(v, u=u)["weight"], np.array(w1), rtol=1e-6)
