"""Convergence: drpt's error against every committed Mitsuba reference falls as 1/N;
the ratio computations of ``drpt converge``; converge/knobs CLI smoke tests.

1/N test (``test_error_falls_as_one_over_n``), on one fixed scene where the slope is well
defined: the Cornell box's committed reference (8192 spp at 128 x 128), box-downsampled by 2
to 64 x 64 (exact with a box pixel filter: 32768 of Mitsuba's samples per big pixel), and
drpt at 64, 128, 256, 512, 1024 spp (:data:`SLOPE_LEVELS`), each level with its own seed.
At 64 spp and more the Cornell box's pixel means are in their central-limit regime, so the
squared relative error of a pixel, ``(x - ref)^2 / (ref^2 + 0.01)``, is its variance
``v / N`` times a chi-square(1) draw, and the median over the 12288 pixel channels falls as
exactly 1/N (with the reference's own noise, ``v / 32768``: the median divided by ``1 + N /
32768``). Its least-squares log-log slope must be within :data:`SLOPE_TOL` = 0.1 of -1
(measured over 6 seed sets: -0.966 to -1.020, standard deviation 0.018: 0.1 is over 5 of
them). The median, not the mean (relMSE): a mean is decided by its rarest, brightest
samples, and at 4-64 spp (the previous design) the slope of relMSE was decided by the 4-spp
level's heavy tail. Negative controls (each must leave the bound): an estimator whose error
falls as N^-1/2 instead of its variance (at level N it averages only ``sqrt(64 N)`` samples;
measured -0.49), a biased one (paths cut at 6 segments; measured -0.65) and a 2% bias
(the image times 1.02; measured -0.73).

Bias against each reference (``test_error_is_unbiased_against_each_reference``), for every
entry of ``drpt.tools.reference.REFERENCES`` (new entries are picked up; a missing EXR
skips):

* the reference is box-downsampled by an integer factor ``f`` to at most
  64 pixels a side and drpt renders that size at 4, 8, 16, 32, 64 spp, each level with
  its own seed;
* ``excess = relMSE - floor``; the reference's noise floor
  ``mean(var_ref / (ref^2 + 0.01))`` takes ``var_ref`` from the reference's
  variance EXR where one is committed (references rendered in batches,
  ``variance_path``; downsampled as ``sum / f^4``), else from drpt's own
  per-sample variance over ``ref_spp * f^2`` samples (Mitsuba's per-sample
  variance is close to drpt's; the floor is ~1% of the 64-spp error);
* bias: for an unbiased renderer ``E[excess_N] = mean(var_N / w)``
  (``var_N`` the variance of the pixel mean, which drpt estimates), a bias
  adds ``mean(bias^2 / w)`` that does not fall with N. So
  ``b = excess_64 - mean(var_64 / w)`` estimates the error left at infinite
  spp, and the error extrapolated to the reference's spp is
  ``excess_64 * 64 / ref_spp + b``. We require ``b <= 0.25 * excess_64``
  at 64 spp (and the mean over levels of ``excess_N / pred_N`` within
  [0.85, 1.15]): a bias whose relMSE is above a quarter of the 64-spp noise
  fails; smaller biases are below what this test can see (measured ratios
  0.91-1.06). The printout also gives each level's share of relMSE in the top 0.1% of
  values (showcase_day 0.67, showcase_dusk 0.99; Cornell box and newscene <= 0.2): where
  it is high, a single render's relMSE is far from its 1/N regime at these spp.
* HEAVY_TAILED references (showcase_dusk since its alphas became Roughness^2)
  are left out of the 1/N test and checked at 4096 spp by region means
  instead (``test_heavy_tailed_*``: the variance there is the larger of drpt's
  own estimate and the reference's per-sample variance, see
  ``heavy_tailed_z``; its control renders Mitsuba itself, and a biased
  sharp lobe fails it).

Runtime: the 1/N test ~5 s per estimator under load (1984 spp at 64 x 64); the bias test
1-3 s per scene at light load, ~4-8 s under load (124 spp at <= 64x64);
scenes come from the session-wide ``reference_scene`` fixture (conftest.py),
which generates the git-ignored dining room when it is absent, so it is
checked on CI too;
the dining room ~25-35 s, nearly all of it loading and building its 510k
triangles, not rendering.
"""

from __future__ import annotations

import argparse
import csv
import json
import math

import numpy as np
import pytest

from drpt.errors import DrptError
from drpt.tools import converge
from drpt.tools.converge import (
    equal_time_ratios,
    interp_loglog,
    loglog_slope,
    noise_floor,
    spp_levels,
    time_to_error,
    time_to_error_ratios,
)
from drpt.tools.reference import REFERENCES, reference_path, variance_path

LEVELS = (4, 8, 16, 32, 64)  # the bias test's
#: the 1/N test's levels, its bound on |slope + 1| and its scene (a REFERENCES entry)
SLOPE_LEVELS = (64, 128, 256, 512, 1024)
SLOPE_TOL = 0.1
SLOPE_SCENE = "cornellbox"
BIAS_FRACTION = 0.25
MAX_SIDE = 64


# ------------------------------------------------------------ ratio maths
def test_loglog_slope_recovers_power_laws():
    n = np.array([1, 2, 4, 8, 16, 32], float)
    s, se = loglog_slope(n, 3.0 / n)
    assert s == pytest.approx(-1.0, abs=1e-12) and se == pytest.approx(0.0, abs=1e-9)
    s, _ = loglog_slope(n, 0.5 * n ** -0.5)
    assert s == pytest.approx(-0.5, abs=1e-12)
    # non-positive errors (at the noise floor) are left out
    s, _ = loglog_slope(np.append(n, 64), np.append(2.0 / n, -1e-4))
    assert s == pytest.approx(-1.0, abs=1e-12)
    assert math.isnan(loglog_slope([1], [1])[0])


def test_interp_loglog_is_exact_on_power_laws_and_nan_outside():
    t = np.array([0.1, 0.2, 0.4, 0.8])
    e = 0.01 / t
    at = np.array([0.05, 0.1, 0.15, 0.3, 0.8, 1.0])
    got = interp_loglog(t, e, at)
    assert np.isnan(got[0]) and np.isnan(got[-1])
    np.testing.assert_allclose(got[1:5], 0.01 / at[1:5], rtol=1e-12)
    # order of the points does not matter
    np.testing.assert_allclose(interp_loglog(t[::-1], e[::-1], at), got, rtol=1e-12)


