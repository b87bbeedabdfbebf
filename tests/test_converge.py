"""Convergence: drpt's error against every committed Mitsuba reference falls as 1/N;
the ratio computations of ``drpt converge``; converge/knobs CLI smoke tests.

1/N test (``test_error_falls_as_one_over_n``), for every entry of
``drpt.tools.reference.REFERENCES`` (new entries are picked up; a
missing EXR skips):

* the reference is box-downsampled by an integer factor ``f`` to at most
  64 pixels a side (exact: with a box pixel filter, a big pixel's mean is
  the average of its ``f x f`` sub-pixels' means) and drpt renders that size
  at 4, 8, 16, 32, 64 spp, each level with its own seed;
* ``excess = relMSE - floor``; the reference's noise floor
  ``mean(var_ref / (ref^2 + 0.01))`` takes ``var_ref`` from the reference's
  variance EXR where one is committed (references rendered in batches,
  ``variance_path``; downsampled as ``sum / f^4``), else from drpt's own
  per-sample variance over ``ref_spp * f^2`` samples (Mitsuba's per-sample
  variance is close to drpt's; the floor is ~1% of the 64-spp error);
* slope: the least-squares log-log slope of ``excess`` over the 5 levels is
  within 0.25 of -1. The level-to-level scatter of relMSE is heavy tailed
  (caustic fireflies): measured ``excess * N`` varies by up to +-30% on
  newscene between seeds, which puts one standard error of the slope near
  0.09; 0.25 is ~3 of them. (Measured with these seeds: see the printout.)
* bias: for an unbiased renderer ``E[excess_N] = mean(var_N / w)``
  (``var_N`` the variance of the pixel mean, which drpt estimates), a bias
  adds ``mean(bias^2 / w)`` that does not fall with N. So
  ``b = excess_64 - mean(var_64 / w)`` estimates the error left at infinite
  spp, and the error extrapolated to the reference's spp is
  ``excess_64 * 64 / ref_spp + b``. We require ``b <= 0.25 * excess_64``
  at 64 spp (and the mean over levels of ``excess_N / pred_N`` within
  [0.85, 1.15]): a bias whose relMSE is above a quarter of the 64-spp noise
  fails; smaller biases are below what this test can see (measured ratios
  0.91-1.06).

* fireflies: where the top 0.1% of values carry more than half of the
  relMSE at some level (measured: showcase_day 0.67, showcase_dusk 0.99;
  Cornell box and newscene <= 0.2), a single render's relMSE is not in its
  1/N regime at these spp (rare caustic paths through glossy/specular
  surfaces lit by a small bright source dominate; the per-sample
  distribution is so heavy-tailed that relMSE grows with spp between
  seeds). Mitsuba shows the same: on showcase_day at 128x72 and 64 spp
  three seeds gave relMSE 1.5, 2.6 and 0.03 against the reference. There
  the 1/N check is made on the typical pixel instead: the median over
  pixels of the squared relative error must have a log-log slope within
  SLOPE_TOL of -1 (measured: showcase_day -0.98 +- 0.04, showcase_dusk
  -1.02 +- 0.02), after the bias checks above (which hold there since
  drpt's variance estimate sees the same fireflies as the error).

Runtime: 1-3 s per scene at light load, ~4-8 s under load (124 spp at <= 64x64);
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

from conftest import REPO
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

CORNELL = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
LEVELS = (4, 8, 16, 32, 64)
SLOPE_TOL = 0.25
BIAS_FRACTION = 0.25
FIREFLY_SHARE = 0.5
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


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REFERENCES))
def test_error_falls_as_one_over_n(name, reference_scene):
    from drpt.imageio import read_image
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    scene_file, W, H, ref_spp, depth, mode = REFERENCES[name]
    path = reference_path(name)
    if not path.is_file():
        pytest.skip(f"{path.name} is not committed")
    f = _factor(W, H)
    w, h = W // f, H // f
    ref = read_image(path)[..., :3].astype(np.float64)
    ref = ref.reshape(h, f, w, f, 3).mean((1, 3))
    weight = ref * ref + 1e-2

    r = Renderer(reference_scene(scene_file),
                 RenderOptions(width=w, height=h, spp=1, bsdf=mode, progress=False,
                               path=PathOptions(max_depth=depth)))
    results = {}
    for i, spp in enumerate(LEVELS):
        r.opt.spp, r.opt.seed = spp, 4242 + i
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
    slope, se = loglog_slope(LEVELS, excess)
    b = excess[-1] - pred[-1]
    extrapolated = excess[-1] * n_top / ref_spp + b
    ratios = excess / pred
    print(f"{name} {w}x{h}: excess {np.array2string(excess, precision=4)}, "
          f"excess*N {np.array2string(excess * LEVELS, precision=3)}, slope {slope:.3f} "
          f"+- {se:.3f}, floor {floor:.2e}, excess/pred {np.array2string(ratios, precision=3)}, "
          f"bias^2 estimate {b:.2e}, extrapolated at {ref_spp} spp {extrapolated:.2e}")
    print(f"{name}: share of relMSE in the top 0.1% of values per level "
          f"{np.array2string(shares, precision=2)}")
    assert b <= BIAS_FRACTION * excess[-1], (b, excess[-1])
    assert 0.85 <= ratios.mean() <= 1.15, ratios
    if shares.max() > FIREFLY_SHARE:
        # relMSE, a mean, is decided by a handful of rare, bright samples at these
        # spp: its slope is noise (for Mitsuba too). The typical pixel's squared
        # error, the median over pixels, still falls as 1/N if the estimator is
        # consistent: check that instead (the reference's noise is ~1/64 of
        # drpt's at the top level, a ~1.5% effect on the slope).
        med = np.array([np.median(e) for e in errors])
        mslope, mse = loglog_slope(LEVELS, med)
        print(f"{name}: firefly-dominated (top 0.1% share {shares.max():.0%}); median "
              f"squared error {np.array2string(med, precision=3)}, slope {mslope:.3f} "
              f"+- {mse:.3f}")
        assert abs(mslope + 1.0) < SLOPE_TOL, mslope
        return
    assert abs(slope + 1.0) < SLOPE_TOL, slope


# ------------------------------------------------------------ CLI smoke tests
def _run(module, *argv: str) -> int:
    parser = argparse.ArgumentParser(prog="drpt")
    sub = parser.add_subparsers(dest="command", required=True)
    module.add_parser(sub)
    args = parser.parse_args([module.__name__.rsplit(".", 1)[1], *map(str, argv)])
    return args.func(args)


@pytest.mark.slow
@pytest.mark.mitsuba
def test_converge_cli_smoke(tmp_path, capsys):
    pytest.importorskip("mitsuba")
    out = tmp_path / "cv"
    assert _run(converge, CORNELL, "--size", "16", "16", "--max-spp", "8", "--ref-spp", "64",
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


def test_converge_rejects_bad_arguments(tmp_path):
    from drpt.errors import DrptError

    with pytest.raises(DrptError, match="--ref-spp"):
        _run(converge, CORNELL, "--max-spp", "64", "--ref-spp", "64", "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="--max-spp"):
        _run(converge, CORNELL, "--max-spp", "0", "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="--levels"):
        _run(converge, CORNELL, "--levels", "0", "--out", tmp_path / "o")


@pytest.mark.slow
@pytest.mark.mitsuba
def test_knobs_cli_smoke(tmp_path, capsys):
    pytest.importorskip("mitsuba")
    from drpt.tools import knobs

    out = tmp_path / "kn"
    assert _run(knobs, CORNELL, "--size", "16", "16", "--spp", "8", "--ref-spp", "64",
                "--knobs", "depth", "accel", "--depths", "2", "--repeats", "1",
                "--cache", tmp_path / "cache", "--out", out, "-q") == 0
    text = capsys.readouterr().out
    assert "| max depth | 2 |" in text and "| accel | grid |" in text
    with open(out / "knobs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["knob"], r["setting"]) for r in rows] == [
        ("default", "auto accel, unbounded depth, RR from depth 5 (adaptive)"),
        ("max depth", "2"), ("accel", "bvh"), ("accel", "grid")]
    assert all(float(r["seconds"]) > 0 and float(r["samples_per_second"]) > 0 for r in rows)
    # direct light only loses a lot of light: a clear, significant negative bias
    depth2 = rows[1]
    assert float(depth2["mean_bias"]) < -0.15 and depth2["biased"] == "True"
    data = json.loads((out / "knobs.json").read_text())
    assert set(data["references"]) == {"auto"}
    assert (out / "knobs.md").read_text().startswith("# Quality knobs")


def test_knobs_configs_and_bias():
    from drpt.tools.knobs import configs, image_bias

    rows = configs("phong")
    assert rows[0].knob == "default" and rows[0].max_depth == -1 and rows[0].rr_depth == 5
    assert [c.max_depth for c in rows if c.knob == "max depth"] == [2, 3, 5, 8]
    off = [c for c in rows if c.setting.startswith("off")][0]
    assert off.rr_depth > off.max_depth > 0  # roulette never starts
    assert [c.bsdf for c in rows if c.knob == "material"] == ["cook-torrance"]
    assert [c.bsdf for c in configs("cook-torrance", knobs=["bsdf"])] == [
        "cook-torrance", "phong"]
    ref = np.ones((4, 4, 3))
    d, se = image_bias(0.9 * ref, np.full_like(ref, 0.01), ref, np.zeros_like(ref))
    assert d == pytest.approx(-0.1) and se == pytest.approx(np.sqrt(48 * 0.01) / 48)
