"""Pixel reconstruction filters (drpt/filters.py, drpt/render/filter_sampling.py).

* the filter functions equal Mitsuba's ``rfilter`` plugins' ``eval``;
* the sampler's density is the filter truncated to the image: a stratified
  (deterministic) quadrature of each bin's weighted sample mass equals the
  closed-form integral, and a wrong filter parameter or a missing
  truncation fails the same check (negative controls);
* renders with ``--filter tent`` and ``gaussian`` agree with Mitsuba's
  splatting film on an edge-rich scene (block z-test with correlated
  reference pixels, drpt/testing.py); box-filtered drpt against
  Gaussian Mitsuba, a wrong stddev, and filter sampling without the
  truncation at the image border all fail it;
* the noise claim of drpt/filters.py: a filtered drpt pixel is as noisy as a
  box-filtered one, a splatted Mitsuba pixel about J times as noisy (on a
  uniformly noisy image).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drpt.errors import DrptError
from drpt.filters import BOX, PixelFilter, parse_filter
from drpt.options import PathOptions, RenderOptions

TENT, GAUSS = PixelFilter("tent", 1.0), PixelFilter("gaussian", 0.5)


# ------------------------------------------------------------ the vocabulary
def test_parse_filter_spellings_and_defaults():
    assert parse_filter("box") is BOX and BOX.radius == 0.5
    assert parse_filter("tent") == TENT and TENT.radius == 1.0
    g = parse_filter(" gaussian ")
    assert g == GAUSS and g.radius == 2.0  # Mitsuba: radius = 4 stddev
    assert parse_filter("tent:radius=1.5") == PixelFilter("tent", 1.5)
    assert parse_filter("gaussian:stddev=0.25").radius == 1.0
    for f in (BOX, TENT, GAUSS, PixelFilter("tent", 1.5), PixelFilter("gaussian", 0.25)):
        assert parse_filter(str(f)) == f
    assert str(GAUSS) == "gaussian" and str(PixelFilter("tent", 2.0)) == "tent:radius=2.0"
    assert GAUSS.to_mitsuba() == {"type": "gaussian", "stddev": 0.5}
    assert PixelFilter("tent", 1.5).to_mitsuba() == {"type": "tent", "radius": 1.5}
    assert BOX.to_mitsuba() == {"type": "box"}


@pytest.mark.parametrize("text, needle", [
    ("lanczos", "unknown filter"), ("", "unknown filter"), ("box:radius=1", "takes no parameter"),
    ("tent:stddev=1", "takes 'radius=VALUE'"), ("gaussian:0.3", "takes 'stddev=VALUE'"),
    ("tent:radius=wide", "must be a number"), ("tent:radius=0", "between"),
    ("gaussian:stddev=-1", "between"), ("gaussian:stddev=nan", "between"),
    ("tent:radius=1e9", "between"),
])
def test_parse_filter_errors_are_one_line(text, needle):
    with pytest.raises(DrptError, match=needle) as e:
        parse_filter(text)
    assert "\n" not in str(e.value) and str(e.value).startswith("--filter")


def test_filter_flag_and_options(capsys):
    import argparse

    from drpt.cli.args import add_render_flags, options_from_args

    p = argparse.ArgumentParser()
    add_render_flags(p)
    assert options_from_args(p.parse_args([])).filter == "box"
    o = options_from_args(p.parse_args(["--filter", "gaussian:stddev=0.3"]))
    assert o.pixel_filter == PixelFilter("gaussian", 0.3)
    with pytest.raises(DrptError, match="--filter: unknown filter 'mitchell'"):
        options_from_args(p.parse_args(["--filter", "mitchell"]))
    with pytest.raises(DrptError, match="--filter"):
        RenderOptions(filter="tent:radius=-2").validate()


@pytest.mark.slow
def test_filter_on_the_command_line(tmp_path, cornell):
    """render and export take --filter; export writes the matching rfilter;
    a bad value is one line, exit status 2, nothing written."""
    import subprocess
    import sys

    from drpt.cli import main

    scene = str(cornell)
    out = tmp_path / "g.exr"
    assert main(["render", scene, "--size", "8", "6", "--spp", "2", "--filter", "gaussian",
                 "-o", str(out), "--quiet"]) == 0 and out.is_file()
    xml = tmp_path / "t.xml"
    assert main(["export", scene, str(xml), "--size", "8", "6", "--spp", "1",
                 "--filter", "tent:radius=1.5"]) == 0
    text = xml.read_text()
    assert '<rfilter type="tent">' in text and '<float name="radius" value="1.5"/>' in text
    bad = tmp_path / "never.png"
    r = subprocess.run([sys.executable, "-m", "drpt", "render", scene, "--filter", "mitchell",
                        "-o", str(bad)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0, r.stderr
    assert "--filter: unknown filter 'mitchell'" in r.stderr and not bad.exists()


@pytest.mark.parametrize("flt", [TENT, GAUSS, PixelFilter("tent", 2.5), PixelFilter("gaussian", 0.3)])
def test_integral_is_the_integral_of_eval(flt):
    r = flt.radius
    x = np.linspace(-r, r, 400001)
    w = flt.eval(x)
    assert w.min() >= 0 and flt.eval([-r * 1.01, r * 1.01]).max() == 0
    quad = np.trapezoid(w, x)
    assert abs(flt.integral(-r, r) - quad) < 1e-8 * quad
    lo, hi = -0.3 * r, 0.7 * r
    sel = (x >= lo) & (x <= hi)
    assert abs(flt.integral(lo, hi) - np.trapezoid(w[sel], x[sel])) < 1e-4 * quad


def test_splatting_noise_factor_J():
    """The docs' J = (integral w^2) / (integral w)^2 of the 2-D filter."""
    for flt, expect in ((TENT, 4 / 9), (GAUSS, 1 / math.pi)):
        x = np.linspace(-flt.radius, flt.radius, 200001)
        w = flt.eval(x)
        j = (np.trapezoid(w * w, x) / np.trapezoid(w, x) ** 2) ** 2
        assert abs(j - expect) < 0.01 * expect, (flt, j)