def test_equal_time_ratio_of_two_power_laws():
    # a: e = 0.02/t, b: e = 0.01/t -> a's error is 2x b's at any equal time.
    ta = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
    tb = np.array([0.25, 0.5, 1.0, 2.0, 4.0])
    res = equal_time_ratios(ta, 0.02 / ta, tb, 0.01 / tb)
    assert res["overlap"] == pytest.approx((0.5, 4.0))
    assert res["geomean"] == pytest.approx(2.0, rel=1e-12)
    assert [t for t, _ in res["at_a_times"]] == pytest.approx([0.5, 1.0, 2.0, 4.0])
    assert all(r == pytest.approx(2.0) for _, r in res["at_a_times"])
    # Slower renderer with the same error per sample: a takes 3x the time per
    # sample, so at equal time it has 1/3 the samples and 3x the error.
    n = np.array([1, 2, 4, 8, 16, 32, 64], float)
    res = equal_time_ratios(3 * n, 1 / n, n, 1 / n)
    assert res["geomean"] == pytest.approx(3.0, rel=1e-12)
    # no overlap in time
    res = equal_time_ratios([1, 2], [1, 0.5], [3, 4], [1, 0.5])
    assert res["overlap"] is None and math.isnan(res["geomean"]) and res["at_a_times"] == []


def test_efficiency_rounds_on_known_noise_and_time(monkeypatch):
    """Ways of known noise (per-pixel standard deviation 1 and 2) and known time (a fake clock
    each render advances by 1 s and 0.5 s): variance within 3% of 1 and 4 (64 x 64 x 3 values
    over 8 rounds: a relative standard error near 0.6%), seconds exact, efficiency 1/(s var);
    the warm-up render counts in neither. Negative control: the noisier way's variance is not
    the quieter one's."""
    clock = [0.0]
    monkeypatch.setattr(converge.time, "perf_counter", lambda: clock[0])
    seeds = []

    def way(sd, seconds):
        def render(seed):
            seeds.append(seed)
            clock[0] += seconds
            return np.random.default_rng(seed * 2 + (sd > 1)).normal(5.0, sd, (64, 64, 3))
        return render

    res = converge.efficiency_rounds({"a": way(1.0, 1.0), "b": way(2.0, 0.5)}, 8, warm_seed=99)
    assert seeds[:2] == [99, 99] and seeds[2:] == [k for k in range(8) for _ in (0, 1)]
    assert res["a"]["seconds"] == 1.0 and res["b"]["seconds"] == 0.5
    assert abs(res["a"]["variance"] - 1.0) < 0.03 and abs(res["b"]["variance"] / 4.0 - 1.0) < 0.03
    for r in res.values():
        assert r["efficiency"] == pytest.approx(1.0 / (r["seconds"] * r["variance"]))
    assert res["b"]["variance"] > 3.0 * res["a"]["variance"]
    with pytest.raises(DrptError):
        converge.efficiency_rounds({"a": way(1.0, 1.0)}, 1)


def test_efficiency_rounds_go_on_while_more_asks(monkeypatch):
    """With ``more``, rounds double (seeds 8-15, then 16-31) while ``more`` says so, up to
    ``max_rounds``, and the result is the longer run's, the same as asking for those rounds at
    once; ``rounds`` says how many. Control: a ``more`` that never asks stops at the first 8."""
    clock = [0.0]
    monkeypatch.setattr(converge.time, "perf_counter", lambda: clock[0])

    def way(sd):
        def render(seed):
            clock[0] += 1.0
            return np.random.default_rng(seed * 2 + (sd > 1)).normal(5.0, sd, (8, 8, 3))
        return render

    asked = []

    def more(res):
        asked.append(res["a"]["rounds"])
        return True

    ways = {"a": way(1.0), "b": way(2.0)}
    res = converge.efficiency_rounds(ways, 8, warm_seed=99, more=more, max_rounds=32)
    assert asked == [8, 16] and res["a"]["rounds"] == res["b"]["rounds"] == 32
    once = converge.efficiency_rounds(ways, 32, warm_seed=99)
    assert res["a"]["variance"] == once["a"]["variance"] and res["b"]["loo_variances"] == once["b"]["loo_variances"]
    never = converge.efficiency_rounds(ways, 8, warm_seed=99, more=lambda r: False, max_rounds=32)
    assert never["a"]["rounds"] == 8 and never["a"]["variance"] != res["a"]["variance"]


def test_efficiency_rounds_scores_every_way_on_the_pixels_finite_in_all(monkeypatch):
    """A way whose image has a NaN pixel in one round (as Mitsuba's ldsampler image of the
    dining room has) and an infinite one in another: both ways' variances are taken over the
    other pixels, the same for both, and equal the variances computed there by hand; each way
    counts its own non-finite pixels. Negative control: with the mask of finite pixels
    replaced by one that keeps every pixel, the variance of the way with the NaN pixel comes
    out NaN."""
    clock = iter(range(10_000))  # each render takes 1 "second"
    monkeypatch.setattr(converge.time, "perf_counter", lambda: float(next(clock)))

    def way(sd, bad):
        def render(seed):
            img = np.random.default_rng(seed * 2 + (sd > 1)).normal(5.0, sd, (16, 16, 3))
            if seed in bad:
                img[bad[seed][0]] = bad[seed][1]
            return img
        return render

    bad = {2: ((3, 4, 1), float("nan")), 4: ((0, 0, 2), float("inf"))}
    images = {"a": [way(1.0, {})(k) for k in range(6)], "b": [way(2.0, bad)(k) for k in range(6)]}
    res = converge.efficiency_rounds({"a": way(1.0, {}), "b": way(2.0, bad)}, 6, warm_seed=99)
    keep = np.ones((16, 16), bool)
    keep[3, 4] = keep[0, 0] = False
    for name in ("a", "b"):
        want = np.stack(images[name])[:, keep].var(0, ddof=1).mean()
        assert res[name]["variance"] == pytest.approx(want, rel=1e-12)
        assert math.isfinite(res[name]["efficiency"])
        assert res[name]["mean"] == pytest.approx(np.stack(images[name])[:, keep].mean(), rel=1e-12)
    assert res["a"]["nonfinite_pixels"] == 0 and res["b"]["nonfinite_pixels"] == 2
    assert 3.0 < res["b"]["variance"] / res["a"]["variance"] < 5.5
    # every round finite: every pixel counts
    res = converge.efficiency_rounds({"a": way(1.0, {})}, 6, warm_seed=99)
    assert res["a"]["variance"] == np.stack(images["a"]).var(0, ddof=1).mean()
    assert res["a"]["nonfinite_pixels"] == 0
    # control: a mask keeping every pixel lets the NaN round make the variance NaN
    with monkeypatch.context() as m:
        m.setattr(converge, "finite_in_every_round", lambda st: np.ones(st.shape[1:3], bool))
        res = converge.efficiency_rounds({"a": way(1.0, {}), "b": way(2.0, bad)}, 6, warm_seed=99)
    assert math.isnan(res["b"]["variance"]) and math.isfinite(res["a"]["variance"])


