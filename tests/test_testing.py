"""drpt.testing, the statistical helpers users can call: each check passes on a correct
sampler or image and fails on a wrong one (its negative control), at the thresholds its
docstring states."""

from __future__ import annotations

import numpy as np
import pytest
from drjit.auto import Array3f

from drpt.render.bsdf import diffuse
from drpt.render.bsdf.diffuse import DiffuseParams
from drpt.testing import agreement, block_z, bsdf_chi2, furnace, z_test

WIS = [(0.0, 0.0, 1.0), (0.6, 0.0, 0.8), (0.999, 0.0, 0.0447)]


def _diffuse(kd):
    p = DiffuseParams(Array3f(*kd))
    return lambda wi, u1, u2: diffuse.sample(p, wi, u1, u2)


def test_furnace_passes_lossless_and_lossy_lobes():
    assert furnace(_diffuse((1.0, 1.0, 1.0)), WIS, lossless=True).passed
    r = furnace(_diffuse((0.7, 0.5, 0.2)), WIS)
    assert r.passed and np.allclose(r.albedo, [0.7, 0.5, 0.2], atol=1e-5)


def test_furnace_negative_controls():
    """1% too much energy fails; a lossy lobe claimed lossless fails; NaN weights fail."""
    lobe = _diffuse((1.0, 1.0, 1.0))
    assert not furnace(lambda wi, u1, u2: lobe(wi, u1, u2).weight * 1.01, WIS).passed
    assert not furnace(_diffuse((0.99, 0.99, 0.99)), WIS, lossless=True).passed
    assert not furnace(lambda wi, u1, u2: lobe(wi, u1, u2).weight + float("nan"), WIS).passed


@pytest.mark.mitsuba
def test_bsdf_chi2_passes_and_catches_a_wrong_pdf():
    p = DiffuseParams(Array3f(0.5))
    ok, msg = bsdf_chi2(diffuse, p, (0.6, 0.0, 0.8), sample_count=100_000, res=31)
    assert ok, msg

    class UniformPdf:  # samples the cosine density but claims the uniform hemisphere one
        sample = staticmethod(diffuse.sample)

        @staticmethod
        def pdf(p, wi, wo):
            import drjit as dr
            return dr.select(wo.z > 0.0, 1.0 / (2.0 * np.pi), 0.0)

    ok, _ = bsdf_chi2(UniformPdf, p, (0.6, 0.0, 0.8), sample_count=100_000, res=31)
    assert not ok


def test_block_z_and_z_test_negative_controls():
    rng = np.random.default_rng(0)
    ref = np.full((32, 32, 3), 0.5)
    var = np.full((32, 32, 3), 0.01)
    x = ref + rng.normal(0.0, 0.1, ref.shape)
    assert np.abs(block_z(x, var, ref, var)).max() < 4.5
    assert np.abs(block_z(x * 1.2, var, ref, var)).max() > 4.5
    # z_test: per-sample variance 0.25 at 64 spp -> std of the mean 0.0625
    img = ref + rng.normal(0.0, 0.0625, ref.shape)
    assert z_test(img, 64, ref, np.full_like(ref, 0.25)).passed
    assert not z_test(img + 0.4, 64, ref, np.full_like(ref, 0.25)).passed


def test_agreement_of_two_renders():
    """Two noisy estimates of one image agree (block and mean |z| small); one 3% brighter
    does not (control)."""
    from types import SimpleNamespace

    rng = np.random.default_rng(3)
    truth = rng.random((32, 32, 3)) + 0.5
    var = np.full_like(truth, 1e-3)

    def render(scale=1.0):
        return SimpleNamespace(image=scale * truth + rng.normal(0.0, np.sqrt(1e-3), truth.shape), variance=var)

    zb, zm = agreement(render(), render())
    assert zb < 4.5 and zm < 4.0
    zb, zm = agreement(render(1.03), render())
    assert zb > 6.0 and zm > 6.0