# ------------------------------------------------------------ against Mitsuba's plugins
@pytest.mark.mitsuba
def test_filter_functions_equal_mitsubas():
    mi = pytest.importorskip("mitsuba")
    from drpt.backend import mitsuba_variant

    mi.set_variant(mitsuba_variant())
    for flt in (BOX, TENT, GAUSS, PixelFilter("tent", 1.7), PixelFilter("gaussian", 0.3)):
        m = mi.load_dict(flt.to_mitsuba())
        assert m.radius() == pytest.approx(flt.radius, rel=1e-6)
        x = np.linspace(-1.2 * flt.radius, 1.2 * flt.radius, 4801)
        if flt.is_box:  # away from the jumps at +-1/2 (float32 rounding of x)
            x = x[np.abs(np.abs(x) - 0.5) > 1e-4]
        ours = flt.eval(x)
        theirs = np.asarray(m.eval(mi.Float(x)), np.float64)
        # Mitsuba's LLVM Gaussian is a polynomial fit of exp (drpt/filters.py): 4.2e-4
        tol = 5e-4 if flt.kind == "gaussian" else 1e-6
        assert np.abs(ours - theirs).max() < tol, flt
        if flt.kind == "gaussian":  # ... whose normalized step response is within 5e-5
            a, b = np.cumsum(ours), np.cumsum(theirs)
            assert np.abs(a / a[-1] - b / b[-1]).max() < 5e-5


# ------------------------------------------------------------ the sampler
N = 1 << 20


def _weighted_histogram(flt, lo, hi, edges):
    """Bin masses of N stratified samples of sample_offset on [lo, hi]."""
    import drjit as dr
    from drjit.auto import Float

    from drpt.render.filter_sampling import sample_offset

    u = (dr.arange(Float, N) + 0.5) / N
    x, w = sample_offset(flt, u, dr.full(Float, lo, N), dr.full(Float, hi, N))
    x = np.asarray(x, np.float64)
    w = np.ones_like(x) if w is None else np.asarray(w, np.float64)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(w)) and w.min() >= 0
    r = flt.radius
    assert x.min() >= max(lo, -r) and x.max() <= min(hi, r)
    if flt.kind == "gaussian":
        assert w.max() < 1.00075  # per axis (drpt/render/filter_sampling.py)
    return np.histogram(x, edges, weights=w)[0] / N, w.mean()


def _expected(flt, lo, hi, edges):
    r = flt.radius
    lo, hi = max(lo, -r), min(hi, r)
    a, b = np.clip(edges[:-1], lo, hi), np.clip(edges[1:], lo, hi)
    return flt.integral(a, b) / flt.integral(lo, hi)


# interior pixel, the first pixel (center 0.5 from the edge), the second, a 2-pixel image
INTERVALS = [(-1e4, 1e4), (-0.5, 1e4), (-1.5, 1e4), (-0.5, 1.5)]


@pytest.mark.parametrize("flt", [TENT, GAUSS, PixelFilter("tent", 2.5), PixelFilter("gaussian", 0.3)])
@pytest.mark.parametrize("lo, hi", INTERVALS)
def test_sampled_density_is_the_truncated_filter(flt, lo, hi):
    edges = np.linspace(-flt.radius, flt.radius, 81)
    got, mean_w = _weighted_histogram(flt, lo, hi, edges)
    assert abs(mean_w - 1.0) < 2e-5
    assert np.abs(got - _expected(flt, lo, hi, edges)).max() < 2e-5