def test_efficiency_rounds_keep_their_images_outside_the_timed_renders(monkeypatch):
    """The images of a stretch of rounds are kept in room made before its first timed render:
    the memory Python's allocators hold (``tracemalloc``, which counts numpy's buffers) is the
    same at the start of every timed render of a stretch, and grows only between stretches
    (``more``: 4 rounds, then 8). Negative control: a way that keeps its own images grows it
    by one image a render, which the same probe reads."""
    import tracemalloc

    seen: list = []

    def way(keep: list | None):
        def render(seed):
            seen.append(tracemalloc.get_traced_memory()[0])
            img = np.random.default_rng(seed).normal(5.0, 1.0, (64, 64, 3))
            if keep is not None:
                keep.append(img.copy())
            return img
        return render

    tracemalloc.start()
    try:
        converge.efficiency_rounds({"a": way(None)}, 4, warm_seed=99, more=lambda r: True, max_rounds=8)
        probes = list(seen)
        seen.clear()
        kept: list = []
        converge.efficiency_rounds({"a": way(kept)}, 4, warm_seed=99)
        control = list(seen)
    finally:
        tracemalloc.stop()
    image = 64 * 64 * 3 * 8
    first, second = probes[1:5], probes[5:13]  # (probes[0]: the warm-up render)
    assert max(first) - min(first) < image / 4 and max(second) - min(second) < image / 4
    assert second[0] - first[0] > 3 * image  # the second stretch's room: 8 images where 4 were
    assert all(b - a > image / 2 for a, b in zip(control[1:], control[2:]))


def test_adaptive_ratio_against_uniform_drpt():
    from drpt.tools.converge import adaptive_ratio

    # adaptive: half the error per sample, 1.25x the seconds -> 0.625x at equal time
    rows = [{"renderer": "drpt", "spp": n, "seconds": 0.01 * n, "excess_rel_mse": 1.0 / n}
            for n in (8, 16, 32, 64)]
    rows += [{"renderer": "drpt+adaptive", "spp": n, "seconds": 0.0125 * n, "excess_rel_mse": 0.5 / n}
             for n in (8, 16, 32, 64)]
    r = adaptive_ratio(rows)
    assert r["equal_spp_ratio"] == pytest.approx(0.5)
    assert r["equal_time_ratio"] == pytest.approx(0.625)
    assert adaptive_ratio(rows[:4])["equal_time_ratio"] is None  # no adaptive rows


def test_time_to_error_interpolates_the_crossing_it_stays_below():
    t = np.array([1.0, 2.0, 4.0, 8.0])
    e = 0.1 / t  # 0.1, 0.05, 0.025, 0.0125
    assert time_to_error(t, e, 0.05) == pytest.approx(2.0)
    assert time_to_error(t, e, 0.1 / 3) == pytest.approx(3.0, rel=1e-12)  # log-log exact
    assert time_to_error(t, e, 0.2) == pytest.approx(1.0)  # reached at the start
    assert time_to_error(t, e, 0.01) is None  # never reached
    # A noisy curve: a lucky dip below the level at 2 s does not count, the
    # crossing after the last point above it (4 s) does.
    got = time_to_error([1, 2, 4, 8], [0.1, 0.04, 0.06, 0.02], 0.05)
    want = math.exp(math.log(4) + (math.log(0.05) - math.log(0.06))
                    / (math.log(0.02) - math.log(0.06)) * math.log(2))
    assert got == pytest.approx(want, rel=1e-12)
    assert time_to_error([1, 2, 4], [0.1, 0.01, 0.2], 0.05) is None  # ends above


def test_time_to_error_ratios_where_both_reach():
    t = np.array([1.0, 2.0, 4.0, 8.0])
    rows = time_to_error_ratios(2 * t, 0.1 / t, t, 0.1 / t, [0.05, 0.02, 0.01])
    assert rows[0]["ratio"] == pytest.approx(2.0) and rows[1]["ratio"] == pytest.approx(2.0)
    assert rows[2]["seconds_a"] is None and rows[2]["ratio"] is None


def test_noise_floor_and_levels():
    ref = np.full((2, 2, 3), 1.0)
    assert noise_floor(ref, np.full_like(ref, 0.0101)) == pytest.approx(0.01)
    assert spp_levels(16) == [1, 2, 4, 8, 16]
    assert spp_levels(12) == [1, 2, 4, 8, 12]
    assert spp_levels(1) == [1]


# ------------------------------------------------------------ 1/N against the references
def _factor(w: int, h: int) -> int:
    f = max(1, math.ceil(max(w, h) / MAX_SIDE))
    while w % f or h % f:
        f += 1
    return f


#: References whose scene is too heavy-tailed for the bias check at LEVELS: the dusk sun
#: reflected by chrome and paint at GGX alpha 1e-3 to 6e-3. At 4 to 64 spp a pixel's own
#: variance estimate misses the rare, bright samples, so the excess over the predicted
#: error grows with N (2.4x at 64 spp) although the image converges to the reference:
#: test_heavy_tailed_reference_is_reached_at_high_spp checks that instead.
HEAVY_TAILED = {"showcase_dusk"}


def _downsampled_reference(name):
    """``(f, ref, weight)``: reference ``name`` box-downsampled by ``f`` to at most
    :data:`MAX_SIDE` pixels a side, and the relative error's weight ``ref^2 + 0.01``."""
    from drpt.imageio import read_image

    _, W, H, _, _, _ = REFERENCES[name]
    path = reference_path(name)
    if not path.is_file():
        pytest.skip(f"{path.name} is not committed")
    f = _factor(W, H)
    w, h = W // f, H // f
    ref = read_image(path)[..., :3].astype(np.float64).reshape(h, f, w, f, 3).mean((1, 3))
    return f, ref, ref * ref + 1e-2


