"""Lambertian lobe (drpt/render/bsdf/diffuse.py): sampling matches its pdf,
the sample weight equals eval/pdf, energy is conserved, reciprocity holds."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.render.bsdf import diffuse
from drpt.render.bsdf.diffuse import DiffuseParams
from drpt.testing import run_chi2

KD = DiffuseParams(Array3f(0.7, 0.5, 0.2))


def _dir(theta_deg):
    t = np.radians(theta_deg)
    return Array3f(float(np.sin(t)), 0.0, float(np.cos(t)))


@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", [0.0, 45.0, 89.9999])
def test_sampling_matches_pdf(theta):
    wi = _dir(theta)
    ok, msg = run_chi2(lambda u: diffuse.sample(KD, Array3f(wi.x, wi.y, wi.z), Float(0.5), u).wo,
                       lambda w: diffuse.pdf(KD, Array3f(wi.x, wi.y, wi.z), w))
    assert ok, msg


def test_weight_is_eval_over_pdf_and_reciprocal():
    rng = np.random.default_rng(0)
    n = 10000
    u = Array2f(rng.random((2, n)).astype(np.float32))
    wi = dr.normalize(Array3f(0.3, -0.2, 0.9))
    bs = diffuse.sample(KD, wi, Float(0.5), u)
    wo, weight, pdf, valid = bs.wo, bs.weight, bs.pdf, bs.valid
    f = diffuse.eval(KD, wi, wo)
    w = np.array(weight)
    assert np.all(np.array(valid))
    assert np.allclose(np.array(f) / np.array(pdf), w, rtol=1e-4)
    # Reciprocity of f (eval includes cos(wo), so divide it out).
    f_rev = diffuse.eval(KD, wo, wi)
    lhs = np.array(f) / np.array(wo.z)
    rhs = np.array(f_rev) / float(wi.z[0])
    assert np.allclose(lhs, rhs, rtol=1e-4)


def test_furnace_albedo_one():
    # Reflected energy for kd = 1: the weights average to exactly 1.
    rng = np.random.default_rng(3)
    u = Array2f(rng.random((2, 100_000)).astype(np.float32))
    weight = diffuse.sample(DiffuseParams(Array3f(1.0)), Array3f(0.0, 0.0, 1.0), Float(0.5), u).weight
    assert np.allclose(np.array(weight).mean(axis=1), 1.0, atol=1e-6)


def test_below_surface_is_zero_not_nan():
    wi = Array3f(0.0, 0.0, -1.0)  # viewer below: the lobe is zero
    wo = Array3f(0.0, 0.6, 0.8)
    assert np.all(np.array(diffuse.eval(KD, wi, wo)) == 0)
    assert np.array(diffuse.pdf(KD, wi, wo))[0] == 0
    bs = diffuse.sample(KD, wi, Float(0.5), Array2f(0.3, 0.7))
    weight, pdf, valid = bs.weight, bs.pdf, bs.valid
    assert not bool(valid[0]) and np.array(pdf)[0] == 0 and np.all(np.array(weight) == 0)
    grazing = Array3f(1.0, 0.0, 1e-6)
    v = np.array(diffuse.eval(KD, grazing, grazing))
    assert np.all(np.isfinite(v)) and np.all(v >= 0)
