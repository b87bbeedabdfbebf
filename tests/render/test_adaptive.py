"""Adaptive sampling (``--adaptive``, :mod:`drpt.render.adaptive`).

Unbiasedness by the block z-test at high spp: ``K`` independent adaptive renders
(seeds 100..) of the Cornell box at 16x16, 8 spp each (pilots of 2 samples: the
allocation is as noisy as it gets, so a biased estimator shows most), averaged, against
a uniform render of ``4 K 8`` spp. Each 4x4 block and channel gives ``z`` = difference
of the means over the combined standard error (the adaptive side's from the spread of
the ``K`` renders): all 48 within ``|z| < 4`` (each has probability ~6e-5 of exceeding
it by chance) and their mean within 1 (it is ~N(0, 1/48) for independent blocks,
wider with the channels' correlation). The negative control averages each pilot's
samples in with the samples whose count they decided (``reuse_pilot``): biased low,
it fails both (measured: max |z| 5.85, mean z -2.06; the unbiased estimator: 1.55, -0.00 as
shipped, 1.80, -0.36 with the aggressive allocation).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from drpt.options import RenderOptions
from drpt.render import adaptive
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import block_z
from support import REPO

ROOT = REPO
CORNELL = str(ROOT / "scenes" / "cornellbox" / "cornellbox.txt")
N, SPP, K = 16, 8, 128


@pytest.fixture(scope="module")
def cornell():
    scene = load_scene(CORNELL)
    ref = Renderer(scene, RenderOptions(width=N, height=N, spp=SPP * K * 4, seed=7, progress=False)).render()
    return scene, ref


def _z(cornell, reuse: bool):
    scene, ref = cornell
    r = Renderer(scene, RenderOptions(width=N, height=N, spp=SPP, seed=1, progress=False, adaptive=True))
    imgs = np.stack([adaptive.render_adaptive(r.derive(dataclasses.replace(r.opt, seed=100 + k)),
                                              reuse_pilot=reuse).image for k in range(K)]).astype(np.float64)
    z = block_z(imgs.mean(0), imgs.var(0, ddof=1) / K, ref.image.astype(np.float64),
                ref.variance, block=4)
    return np.abs(z).max(), z.mean()


@pytest.mark.slow
@pytest.mark.parametrize("aggressive", [False, True])
def test_adaptive_render_is_unbiased(cornell, aggressive, monkeypatch):
    """The shipped allocation, and the most aggressive one (per pixel, no smoothing, no
    uniform share): unbiased whatever the allocation, as long as pilot A only decides."""
    if aggressive:
        monkeypatch.setattr(adaptive, "SMOOTH", 1)
        monkeypatch.setattr(adaptive, "UNIFORM_SHARE", 0.0)
    zmax, zmean = _z(cornell, reuse=False)
    assert zmax < 4.0 and abs(zmean) < 1.0, (zmax, zmean)


@pytest.mark.slow
def test_reusing_the_pilot_fails_the_z_test(cornell, monkeypatch):
    """Negative control: pilot A's samples averaged in with the ones they sent."""
    monkeypatch.setattr(adaptive, "SMOOTH", 1)
    monkeypatch.setattr(adaptive, "UNIFORM_SHARE", 0.0)
    zmax, zmean = _z(cornell, reuse=True)
    assert zmax > 4.0 and zmean < -1.0, (zmax, zmean)


def test_allocation_follows_the_error_and_keeps_the_budget():
    mean = np.full((8, 8, 3), 0.5)
    var = np.zeros((8, 8, 3))
    var[:, 4:] = 1.0  # the right half is noisy
    n = adaptive.allocate(mean, var, 64 * 10)
    assert n.min() >= 1
    assert n[:, 6:].mean() > 3 * n[:, :2].mean()
    assert abs(n.sum() - 640) <= 64


def test_adaptive_result_counts_its_samples(cornell):
    scene, _ = cornell
    r = Renderer(scene, RenderOptions(width=8, height=8, spp=16, seed=3, progress=False,
                                      adaptive=True)).render()
    assert np.isfinite(r.image).all() and np.isfinite(r.variance).all()
    assert abs(r.samples - 8 * 8 * 16) <= 0.25 * 8 * 8 * 16  # (a budget of work, not of samples)
    assert r.image.mean() > 0


@pytest.mark.parametrize("flags, message", [
    (["--spp", "4"], "--adaptive needs --spp of at least 8"),
    (["--sampler", "zsobol"], "--sampler must be independent"),
    (["--filter", "tent"], "box filter"),
    (["--integrator", "ptracer"], "path or volpath"),
    (["--time-limit", "1"], "--target-error or --time-limit"),
    (["--workers", "2"], "--workers, --cluster and --resume"),
])
def test_unsupported_options_are_one_line_errors(tmp_path, flags, message):
    p = subprocess.run([sys.executable, "-m", "drpt", "render", CORNELL, "--size", "8", "8",
                        "--spp", "16", "--adaptive", "--quiet", "--output", str(tmp_path / "x.exr"),
                        *flags], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("drpt: error:") and message in lines[0], p.stderr