def _median_slope(scene, name, seed, spp_of=lambda n: n, depth=None, scale=1.0):
    """The log-log slope of the median squared relative error over :data:`SLOPE_LEVELS`
    (drpt against reference ``name``, level ``i`` rendered with ``spp_of(N)`` samples, seed
    ``seed + i``, the image times ``scale``), each median divided by ``1 + N / M`` for the
    reference's own noise (``M`` its samples per big pixel); and the medians."""
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    _, W, H, ref_spp, ref_depth, mode = REFERENCES[name]
    f, ref, weight = _downsampled_reference(name)
    # independent samples: the error is the per-pixel variance estimate (a low-discrepancy
    # sampler's is below it)
    r = Renderer(scene, RenderOptions(width=W // f, height=H // f, spp=1, bsdf=mode, progress=False,
                                      sampler="independent",
                                      path=PathOptions(max_depth=ref_depth if depth is None else depth)))
    med = []
    for i, n in enumerate(SLOPE_LEVELS):
        r.opt.spp, r.opt.seed = spp_of(n), seed + i
        res = r.render()
        assert res.nonfinite == 0 and np.all(np.isfinite(res.image))
        med.append(np.median((res.image * scale - ref) ** 2 / weight) / (1.0 + n / (ref_spp * f * f)))
    slope, _ = loglog_slope(SLOPE_LEVELS, np.array(med))
    return slope, np.array(med)


@pytest.mark.slow
def test_error_falls_as_one_over_n(reference_scene):
    """The median squared relative error against the Cornell box's reference falls as 1/N
    from 64 to 1024 spp (the module's docstring); negative controls: N^-1/2 convergence and
    two biases leave the bound."""
    scene = reference_scene(REFERENCES[SLOPE_SCENE][0])
    slope, med = _median_slope(scene, SLOPE_SCENE, 4343)
    print(f"{SLOPE_SCENE}: median squared error * N {np.array2string(med * SLOPE_LEVELS, precision=4)}, "
          f"slope {slope:.3f}")
    assert abs(slope + 1.0) < SLOPE_TOL, slope
    controls = {"error ~ N^-1/2": {"spp_of": lambda n: int(round(math.sqrt(64 * n)))},
                "paths cut at 6 segments": {"depth": 6}, "2% bias": {"scale": 1.02}}
    for what, kw in controls.items():
        bad, _ = _median_slope(scene, SLOPE_SCENE, 4343, **kw)
        print(f"{SLOPE_SCENE}, {what}: slope {bad:.3f}")
        assert abs(bad + 1.0) > SLOPE_TOL, (what, bad)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(REFERENCES) - HEAVY_TAILED))
def test_error_is_unbiased_against_each_reference(name, reference_scene):
    from drpt.imageio import read_image
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    scene_file, W, H, ref_spp, depth, mode = REFERENCES[name]
    f, ref, weight = _downsampled_reference(name)
    w, h = W // f, H // f

    r = Renderer(reference_scene(scene_file),
                 RenderOptions(width=w, height=h, spp=1, bsdf=mode, progress=False,
                               sampler="independent",  # the error the variance estimate predicts
                               path=PathOptions(max_depth=depth),
                               integrator="volpath" if reference_scene(scene_file).media else "path"))
    results = {}
    for i, spp in enumerate(LEVELS):
        # (seeds 4242 + i failed newscene's former slope check with the renderer's hashed
        # streams: no firefly drawn at 4 spp; 4343 and 5151 pass)
        r.opt.spp, r.opt.seed = spp, 4343 + i
        res = r.render()
        assert res.nonfinite == 0 and np.all(np.isfinite(res.image))
        results[spp] = res
    n_top = LEVELS[-1]
    vpath = variance_path(name)
    if vpath.is_file():  # references rendered in batches carry their variance
        var_ref = read_image(vpath)[..., :3].astype(np.float64)
        var_ref = var_ref.reshape(h, f, w, f, 3).sum((1, 3)) / f**4
    else:
        var_ref = results[n_top].variance * n_top / (ref_spp * f * f)
    floor = noise_floor(ref, var_ref)
    errors = [((results[n].image - ref) ** 2 / weight).ravel() for n in LEVELS]
    excess = np.array([e.mean() - floor for e in errors])
    top = max(1, errors[0].size // 1000)
    shares = np.array([np.sort(e)[-top:].sum() / e.sum() for e in errors])
    pred = np.array([np.mean(results[n].variance / weight) for n in LEVELS])
    b = excess[-1] - pred[-1]
    extrapolated = excess[-1] * n_top / ref_spp + b
    ratios = excess / pred
    print(f"{name} {w}x{h}: excess {np.array2string(excess, precision=4)}, "
          f"excess*N {np.array2string(excess * LEVELS, precision=3)}, floor {floor:.2e}, "
          f"excess/pred {np.array2string(ratios, precision=3)}, "
          f"bias^2 estimate {b:.2e}, extrapolated at {ref_spp} spp {extrapolated:.2e}")
    print(f"{name}: share of relMSE in the top 0.1% of values per level "
          f"{np.array2string(shares, precision=2)}")
    assert b <= BIAS_FRACTION * excess[-1], (b, excess[-1])
    assert 0.85 <= ratios.mean() <= 1.15, ratios


HEAVY_SPP = 4096
HEAVY_SEED = 77  # the render whose own-variance region z read -10.6 (the worst of 6 seeds measured)


def _heavy_reference(name):
    """(factor f, reference mean, variance of its mean, samples per big pixel),
    box-downsampled by 4 (a big pixel holds ``ref_spp * 16`` of Mitsuba's samples)."""
    from drpt.imageio import read_image

    _, W, H, ref_spp, _, _ = REFERENCES[name]
    f = 4
    w, h = W // f, H // f
    ref = read_image(reference_path(name))[..., :3].astype(np.float64).reshape(h, f, w, f, 3).mean((1, 3))
    var_ref = read_image(variance_path(name))[..., :3].astype(np.float64).reshape(h, f, w, f, 3).sum((1, 3))
    return f, ref, var_ref / f**4, ref_spp * f * f


def heavy_tailed_z(img, var_own, spp, ref, var_ref, n_ref, ry=6, rx=4):
    """z of the mean of each of ``ry x rx`` regions (per channel), then of the whole
    image (3 values), of ``img`` (``spp`` samples per pixel, its own estimate
    ``var_own`` of its pixels' variance of the mean) against ``ref`` (``n_ref``
    samples per pixel, variance of the mean ``var_ref``).

    The variance of ``img``'s pixel is ``max(var_own, var_ref * n_ref / spp)``: the
    larger of its own estimate and the reference's per-sample variance scaled to
    ``spp``. On a heavy-tailed scene ``var_own`` misses the rare, bright samples at
    ``spp`` (a 4096-spp render that saw none of them is below the mean *and*
    reports a small variance, so ``(img - ref) / sqrt(var_own)`` reads a deficit
    of 5-10 sigma: measured so on showcase_dusk for drpt AND for Mitsuba's own
    4096-spp renders); the reference, 64x the samples, sees them. Where the
    reference's estimate is the smaller (smooth sky: it averages 4x4 sub-pixels
    rendered separately, a stratification that hides the spread of radiance inside
    a big pixel, which ``img``'s samples do have) ``var_own`` is used."""
    var = np.maximum(var_own, var_ref * n_ref / spp) + var_ref
    h, w, _ = ref.shape
    by, bx = h // ry, w // rx

    def regions(a):
        return a[:ry * by, :rx * bx].reshape(ry, by, rx, bx, 3).sum((1, 3))

    z = regions(img - ref) / np.sqrt(regions(var))
    whole = (img - ref).sum((0, 1)) / np.sqrt(var.sum((0, 1)))
    return np.concatenate([z.ravel(), whole])


def _own_variance_z(img, var_own, ref, var_ref, ry=6, rx=4):
    """The same regions with ``img``'s own variance estimate only (the unsound
    statistic, printed for comparison)."""
    return heavy_tailed_z(img, var_own, 1, ref, var_ref, 0, ry, rx)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(HEAVY_TAILED))
