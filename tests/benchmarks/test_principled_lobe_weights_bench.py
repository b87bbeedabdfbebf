"""benchmarks/principled_lobe_weights.py: its albedo rule is an estimator of the same image
as principled's own (a normalized density that ``sample`` draws and ``pdf`` states, on the
same lobes), so that the benchmark compares noise only; and its material cases."""

from __future__ import annotations

import importlib.util

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.render.bsdf import principled as pr
from drpt.testing import mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3
from support import REPO

_spec = importlib.util.spec_from_file_location("lobe_weights_bench", REPO / "benchmarks" / "principled_lobe_weights.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)

ROT = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # the normal to +y (test_principled's)
CASES = {
    "textured1": {"base_color": (0.2, 0.8, 0.1), "roughness": 0.15, "anisotropic": 0.8, "metallic": 0.1,
                  "clearcoat": 0.9, "sheen": 0.9, "specular": 0.7},
    "rough_all": {"base_color": (0.3, 0.6, 0.8), "roughness": 0.9, "metallic": 0.3, "spec_trans": 0.4,
                  "clearcoat": 0.6, "clearcoat_gloss": 0.5, "sheen": 0.5},
}


def _dir(theta: float, n: int) -> Array3f:
    t = np.radians(theta)
    return dr.full(Array3f, [float(np.sin(t)), 0.0, float(np.cos(t))], n)


def _chi2(prm: dict, theta: float, rule, monkeypatch):
    mi = mitsuba()
    monkeypatch.setattr(pr, "_probabilities", rule)
    p = pr.from_params(prm)

    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        bs = pr.sample(p, _dir(theta, a.shape[1]), Float(a[0]), Array2f(a[1], a[2]))
        return (to_mitsuba_vec3(ROT @ np.array(bs.wo, dtype=np.float64)),
                mi.Float(np.array(bs.valid).astype(np.float32)))

    def pdf_func(w):
        v = to_drpt(ROT.T @ np.array(w, dtype=np.float64), Array3f)
        return to_mitsuba_float(np.array(pr.pdf(p, _dir(theta, dr.width(v)), v)))

    return spherical_chi2(sample_func, pdf_func, sample_dim=3, sample_count=200_000, res=121, ires=8)


def _microfacet_dependent(p, front, F, bsdf, brdf):
    """Negative control: the albedo rule with the reflection's weight scaled by the Fresnel
    of the sampled microfacet -- the normalization then depends on the microfacet, the mixture
    ``sample`` draws is no longer the one ``pdf`` states."""
    pd, pc, pt, ps, ok = bench.albedo_probabilities(p, front, F, bsdf, brdf)
    ps = ps * 10.0 * F
    inv = dr.select(ok, dr.rcp(dr.select(ok, pd + pc + pt + ps, 1.0)), 0.0)
    return pd * inv, pc * inv, pt * inv, ps * inv, ok


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", [10.0, 45.0, 75.0])
@pytest.mark.parametrize("name", list(CASES))
def test_albedo_rule_samples_the_pdf_it_states(name, theta, monkeypatch):
    ok, msg = _chi2(CASES[name], theta, bench.albedo_probabilities, monkeypatch)
    assert ok, msg


@pytest.mark.slow
@pytest.mark.mitsuba
def test_chi2_negative_control_microfacet_dependent_rule(monkeypatch):
    ok, _ = _chi2(CASES["rough_all"], 45.0, _microfacet_dependent, monkeypatch)
    assert not ok


@pytest.mark.parametrize("front", [True, False])
def test_albedo_rule_has_mitsubas_support(front):
    """Each lobe's probability is positive exactly where Mitsuba's is (zeros in every
    parameter and rate included), so both rules sample the same directions."""
    rng = np.random.default_rng(8)
    n = 4096
    vals = {k: rng.choice([0.0, 0.3, 1.0], n) for k in ("metallic", "spec_trans", "clearcoat", "sheen")}
    rates = {k: rng.choice([0.0, 1.0, 2.5], n) for k in ("rate_diffuse", "rate_spec", "rate_clearcoat")}
    color = rng.choice([0.0, 0.5], (3, n))
    p = pr.PrincipledParams(base_color=Array3f(*(Float(c) for c in color)), eta=Float(1.5),
                            **{k: Float(v) for k, v in {**vals, **rates}.items()})
    _, brdf, bsdf = pr._weights(p)
    F = Float(rng.uniform(0.0, 1.0, n))
    side = dr.full(dr.auto.Bool, front, n)
    theirs = pr._probabilities(p, side, F, bsdf, brdf)
    ours = bench.albedo_probabilities(p, side, F, bsdf, brdf)
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(np.array(a) > 0, np.array(b) > 0)
    if front:  # every lobe is drawn somewhere, and not everywhere
        assert all(0.0 < np.mean(np.array(a) > 0) < 1.0 for a in ours[:4])


def test_material_cases_expand_each_checkerboard():
    class Board:
        def __init__(self, c0, c1):
            self.color0, self.color1 = (c0,) * 3, (c1,) * 3

    cases = bench._combinations({"roughness": 0.15, "metallic": Board(0.7, 0.1), "sheen": Board(0.2, 0.9)})
    assert sorted((c["metallic"], c["sheen"]) for c in cases) == [(0.1, 0.2), (0.1, 0.9), (0.7, 0.2), (0.7, 0.9)]
    assert all(c["roughness"] == 0.15 for c in cases)
