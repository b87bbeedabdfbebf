"""gather_splats' sums (drpt/render/film.py): float32 partial sums per source pixel added in
float64 give the float64 sums to float32 rounding, and radiance near the float32 maximum, whose
float32 partial sums overflow, is gathered again in float64."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Array3f, Float, Float64, UInt32

from drpt.filters import PixelFilter
from drpt.render.film import SplatFilm, _gather, gather_splats

W, H, K = 9, 7, 6


def _samples(scale):
    n = W * H * K
    rng = PCG32(n, initstate=3)
    pix = dr.arange(UInt32, n) // K
    x = Float(pix % W) + rng.next_float32()
    y = Float(pix // W) + rng.next_float32()
    L = Array3f(rng.next_float32(), rng.next_float32() * 2.0, 1.0) * scale
    ok = rng.next_float32() < 0.9
    return x, y, L, ok


@pytest.mark.parametrize("flt", [PixelFilter("gaussian", 0.5), PixelFilter("tent", 1.5)])
def test_float32_partial_sums_match_float64_ones(flt):
    """Sums, squares, weights and channel products agree with float64 partial sums to 1e-6
    relative (float32 rounding of six-sample partial sums), and a second call gives the
    same bits (a fixed order). Negative control: the samples at 1.001 times the radiance
    differ by more than the bound."""
    x, y, L, ok = _samples(1.0)
    _, s, q, w = gather_splats(flt, W, H, 0, H, K, x, y, L, ok, moment=True)
    _, s64, q64, w64 = _gather(flt, W, H, 0, H, K, x, y, L, ok, True, Float64)
    for a, b in ((s, s64), (q, q64), (w, w64)):
        assert np.allclose(a, b, rtol=1e-6, atol=0.0)
    again = gather_splats(flt, W, H, 0, H, K, x, y, L, ok, moment=True)
    assert all(np.array_equal(a, b) for a, b in zip(again[1:], (s, q, w)))
    _, off, _, _ = gather_splats(flt, W, H, 0, H, K, x, y, L * 1.001, ok)
    assert not np.allclose(off, s64, rtol=1e-6, atol=0.0)


def test_radiance_near_float32_max_is_gathered_in_float64():
    """Samples of 3e38 (finite in float32; their squares and sums are not): the gathered
    sums are finite and those of the scattering float64 film. Negative control: float32
    partial sums alone overflow."""
    flt = PixelFilter("gaussian", 0.5)
    x, y, L, ok = _samples(1.5e38)
    _, s, q, w = gather_splats(flt, W, H, 0, H, K, x, y, L, ok, moment=True)
    film = SplatFilm(W, H, flt, weights=True, moment=True)
    film.put(x, y, L, ok)
    fs, fq, fw = film.arrays()
    for a, b in ((s, fs), (q, fq), (w, fw)):
        assert np.all(np.isfinite(a)) and np.allclose(a, b, rtol=1e-5, atol=0.0)
    _, s32, q32, _ = _gather(flt, W, H, 0, H, K, x, y, L, ok, True, Float)
    assert not (np.isfinite(s32).all() and np.isfinite(q32).all())