def test_heavy_tailed_reference_is_reached_at_high_spp(name, reference_scene):
    """At 4096 spp (a 4x downsampled image) drpt agrees with the reference: the
    mean of each of 6 x 4 regions and of the whole image, per channel, within 4
    standard errors (:func:`heavy_tailed_z`; single pixels are not compared).

    Why not drpt's own variance estimate: with it this render (seed 77) reads
    region z down to -10.6 over the car body (max |z| 2.3-10.6 over 6 seeds), and
    Mitsuba's own 4096-spp renders of the exported scene read 4.9-6.3 against
    their reference (6 seeds), always a deficit, as drpt's: the statistic, not
    the renderer. At 65536 spp drpt reads max |z| 2.5 by its own variance (1.8
    by :func:`heavy_tailed_z`; whole image +0.36%, +0.14%, +0.03% in R, G, B),
    Mitsuba 2.3 (2.3), and with max_depth 2 and 3 drpt agrees with a fresh
    Mitsuba render at 4096 spp by its own variance (regions |z| < 1.7).
    Measured with :func:`heavy_tailed_z` at 4096 spp: max |z| 1.5-2.5 for drpt
    (6 seeds), 1.8-2.8 for Mitsuba (6 seeds).

    Negative controls: the image 3% too bright fails (the sky), and so does a 5%
    error confined to the heavy-tailed pixels (where the reference's variance
    exceeds 4x drpt's own estimate: ~105 of 576 pixels, ~10% of the flux, the car
    body and its reflections; measured z 5.4-8.9 for 5% over the 12 renders)."""
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    scene_file, _, _, _, depth, mode = REFERENCES[name]
    f, ref, var_ref, n_ref = _heavy_reference(name)
    h, w = ref.shape[:2]
    r = Renderer(reference_scene(scene_file),
                 RenderOptions(width=w, height=h, spp=HEAVY_SPP, bsdf=mode, seed=HEAVY_SEED, progress=False,
                               sampler="independent",  # the statistic's variance is independent samples'
                               path=PathOptions(max_depth=depth))).render()
    assert r.nonfinite == 0
    img, var = r.image.astype(np.float64), r.variance.astype(np.float64)
    z = heavy_tailed_z(img, var, HEAVY_SPP, ref, var_ref, n_ref)
    old = _own_variance_z(img, var, ref, var_ref)
    print(f"{name}: region z max {np.abs(z).max():.2f}, whole image z {np.round(z[-3:], 2)}; "
          f"with drpt's own variance only: max {np.abs(old).max():.2f}")
    print(np.round(z[:-3].reshape(6, 4, 3), 1))
    assert np.abs(z).max() < 4.0, np.abs(z).max()
    assert np.abs(heavy_tailed_z(img * 1.03, var, HEAVY_SPP, ref, var_ref, n_ref)).max() > 4.0
    heavy = (var_ref * n_ref / HEAVY_SPP).mean(-1, keepdims=True) > 4.0 * var.mean(-1, keepdims=True)
    assert heavy.sum() >= 50, heavy.sum()
    for k in (0.95, 1.05):
        zk = heavy_tailed_z(np.where(heavy, img * k, img), var, HEAVY_SPP, ref, var_ref, n_ref)
        assert np.abs(zk).max() > 4.0, (k, np.abs(zk).max())


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(HEAVY_TAILED))
def test_heavy_tailed_statistic_catches_a_biased_sharp_lobe(name, reference_scene, monkeypatch):
    """Negative control of the kind of bias suspected on showcase_dusk: the
    cook_torrance lobes sharper than alpha 0.01 (car paint 0.0064, chrome 1e-3)
    reflect 10% too little (eval and sample weight x 0.9): :func:`heavy_tailed_z`
    reads max |z| 7.9 (whole image -2.9% in R). Its power is limited at 4096 spp:
    x 0.95 read 4.7, x 1.05 only 2.3 (undetected), the seed-77 render."""
    import drjit as dr

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.bsdf import cook_torrance as ct
    from drpt.render.renderer import Renderer

    eval0, sample0 = ct.eval, ct.sample

    def k(p):
        return dr.select(p.alpha < 0.01, 0.9, 1.0)

    def biased_eval(p, wi, wo):
        return eval0(p, wi, wo) * k(p)

    def biased_sample(p, wi, u1, u2):
        bs = sample0(p, wi, u1, u2)
        bs.weight = bs.weight * k(p)
        return bs

    monkeypatch.setattr(ct, "eval", biased_eval)
    monkeypatch.setattr(ct, "sample", biased_sample)
    scene_file, _, _, _, depth, mode = REFERENCES[name]
    f, ref, var_ref, n_ref = _heavy_reference(name)
    h, w = ref.shape[:2]
    r = Renderer(reference_scene(scene_file),
                 RenderOptions(width=w, height=h, spp=HEAVY_SPP, bsdf=mode, seed=HEAVY_SEED, progress=False,
                               sampler="independent",  # the statistic's variance is independent samples'
                               path=PathOptions(max_depth=depth))).render()
    z = heavy_tailed_z(r.image.astype(np.float64), r.variance.astype(np.float64), HEAVY_SPP, ref, var_ref, n_ref)
    print(f"{name}, sharp lobes x 0.9: region z max {np.abs(z).max():.2f}, whole image z {np.round(z[-3:], 2)}")
    assert np.abs(z).max() > 4.0, np.abs(z).max()


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", sorted(HEAVY_TAILED))
def test_heavy_tailed_statistic_passes_mitsuba_itself(name, reference_scene):
    """The control of the test above: Mitsuba's own render of the exported scene
    at the same size and spp (256 batches of 16 spp; the variance of the mean from
    their spread), judged against its reference by :func:`heavy_tailed_z`, passes
    the same bound. (By its own variance only it reads max |z| ~5-6: printed.)"""
    from drpt.backend import set_mitsuba_variant
    from drpt.tools.reference import render_batches

    scene_file, _, _, _, depth, mode = REFERENCES[name]
    f, ref, var_ref, n_ref = _heavy_reference(name)
    h, w = ref.shape[:2]
    set_mitsuba_variant()
    batch = 16
    mean, var, _, _ = render_batches(reference_scene(scene_file), w, h, batch, HEAVY_SPP // batch, 5,
                                     max_depth=depth, bsdf=mode, progress=False)
    mean, var = mean[..., :3].astype(np.float64), var[..., :3].astype(np.float64)
    z = heavy_tailed_z(mean, var, HEAVY_SPP, ref, var_ref, n_ref)
    old = _own_variance_z(mean, var, ref, var_ref)
    print(f"{name} (Mitsuba): region z max {np.abs(z).max():.2f}, whole image z {np.round(z[-3:], 2)}; "
          f"with its own variance only: max {np.abs(old).max():.2f}")
    assert np.abs(z).max() < 4.0, np.abs(z).max()


