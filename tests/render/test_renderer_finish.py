"""finish (drpt/render/renderer.py) of splatted camera samples: the render's own call
(``consume``, in the merge's arrays) gives the image, variance and second moments of
``consume=False`` bit for bit; of a box film's samples (with the moment integrator's
products too), both are the definition written out, bit for bit. all_finite, the check
of a pass's float32 sums for overflow."""

import copy

import numpy as np
import pytest

from drpt.render import renderer
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


def _plain(channels: int) -> ChunkMerge:
    rng = np.random.default_rng(channels)
    m = ChunkMerge(plan_chunks(W, H, 27, 1 << 20, None))
    m.next = m.chunks.count
    m.sum = rng.random((H, W, 3)) * 27.0
    m.sumsq = rng.random((H, W, channels)) * 27.0
    m.sumsq[::3, ::2, :3] *= 0.01  # a negative variance estimate, clamped to 0
    if channels == 6:
        m.sumsq[..., 3:] -= 13.0  # channel products of either sign
    return m


@pytest.mark.parametrize("channels", [3, 6])
def test_finish_of_a_pixels_own_samples_is_its_definition(channels):
    """A box film's merge (each pixel the mean of its own spp samples; with 6 channels the
    moment integrator's products after the squares): the image, variance and second moments
    of ``consume`` and of ``consume=False`` are, bit for bit, the definition written in the
    operations' order (``max(sumsq / spp - mean^2, 0) / max(spp - 1, 1)``). Negative control:
    the variance as ``max(sumsq / spp - mean^2, 0) * spp / max(spp - 1, 1) / spp``, the same in
    exact arithmetic, differs in its bits."""
    m = _plain(channels)
    spp = m.spp
    mean = m.sum / spp
    second = m.sumsq / spp
    var = np.maximum(second[..., :3] - mean * mean, 0.0) / max(spp - 1, 1)
    for consume in (False, True):
        got = finish(copy.deepcopy(m), 1.0, 0.0, consume=consume)
        assert np.array_equal(got.image, mean.astype(np.float32))
        assert np.array_equal(got.variance, var) and got.variance.flags.c_contiguous
        assert (got.moment2 is None) == (channels == 3)
        if channels == 6:
            assert np.array_equal(got.moment2, xyz_second_moment(second))
    other = np.maximum(second[..., :3] - mean * mean, 0.0) * spp / max(spp - 1, 1) / spp
    assert not np.array_equal(other, got.variance)


def _check_all_finite(f) -> None:
    """``f`` is false for a float32 sum that overflowed to +inf, a negative one at -inf and a
    NaN, and true for finite values near the float32 maximum whose float32 sum overflows."""
    near = np.full((4, 5, 3), 3e38, np.float32)
    assert f(near, near[..., :1])
    for bad in (np.inf, -np.inf, np.nan):
        a = near.copy()
        a[2, 3, 1] = bad
        assert not f(near, a) and not f(a)


def test_all_finite_sees_every_overflow_and_no_finite_sum():
    """``all_finite`` (the check that traces a pass again with float64 sums) passes
    :func:`_check_all_finite`. Negative control: a check by the float32 sum
    (``isfinite(a.sum(dtype=float32))``), which takes finite values near the float32 maximum
    for an overflow, fails it."""
    _check_all_finite(renderer.all_finite)

    def by_float32_sum(*arrays):
        with np.errstate(over="ignore"):
            return all(np.isfinite(a.sum(dtype=np.float32)) for a in arrays)

    with pytest.raises(AssertionError):
        _check_all_finite(by_float32_sum)


@pytest.mark.parametrize("channels", [3, 6])
def test_the_renders_own_finish_computes_variance_and_moments_on_first_read(channels, monkeypatch):
    """``consume`` (a render's own result, a film of at most ``DEFER_MAX_PIXELS``): the variance
    and moments are computed when first read, once for both, and are then ``consume=False``'s
    bit for bit; a pickled result holds them computed. Negative controls: ``consume=False``
    and a larger film compute them at once."""
    import pickle

    calls = []
    real = renderer._variance_and_moment
    monkeypatch.setattr(renderer, "_variance_and_moment", lambda *a: calls.append(1) or real(*a))
    m = _plain(channels)
    want = finish(copy.deepcopy(m), 1.0, 0.0, consume=False)
    assert len(calls) == 1  # (the control: at once)
    got = finish(copy.deepcopy(m), 1.0, 0.0, consume=True)
    assert len(calls) == 1 and np.array_equal(got.image, want.image)
    assert np.array_equal(got.variance, want.variance) and len(calls) == 2
    if channels == 6:
        assert np.array_equal(got.moment2, want.moment2)
    else:
        assert got.moment2 is None
    assert len(calls) == 2
    late = finish(copy.deepcopy(m), 1.0, 0.0, consume=True)
    back = pickle.loads(pickle.dumps(late))
    assert len(calls) == 3 and np.array_equal(back.variance, want.variance)
    assert isinstance(back.__dict__["_variance"], np.ndarray)
    # a film above DEFER_MAX_PIXELS computes them at once (the same values)
    monkeypatch.setattr(renderer, "DEFER_MAX_PIXELS", H * W - 1)
    big = finish(copy.deepcopy(m), 1.0, 0.0, consume=True)
    assert len(calls) == 4 and np.array_equal(big.variance, want.variance)