def test_sampled_density_check_catches_a_wrong_filter():
    """Negative controls: the same check against a slightly different filter
    (tent radius 1.05, stddev 0.48) or against the untruncated filter fails
    by far more than its tolerance (2e-5)."""
    edges = np.linspace(-2.0, 2.0, 81)
    got, _ = _weighted_histogram(TENT, -1e4, 1e4, edges)
    assert np.abs(got - _expected(PixelFilter("tent", 1.05), -1e4, 1e4, edges)).max() > 1e-3
    got, _ = _weighted_histogram(GAUSS, -1e4, 1e4, edges)
    assert np.abs(got - _expected(PixelFilter("gaussian", 0.48), -1e4, 1e4, edges)).max() > 1e-3
    got, _ = _weighted_histogram(GAUSS, -0.5, 1e4, edges)
    assert np.abs(got - _expected(GAUSS, -1e4, 1e4, edges)).max() > 1e-2


def test_sample_position_covers_the_image_only():
    import drjit as dr
    from drjit.auto import Float, UInt32

    from drpt.render.filter_sampling import sample_position

    n = 1 << 16
    k = dr.arange(UInt32, n)
    u1, u2 = (Float(k % 256) + 0.5) / 256, (Float(k // 256) + 0.5) / 256
    for i, j in ((0, 0), (4, 2), (4, 3)):
        x, y, w = sample_position(GAUSS, dr.full(Float, i, n), dr.full(Float, j, n), u1, u2, 5, 4)
        x, y = np.asarray(x), np.asarray(y)
        assert 0 <= x.min() and x.max() <= 5 and 0 <= y.min() and y.max() <= 4
        assert abs(x.mean() - (i + 0.5)) < 0.5  # centered on the pixel, as far as the image allows
        assert w is not None and abs(np.asarray(w).mean() - 1) < 1e-3


@pytest.mark.parametrize("flt", [PixelFilter("tent", 1e-3), PixelFilter("tent", 64.0),
                                 PixelFilter("gaussian", 1e-3), PixelFilter("gaussian", 16.0)])
@pytest.mark.parametrize("size", [(1, 1), (3, 2), (64, 48)])
def test_extreme_filters_and_tiny_images_sample_finite_positions(flt, size):
    import drjit as dr
    from drjit.auto import Float, UInt32

    from drpt.render.filter_sampling import sample_position

    w, h = size
    n = 4096
    k = dr.arange(UInt32, n)
    u1, u2 = (Float(k % 64) + 0.5) / 64, (Float(k // 64) + 0.5) / 64
    u1[0], u2[0] = 0.0, 0.0  # PCG32 gives exact 0; and nearly 1
    u1[1], u2[1] = 1.0 - 2.0 ** -24, 1.0 - 2.0 ** -24
    for i, j in ((0, 0), (w - 1, h - 1), (w // 2, h // 2)):
        x, y, wt = sample_position(flt, dr.full(Float, i, n), dr.full(Float, j, n), u1, u2, w, h)
        x, y = np.asarray(x), np.asarray(y)
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(y))
        assert 0 <= x.min() and x.max() <= w and 0 <= y.min() and y.max() <= h
        assert np.abs(x - (i + 0.5)).max() <= flt.radius * (1 + 1e-5) + 2e-6 * w  # float32
        if wt is not None:
            wt = np.asarray(wt)
            assert np.all(np.isfinite(wt)) and wt.min() >= 0 and wt.max() < 1.0015
            assert abs(wt.mean() - 1) < 2e-3


# ------------------------------------------------------------ renders against Mitsuba
W = H = 48
SPP = 256
DEPTH = 2


@pytest.fixture(scope="module")
def edge(tmp_path_factory):
    from drpt.scene import load_scene
    from support.scenes import edge_scene

    p = tmp_path_factory.mktemp("filters") / "edges.txt"
    p.write_text(edge_scene())
    return load_scene(p)


@pytest.fixture(scope="module")
def mitsuba(edge):
    """``get(rfilter)``: Mitsuba's batches of the edge scene (cached)."""
    from drpt.testing import mitsuba_runs

    runs = {}

    def get(rfilter):
        if rfilter not in runs:
            runs[rfilter] = mitsuba_runs(edge, W, H, 512, max_depth=DEPTH, seed=5, rfilter=rfilter)
        return runs[rfilter]

    return get


def _drpt(scene, flt, spp=SPP, seed=1, filter_sampling=False):
    from drpt.render.renderer import Renderer

    return Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, filter=flt,
                                         filter_sampling=filter_sampling, progress=False,
                                         path=PathOptions(max_depth=DEPTH))).render()


def _max_z(r, runs, block=4):
    from drpt.testing import block_z_correlated

    assert np.all(np.isfinite(r.image)) and r.nonfinite == 0
    z, f = block_z_correlated(r.image, r.variance, runs, block=block)
    return float(np.abs(z).max()), f


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("flt", ["tent", "gaussian"])
def test_filtered_render_agrees_with_mitsuba(edge, mitsuba, flt):
    z, f = _max_z(_drpt(edge, flt), mitsuba(flt))
    assert z < 4.5, z
    assert np.all(f > 1.2), f  # Mitsuba's splatted pixels are correlated; drpt's are not


@pytest.mark.slow
@pytest.mark.mitsuba
def test_filter_mismatches_fail_the_z_test(edge, mitsuba, monkeypatch):
    """Negative controls on the same scene and statistic: drpt's box against
    Mitsuba's Gaussian, a 16% smaller stddev, and filter importance sampling
    that does not truncate at the image border (so the border pixels see the
    emitters beyond the frame, which Mitsuba's film, sampled inside only,
    does not) all fail."""
    gauss = mitsuba("gaussian")
    assert _max_z(_drpt(edge, "box"), gauss)[0] > 10
    assert _max_z(_drpt(edge, "gaussian:stddev=0.42"), gauss)[0] > 4.5

    import drpt.render.renderer as renderer
    from drpt.render import filter_sampling

    def untruncated(flt, i, j, u1, u2, width, height):
        dx, wx = filter_sampling.sample_offset(flt, u1, i * 0 - 1e6, i * 0 + 1e6)
        dy, wy = filter_sampling.sample_offset(flt, u2, j * 0 - 1e6, j * 0 + 1e6)
        return i + 0.5 + dx, j + 0.5 + dy, wx * wy

    monkeypatch.setattr(renderer, "sample_position", untruncated)
    assert _max_z(_drpt(edge, "gaussian", filter_sampling=True), gauss)[0] > 4.5


# A wall lit by an area light out of view: per-sample noise (light sampling)
# dominates, and its mean and variance hardly change across a filter's footprint.
LIT_WALL = """PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }
Materials { numMaterials 2
  Material { diffuseColor 0.6 0.6 0.6 }
  Material { diffuseColor 0 0 0 Ke 6 6 6 }
}
Group { numObjects 4
  MaterialIndex 0
  Triangle { vertex0 -3 -3 0 vertex1 3 -3 0 vertex2 3 3 0 }
  Triangle { vertex0 -3 -3 0 vertex1 3 3 0 vertex2 -3 3 0 }
  MaterialIndex 1
  Triangle { vertex0 -1 1.2 2.5 vertex1 1 2.2 2.5 vertex2 1 1.2 2.5 }
  Triangle { vertex0 -1 1.2 2.5 vertex1 -1 2.2 2.5 vertex2 1 2.2 2.5 }
}
"""


@pytest.mark.slow
@pytest.mark.mitsuba
def test_noise_per_pixel_filter_importance_sampling_vs_splatting(tmp_path):
    """The noise claim of drpt/filters.py: splatted tent and Gaussian pixels, drpt's
    (its default) and Mitsuba's, are J times as noisy as box pixels (J = 4/9 and
    1/pi), filter-importance-sampled ones (``filter_sampling``) as noisy as box
    pixels (one sample, one pixel), at equal spp, over the interior of a uniformly
    noisy image (drpt: its estimated variance; Mitsuba: across 8 runs)."""
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from drpt.testing import mitsuba_runs

    (tmp_path / "wall.txt").write_text(LIT_WALL)
    scene = load_scene(tmp_path / "wall.txt")
    inner = (slice(4, 28), slice(4, 28))
    var = {}
    for flt in ("box", "tent", "gaussian"):
        def drpt(sampling, flt=flt):
            opts = RenderOptions(width=32, height=32, spp=64, seed=1, filter=flt, filter_sampling=sampling,
                                 progress=False, path=PathOptions(max_depth=2))
            return Renderer(scene, opts).render().variance[inner].mean()

        runs = mitsuba_runs(scene, 32, 32, 512, max_depth=2, seed=5, rfilter=flt)
        var[flt] = drpt(False), drpt(True), runs.var(0, ddof=1)[inner].mean()
    for flt, j in (("tent", 4 / 9), ("gaussian", 1 / math.pi)):
        assert 0.85 * j < var[flt][0] / var["box"][0] < 1.15 * j
        assert 0.9 < var[flt][1] / var["box"][1] < 1.1
        assert 0.85 * j < var[flt][2] / var["box"][2] < 1.15 * j