# ------------------------------------------------------------ CLI smoke tests
def _run(module, *argv: str) -> int:
    parser = argparse.ArgumentParser(prog="drpt")
    sub = parser.add_subparsers(dest="command", required=True)
    module.add_parser(sub)
    args = parser.parse_args([module.__name__.rsplit(".", 1)[1], *map(str, argv)])
    return args.func(args)


@pytest.mark.slow
@pytest.mark.mitsuba
def test_converge_cli_smoke(tmp_path, capsys, cornell):
    pytest.importorskip("mitsuba")
    out = tmp_path / "cv"
    assert _run(converge, cornell, "--size", "16", "16", "--max-spp", "8", "--ref-spp", "64",
                "--cache", tmp_path / "cache", "--out", out, "-q") == 0
    text = capsys.readouterr().out
    assert "equal-time error ratio" in text and "time to error" in text
    with open(out / "converge.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["renderer"], int(r["spp"])) for r in rows] == [
        (name, n) for n in (1, 2, 4, 8) for name in ("drpt", "mitsuba")]
    assert all(float(r["seconds"]) > 0 and float(r["rel_mse"]) > 0 for r in rows)
    data = json.loads((out / "converge.json").read_text())
    assert data["reference"]["spp"] == 64 and data["noise_floor"] > 0
    assert {"slopes", "equal_time", "time_to_error", "timing_note"} <= data.keys()
    assert (out / "converge.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1


@pytest.mark.slow
@pytest.mark.mitsuba
def test_converge_takes_an_xml_scene_as_mitsuba_reads_it(tmp_path, monkeypatch, repo):
    """An XML scene: the file's film size and max_depth apply (no flags given), and Mitsuba
    renders the file itself for the reference and for its curve, not drpt's export."""
    pytest.importorskip("mitsuba")
    from drpt.tools import xmlref

    loads = []
    real = xmlref.MitsubaXML.load

    def load(self):
        loads.append(self.path.name)
        return real(self)
    monkeypatch.setattr(xmlref.MitsubaXML, "load", load)
    out = tmp_path / "cv"
    xml = repo / "tests" / "data" / "xml" / "sphere_light.xml"
    assert _run(converge, xml, "--max-spp", "2", "--ref-spp", "16", "--no-cache", "--out", out, "-q") == 0
    data = json.loads((out / "converge.json").read_text())
    assert (data["width"], data["height"], data["max_depth"]) == (32, 24, 4)
    assert loads == ["sphere_light.xml", "sphere_light.xml"]  # the reference, then the curve


def test_converge_rejects_bad_arguments(tmp_path, cornell):
    from drpt.errors import DrptError

    with pytest.raises(DrptError, match="--ref-spp"):
        _run(converge, cornell, "--max-spp", "64", "--ref-spp", "64", "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="--max-spp"):
        _run(converge, cornell, "--max-spp", "0", "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="--levels"):
        _run(converge, cornell, "--levels", "0", "--out", tmp_path / "o")


@pytest.mark.slow
@pytest.mark.mitsuba
def test_knobs_cli_smoke(tmp_path, capsys, cornell):
    pytest.importorskip("mitsuba")
    from drpt.tools import knobs

    out = tmp_path / "kn"
    # (128 spp, a 1024-spp reference: direct light only reads -0.19 here whatever the lanes'
    # random streams; at 32 spp against 256 its one-seed estimate moved between -0.21 and
    # -0.12 with the streams alone, not significant at the lower end)
    assert _run(knobs, cornell, "--size", "16", "16", "--spp", "128", "--ref-spp", "1024",
                "--knobs", "depth", "accel", "--depths", "2", "--repeats", "1",
                "--cache", tmp_path / "cache", "--out", out, "-q") == 0
    text = capsys.readouterr().out
    assert "| max depth | 2 |" in text and "| accel | grid |" in text
    with open(out / "knobs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["knob"], r["setting"]) for r in rows] == [
        ("default", "auto accel, unbounded depth, RR from depth 5 (adaptive), below throughput 0.1 before it"),
        ("max depth", "2"), ("accel", "bvh"), ("accel", "grid")]
    assert {r["rr_threshold"] for r in rows} == {"0.1"}  # (drpt's own format: the default)
    assert all(float(r["seconds"]) > 0 and float(r["samples_per_second"]) > 0 for r in rows)
    # direct light only loses a lot of light: a clear, significant negative bias
    depth2 = rows[1]
    assert float(depth2["mean_bias"]) < -0.1 and depth2["biased"] == "True"
    data = json.loads((out / "knobs.json").read_text())
    assert set(data["references"]) == {"auto"}
    assert (out / "knobs.md").read_text().startswith("# Quality knobs")


def test_knobs_has_an_adaptive_row():
    from drpt.tools.knobs import configs

    rows = configs("phong", knobs=("adaptive",))
    assert [(r.knob, r.adaptive) for r in rows] == [("default", False), ("sampling", True)]


def test_knobs_rows_that_switch_to_independent_samples_say_so():
    """Light tracing (``ptracer``) and adaptive sampling draw independent samples: under a
    default row on another sampler (``auto``'s ldsampler) their rows name that part of their
    change; under an independent default row they do not. bdpt draws from the default row's
    sampler (``auto``: ldsampler, as the path tracer), so its row (the second) never says so."""
    from drpt.tools.knobs import configs

    def switched(sampler):
        rows = configs("phong", knobs=("integrator", "adaptive"), sampler=sampler)
        return [r.setting.endswith("independent samples)") for r in rows[1:]]

    assert switched("ldsampler") == [True, False, True]
    assert switched("independent") == [False, False, False]


def test_knobs_configs_and_bias():
    from drpt.tools.knobs import configs, image_bias

    rows = configs("phong")
    assert rows[0].knob == "default" and rows[0].max_depth == -1 and rows[0].rr_depth == 5
    assert [c.max_depth for c in rows if c.knob == "max depth"] == [2, 3, 5, 8]
    off = [c for c in rows if c.setting.startswith("off")][0]
    assert off.rr_depth > off.max_depth > 0 and off.rr_threshold == 0.0  # roulette never starts
    # the early roulette's thresholds other than the default row's (None: the options')
    assert rows[0].rr_threshold is None
    assert [c.rr_threshold for c in rows if "before depth 5" in c.setting] == [0.0, 0.3]
    assert [c.rr_threshold for c in configs("phong", rr_threshold=0.0) if "before depth 5" in c.setting] == [0.1, 0.3]
    assert [c.bsdf for c in rows if c.knob == "material"] == ["cook-torrance"]
    assert [c.bsdf for c in configs("cook-torrance", knobs=["bsdf"])] == [
        "cook-torrance", "phong"]
    ref = np.ones((4, 4, 3))
    d, se = image_bias(0.9 * ref, np.full_like(ref, 0.01), ref, np.zeros_like(ref))
    # the channels taken as perfectly correlated: each channel's s.e. over 16 pixels
    assert d == pytest.approx(-0.1) and se == pytest.approx(np.sqrt(16 * 0.01) / 16)


def test_knobs_bias_is_not_fooled_by_correlated_channels():
    """A gray scene's channels carry the same noise. Summing their variances as if
    independent made the standard error sqrt(3) too small: `knobs --size 32 32 --spp 16`
    read an unbiased setting (RR off) +4.62% +- 1.11% "biased". Unbiased images must be
    flagged at about the 3-sigma rate (0.27%; threshold 3 of 300), a 3% bias always
    (negative control; its z is ~6)."""
    from drpt.tools.knobs import image_bias

    rng = np.random.default_rng(11)
    ref = np.full((16, 16, 3), 0.5)
    sd = 0.04
    var = np.full_like(ref, sd * sd)
    flagged = 0
    for _ in range(300):
        x = ref + rng.normal(0, sd, ref.shape[:2])[..., None]  # one noise for R, G and B
        d, se = image_bias(x, var, ref, np.zeros_like(ref))
        flagged += abs(d) > 3 * se
    assert flagged <= 3
    x = 1.03 * ref + rng.normal(0, sd, ref.shape[:2])[..., None]
    d, se = image_bias(x, var, ref, np.zeros_like(ref))
    assert abs(d) > 3 * se


def test_knobs_rows_for_light_sampler_filter_and_integrator():
    """The knobs of the noise issue: the light sampler, the filter's splatting (only with a
    tent or Gaussian filter), light tracing and bidirectional path tracing, each one row
    changing one option."""
    from drpt.tools.knobs import configs

    rows = configs("auto", ("light", "filter", "integrator"))
    assert [(r.knob, r.light_sampler, r.filter_sampling, r.integrator) for r in rows] == [
        ("default", "mixed", False, "path"), ("light sampler", "uniform", False, "path"),
        ("light sampler", "bvh", False, "path"), ("integrator", "mixed", False, "ptracer"),
        ("integrator", "mixed", False, "bdpt")]
    rows = configs("auto", ("filter",), filtered=True)
    assert [r.knob for r in rows] == ["default", "filter"] and rows[1].filter_sampling


def test_knobs_sampler_rows_are_the_samplers_the_default_row_does_not_use():
    from drpt.tools.knobs import configs

    rows = configs("auto", ("sampler",))
    assert [(r.knob, r.sampler) for r in rows] == [
        ("default", None), ("sampler", "ldsampler"), ("sampler", "zsobol"), ("sampler", "stratified"),
        ("sampler", "multijitter"), ("sampler", "orthogonal")]
    rows = configs("auto", ("sampler",), sampler="zsobol")
    assert [r.sampler for r in rows] == [None, "independent", "ldsampler", "stratified", "multijitter",
                                         "orthogonal"]


@pytest.mark.slow
@pytest.mark.mitsuba
def test_knobs_sampler_row_renders_with_its_sampler(tmp_path, monkeypatch, cornell):
    """The ``sampler`` knob renders each row with its own ``--sampler`` (and the table
    reports each with its error and time)."""
    pytest.importorskip("mitsuba")
    from drpt.render.renderer import Renderer
    from drpt.tools import knobs

    seen = []
    real = Renderer.__init__

    def init(self, scene, options):
        seen.append(options.sampler)
        real(self, scene, options)
    monkeypatch.setattr(Renderer, "__init__", init)
    out = tmp_path / "k"
    assert _run(knobs, cornell, "--size", "16", "16", "--spp", "16", "--ref-spp", "256",
                "--knobs", "sampler", "--repeats", "1", "--out", str(out), "--quiet",
                "--cache", str(tmp_path / "cache")) == 0
    others = ["independent", "zsobol", "stratified", "multijitter", "orthogonal"]
    assert seen == ["auto", *others]  # the default row's auto is ldsampler (the renderer resolves it)
    data = json.loads((out / "knobs.json").read_text())
    assert [r["setting"] for r in data["rows"]][1:] == others
    assert all(r["seconds"] > 0 and np.isfinite(r["excess_rel_mse"]) for r in data["rows"])


def test_knobs_env_compensation_and_triangle_sampling_rows():
    """Each of the two choices has one row, the setting the default row does not take, and
    none where the scene lacks the feature (None)."""
    from drpt.tools.knobs import configs

    both = ("env-compensation", "triangle-sampling")
    assert [r.knob for r in configs("auto", both)] == ["default"]
    rows = configs("auto", both, env_compensation="on", triangle_sampling="area")
    assert [(r.knob, r.env_compensation, r.triangle_sampling) for r in rows] == [
        ("default", None, None), ("env compensation", "off", None),
        ("triangle sampling", None, "solid-angle")]
    rows = configs("auto", both, env_compensation="off", triangle_sampling="solid-angle")
    assert [(r.env_compensation, r.triangle_sampling) for r in rows[1:]] == [("on", None), (None, "area")]


def test_knobs_env_and_triangle_rows_only_where_the_scene_has_them(cornell, repo):
    """An environment map the file leaves to the flag: a row for path tracing, none for light
    tracing (which samples the map by luminance either way) or where the file sets
    ``mis_compensation``; emissive triangles: a row (``auto`` is ``area`` without media),
    none for light tracing or without emissive triangles."""
    from dataclasses import replace

    from drpt.options import RenderOptions
    from drpt.scene import load_scene
    from drpt.tools.knobs import env_compensation_knob, triangle_sampling_knob

    env = load_scene(repo / "tests" / "data" / "xml" / "envmap.xml")
    box = load_scene(cornell)
    opts = RenderOptions()
    assert env_compensation_knob(env, opts) == "on"
    assert env_compensation_knob(env, replace(opts, env_compensation="off")) == "off"
    assert env_compensation_knob(env, replace(opts, integrator="ptracer")) is None
    assert env_compensation_knob(env, replace(opts, env_sampling="uniform")) is None
    sky = next(light for light in env.lights if hasattr(light, "mis_compensation"))
    sky.mis_compensation = False  # the file decides: the flag changes nothing
    assert env_compensation_knob(env, opts) is None
    assert env_compensation_knob(box, opts) is None
    assert triangle_sampling_knob(box, opts) == "area"
    assert triangle_sampling_knob(box, replace(opts, triangle_sampling="solid-angle")) == "solid-angle"
    assert triangle_sampling_knob(box, replace(opts, integrator="bdpt")) is None
    assert triangle_sampling_knob(env, opts) is None  # lit by the sky alone


def test_knobs_no_env_compensation_row_for_a_constant_map(tmp_path, repo):
    """A constant map: compensation leaves it as it is (Mitsuba's rule), the row would be
    the default's; the negative control, a map with a bright half, has its row."""
    from drpt.imageio import write_image
    from drpt.options import RenderOptions
    from drpt.scene import load_scene
    from drpt.tools.knobs import env_compensation_knob

    sky = tmp_path / "sky.exr"
    scene = load_scene(repo / "tests" / "data" / "xml" / "envmap.xml")
    next(light for light in scene.lights if hasattr(light, "mis_compensation")).path = sky
    write_image(sky, np.full((8, 16, 3), 0.7, np.float32))
    assert env_compensation_knob(scene, RenderOptions()) is None
    bright = np.full((8, 16, 3), 0.7, np.float32)
    bright[:4] = 5.0
    write_image(sky, bright)
    assert env_compensation_knob(scene, RenderOptions()) == "on"


@pytest.mark.slow
@pytest.mark.mitsuba
def test_knobs_env_and_triangle_rows_render_with_their_settings(tmp_path, monkeypatch, repo):
    """The ``env-compensation`` and ``triangle-sampling`` rows reach the renderer with their
    settings, and the table reports each with its error and time."""
    pytest.importorskip("mitsuba")
    from drpt.render.renderer import Renderer
    from drpt.tools import knobs

    seen = []
    real = Renderer.__init__

    def init(self, scene, options):
        seen.append((options.env_compensation, options.triangle_sampling))
        real(self, scene, options)
    monkeypatch.setattr(Renderer, "__init__", init)
    # the env map's scene with a small emissive rectangle: both features
    xml = (repo / "tests" / "data" / "xml" / "envmap.xml").read_text().replace(
        "</scene>", '<shape type="rectangle"><transform name="to_world"><scale value="0.3"/>'
        '<translate y="1.5"/></transform><emitter type="area"><rgb name="radiance" value="4"/>'
        "</emitter></shape></scene>")
    scene = tmp_path / "env_tri.xml"
    scene.write_text(xml)
    for name in ("common_sensor.xml", "sky.exr"):
        (tmp_path / name).symlink_to(repo / "tests" / "data" / "xml" / name)
    out = tmp_path / "k"
    assert _run(knobs, scene, "--size", "16", "12", "--spp", "4", "--ref-spp", "64",
                "--knobs", "env-compensation", "triangle-sampling", "--repeats", "1",
                "--out", str(out), "--quiet", "--cache", str(tmp_path / "cache")) == 0
    assert seen == [("on", "auto"), ("off", "auto"), ("on", "solid-angle")]
    data = json.loads((out / "knobs.json").read_text())
    assert [r["knob"] for r in data["rows"]] == ["default", "env compensation", "triangle sampling"]
    assert all(r["seconds"] > 0 and np.isfinite(r["excess_rel_mse"]) for r in data["rows"])


def test_converge_takes_env_compensation_and_triangle_sampling():
    """``converge`` takes the render flags: the two sampling choices reach its options."""
    from drpt.cli.args import options_from_args

    parser = argparse.ArgumentParser()
    converge.add_parser(parser.add_subparsers())
    args = parser.parse_args(["converge", "s.xml", "--env-compensation", "off",
                              "--triangle-sampling", "solid-angle"])
    opts = options_from_args(args, adaptive=False)
    assert (opts.env_compensation, opts.triangle_sampling) == ("off", "solid-angle")
    opts = options_from_args(parser.parse_args(["converge", "s.xml"]), adaptive=False)
    assert (opts.env_compensation, opts.triangle_sampling) == ("on", "auto")


def test_variance_ratio_error_is_the_jackknife_over_rounds(monkeypatch):
    """efficiency_rounds' leave-one-round-out variances equal the variance of the images with
    that round removed (computed again from the same images), and variance_ratio_error is
    the jackknife standard error of the ratio over them. Ways of standard deviation 1 and 2
    over 12 rounds: the ratio near 0.25, its error a few percent of it. Negative controls:
    the leave-one-out variance of another round differs, and below 3 rounds there is no
    error (NaN)."""
    images = {"a": [], "b": []}

    def way(name, sd):
        def render(seed):
            img = np.random.default_rng(seed * 2 + (sd > 1)).normal(5.0, sd, (16, 16, 3))
            if seed < 1000:
                images[name].append(img)
            return img
        return render

    ways = {"a": way("a", 1.0), "b": way("b", 2.0)}
    res = converge.efficiency_rounds(ways, 12, warm_seed=1000)
    for name in ways:
        stack = np.stack(images[name])
        direct = [np.delete(stack, k, 0).var(0, ddof=1).mean() for k in range(12)]
        assert res[name]["loo_variances"] == pytest.approx(direct, rel=1e-9)
        assert res[name]["loo_variances"][0] != pytest.approx(direct[1], rel=1e-6)
    r = np.array(res["a"]["loo_variances"]) / np.array(res["b"]["loo_variances"])
    se = np.sqrt(11 / 12 * np.sum((r - r.mean()) ** 2))
    err = converge.variance_ratio_error(res["a"], res["b"])
    assert err == pytest.approx(se, rel=1e-12)
    assert 0.0 < err < 0.1 * res["a"]["variance"] / res["b"]["variance"]
    two = converge.efficiency_rounds(ways, 2, warm_seed=1000)
    assert two["a"]["loo_variances"] == [] and math.isnan(converge.variance_ratio_error(two["a"], two["b"]))
