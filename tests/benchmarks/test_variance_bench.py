"""benchmarks/variance_vs_mitsuba.py: its option parsing, the jackknife error and the
per-cell breakdown (on synthetic rounds: no render)."""

from __future__ import annotations

import importlib.util

import numpy as np

from support import REPO

_spec = importlib.util.spec_from_file_location("variance_bench", REPO / "benchmarks" / "variance_vs_mitsuba.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_options_anywhere_on_the_line():
    pos, opts = bench._options(["s.xml", "--grid", "5x3", "box", "0", "--scale", "4", "27"])
    assert pos == ["s.xml", "box", "0", "27"]
    assert opts == {"grid": "5x3", "scale": "4"}
    pos, opts = bench._options(["s.txt", "--bsdf", "phong", "box", "160x120", "--mitsuba-sampler", "independent"])
    assert pos == ["s.txt", "box", "160x120"] and opts == {"bsdf": "phong", "mitsuba-sampler": "independent"}
    assert bench._size("160x120") == (160, 120) and bench._size("96") == (96, 96)


def _rounds(rng, scale):
    """16 rounds of an 8x10 image; column block 2 (of 5) has ``scale`` times the noise."""
    x = rng.normal(size=(16, 8, 10, 3))
    x[:, :, 4:6] *= scale
    return x


def test_jackknife_error_is_the_ratios_spread():
    rng = np.random.default_rng(3)
    a, b = _rounds(rng, 1.0), _rounds(rng, 1.0)
    r, e = bench._ratio(a, b), bench._jackknife(a, b)
    assert 0.0 < e < 0.2 and abs(r - 1.0) < 4 * e
    assert bench._jackknife(a, a) < 1e-12  # no spread where the ratio is 1 in every subset


def test_grid_names_the_noisy_cell(capsys):
    rng = np.random.default_rng(4)
    bench._grid(_rounds(rng, 3.0), _rounds(rng, 1.0), "5x2")
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith("(")]
    ratios = {ln.split(":")[0].strip(): float(ln.split(":")[1].split("+-")[0]) for ln in lines}
    assert len(ratios) == 10
    assert ratios["(0, 2)"] > 6 and ratios["(1, 2)"] > 6  # 9x the variance
    assert all(0.5 < v < 2.0 for k, v in ratios.items() if not k.endswith("2)"))


def test_mean_z_of_noise_free_cells():
    """A noise-free pair of cells: z is +-inf where the means differ (the grid lists the
    cell), 0 where they are equal; with noise it is the finite ratio."""
    ones = np.ones((4, 2, 2, 3))
    assert bench._mean_z(ones * 1.5, ones) == np.inf
    assert bench._mean_z(ones, ones * 1.5) == -np.inf
    assert bench._mean_z(ones, ones) == 0.0
    rng = np.random.default_rng(5)
    assert np.isfinite(bench._mean_z(rng.normal(size=(8, 2, 2, 3)), ones))


def test_pixels_not_finite_in_a_round_are_left_out_of_both():
    """A NaN pixel in one of Mitsuba's rounds and an infinite one in one of drpt's: the mask
    keeps the pixels finite in every round of both, and the ratio and grid over it are
    finite and equal to those computed by hand on the other pixels. Negative control: the
    ratio over every pixel is NaN."""
    rng = np.random.default_rng(6)
    a, b = _rounds(rng, 1.0), _rounds(rng, 1.0)
    b[3, 1, 2, 0] = np.nan
    a[5, 7, 9, 2] = np.inf
    mask = bench._scored(a, b)
    assert (~mask).sum() == 2 and not mask[1, 2] and not mask[7, 9]
    keep = np.ones((8, 10), bool)
    keep[1, 2] = keep[7, 9] = False
    want = a[:, keep].var(0, ddof=1).mean() / b[:, keep].var(0, ddof=1).mean()
    assert bench._ratio(a, b, mask) == want and np.isfinite(bench._jackknife(a, b, mask))
    assert np.isnan(bench._ratio(a, b))  # control: every pixel


def test_blocks_are_the_ratios_of_consecutive_rounds():
    """``--blocks N``: each entry is the ratio over rounds ``k N`` to ``k N + N - 1``, so a
    single heavy-tailed pixel (one round in 8 of its ``a`` rounds holds a spike) scatters
    the blocks far apart while identical rounds read 1 in every block."""
    rng = np.random.default_rng(6)
    a, b = rng.normal(size=(32, 4, 4, 3)), rng.normal(size=(32, 4, 4, 3))
    assert bench._blocks(a, a, 8) == [1.0] * 4
    blocks = bench._blocks(a, b, 8)
    assert len(blocks) == 4
    assert blocks == [bench._ratio(a[k:k + 8], b[k:k + 8]) for k in (0, 8, 16, 24)]
    spiky = a.copy()
    spiky[3, 0, 0] += 40.0  # one round's spike: only the first block sees it
    blocks = bench._blocks(spiky, b, 8)
    assert blocks[0] > 3.0 * max(blocks[1:])
    assert bench._blocks(a, b, 5) == [bench._ratio(a[k:k + 5], b[k:k + 5]) for k in (0, 5, 10, 15, 20, 25)]
