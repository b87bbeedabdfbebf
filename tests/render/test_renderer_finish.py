"""finish (drpt/render/renderer.py) of splatted camera samples: the render's own call
(``consume``, in the merge's arrays, every pixel weighted) gives the general case's image,
variance and second moments bit for bit."""

import copy

import numpy as np
import pytest

from drpt.render.chunks import ChunkMerge, plan_chunks
from drpt.render.renderer import finish

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


@pytest.mark.parametrize("channels", [3, 9])
@pytest.mark.parametrize("zero_weight", [False, True])
def test_consuming_finish_is_the_general_one(channels, zero_weight):
    """With ``consume`` (where every pixel has a weight: in place; else the general case)
    the image, variance and moments are those of ``consume=False`` bit for bit. Negative
    control: the variance with the squares' mean taken as ``sumsq * (1 / w2)``, the same in
    exact arithmetic, differs in its bits."""
    m = _weighted(channels, zero_weight)
    want = finish(copy.deepcopy(m), 1.0, 0.0, consume=False)
    got = finish(copy.deepcopy(m), 1.0, 0.0, consume=True)
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
