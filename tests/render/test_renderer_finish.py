"""finish (drpt/render/renderer.py) of splatted camera samples: the render's own call
(``consume``, in the merge's arrays) gives the image, variance and second moments of
``consume=False`` bit for bit."""

import copy

import numpy as np
import pytest

from drpt.render.chunks import ChunkMerge, plan_chunks
from drpt.render.renderer import finish, xyz_second_moment

H, W = 13, 17


def _weighted(channels: int, zero_weight: bool) -> ChunkMerge:
    rng = np.random.default_rng(channels + zero_weight)
    m = ChunkMerge(plan_chunks(W, H, 27, 1 << 20, None))
    m.next = m.chunks.count
    m.sum = rng.random((H, W, 3))
    m.sumsq = rng.random((H, W, channels)) * 2.0
    m.sumsq[::3, ::2] *= 0.01  # a negative variance estimate, clamped to 0
    m.weight = rng.random((H, W, 2)) + 0.1
    m.weight[::2, :, 1] *= 4.0  # an effective sample count below 2
    if zero_weight:
        m.weight[5, 7, 0] = 0.0
    return m


def _defined(m: ChunkMerge):
    """``finish``'s image, variance and moments of a splatted merge, written as its docstring
    defines them, with ``np.where`` per pixel."""
    ws, ws2 = m.weight[..., :1], m.weight[..., 1:]
    ok = ws > 0.0
    mean = np.where(ok, m.sum / np.where(ok, ws, 1.0), 0.0)
    second = np.where(ok, m.sumsq[..., :3] / np.where(ok, ws2, 1.0), 0.0)
    n_eff = np.where(ok, ws * ws / np.where(ok, ws2, 1.0), 1.0)
    var = np.maximum(second - mean * mean, 0.0) / np.maximum(n_eff - 1.0, 1.0)
    m2 = None
    if m.sumsq.shape[-1] == 9:
        m2 = xyz_second_moment(np.where(ok, m.sumsq[..., 3:] / np.where(ok, ws, 1.0), 0.0))
    return mean.astype(np.float32), var, m2


@pytest.mark.parametrize("channels", [3, 9])
@pytest.mark.parametrize("zero_weight", [False, True])
def test_consuming_finish_is_the_general_one(channels, zero_weight):
    """With ``consume`` (in place, a pixel without weight too) the image, variance and
    moments are those of ``consume=False`` bit for bit, and both are the weighted mean's
    definition (:func:`_defined`: every pixel's own quotients, 0 where no weight). Negative
    control: the variance with the squares' mean taken as ``sumsq * (1 / w2)``, the same in
    exact arithmetic, differs in its bits."""
    m = _weighted(channels, zero_weight)
    want = finish(copy.deepcopy(m), 1.0, 0.0, consume=False)
    got = finish(copy.deepcopy(m), 1.0, 0.0, consume=True)
    image, variance, moment2 = _defined(m)
    assert np.array_equal(want.image, image) and np.array_equal(want.variance, variance)
    if channels == 9:
        assert np.array_equal(want.moment2, moment2)
    assert np.array_equal(got.image, want.image)
    assert np.array_equal(got.variance, want.variance)
    assert (got.moment2 is None) == (want.moment2 is None) == (channels == 3)
    if channels == 9:
        assert np.array_equal(got.moment2, want.moment2)
    if not zero_weight:
        ws, ws2 = m.weight[..., :1], m.weight[..., 1:]
        mean = m.sum / ws
        other = np.maximum(m.sumsq[..., :3] * (1.0 / ws2) - mean * mean, 0.0) / np.maximum(ws * ws / ws2 - 1.0, 1.0)
        assert not np.array_equal(other, want.variance)
