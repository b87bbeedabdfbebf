"""gather_splats' sums (drpt/render/film.py): float32 partial sums per source pixel added in
float64 give the float64 sums to float32 rounding, radiance near the float32 maximum, whose
float32 partial sums overflow, is gathered again in float64, and the per-source way gives the
per-receiving-pixel way's sums bit for bit (with one sample or several an iteration of its
loop). lane_sums (the box film's per-pixel sums of a pass's lanes) adds each pixel's lanes
(to within their roundings), each pixel's sum the same bit for bit wherever the pixel lies in
the pass and whatever the pass's size (control: one lane changed changes its pixel's sum
alone); dropped_total adds the lanes' dropped-sample
counts in the kernel that makes them."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Array3f, Float, Float64, UInt32

from drpt.filters import PixelFilter
from drpt.render import film
from drpt.render.film import SplatFilm, _by_source, _gather, _source_groups, gather_splats

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


@pytest.mark.parametrize("flt", [PixelFilter("gaussian", 0.5), PixelFilter("tent", 1.5)])
@pytest.mark.parametrize("moment", [False, True])
def test_per_source_sums_are_the_per_pixel_ones(flt, moment):
    """The per-source way (each source pixel's samples weighted once, partial sums per
    receiving offset; in one group of offset rows and in one row per group) gives
    :func:`_gather`'s sums bit for bit, on a band of rows in the middle of the image, in
    float32 and float64. Negative control: one sample's radiance changed in its last bits
    changes the sums."""
    r0, rows = 2, 4
    x, y, L, ok = _samples(1.0)
    keep = dr.arange(UInt32, dr.width(x)) < rows * W * K
    x, y, L, ok = (dr.gather(type(v), v, dr.arange(UInt32, rows * W * K)) for v in (x, y, L, ok & keep))
    y = y + r0
    R = film._reach(flt)
    for Partial in (Float, Float64):
        want = _gather(flt, W, H, r0, rows, K, x, y, L, ok, moment, Partial)
        for g in ([list(range(-R, R + 1))], [[d] for d in range(-R, R + 1)]):
            got = _by_source(flt, W, H, r0, rows, K, x, y, L, ok, moment, Partial, g)
            assert got[0] == want[0] and all(np.array_equal(a, b) for a, b in zip(got[1:], want[1:]))
    bumped = Array3f(L)
    bumped.x = dr.select(dr.arange(UInt32, dr.width(x)) == 7, L.x * (1.0 + 2.0**-22), L.x)
    off = _by_source(flt, W, H, r0, rows, K, x, y, bumped, ok, moment, Float, [list(range(-R, R + 1))])
    assert not np.array_equal(off[1], want[1])


@pytest.mark.parametrize("k", [5, 6, 8])
def test_per_source_sums_with_several_samples_an_iteration(k, monkeypatch):
    """:func:`_source_partials` adds :func:`_source_step` samples an iteration (a divisor of
    ``k``: 1, 3, 4 here), and its sums are :func:`_gather`'s bit for bit. Negative control: 4
    samples an iteration where 4 does not divide ``k`` (the last iteration reads the next
    pixel's samples) changes them."""
    flt = PixelFilter("gaussian", 0.5)
    n = W * H * k
    rng = PCG32(n, initstate=5)
    pix = dr.arange(UInt32, n) // k
    x = Float(pix % W) + rng.next_float32()
    y = Float(pix // W) + rng.next_float32()
    L = Array3f(rng.next_float32(), rng.next_float32(), 1.0)
    ok = rng.next_float32() < 0.9
    assert film._source_step(k) == {5: 1, 6: 3, 8: 4}[k]
    groups = [list(range(-2, 3))]
    want = _gather(flt, W, H, 0, H, k, x, y, L, ok, True, Float)
    got = _by_source(flt, W, H, 0, H, k, x, y, L, ok, True, Float, groups)
    assert all(np.array_equal(a, b) for a, b in zip(got[1:], want[1:]))
    if k % 4:
        monkeypatch.setattr(film, "_source_step", lambda k: 4)
        off = _by_source(flt, W, H, 0, H, k, x, y, L, ok, True, Float, groups)
        assert not np.array_equal(off[1], want[1])


@pytest.mark.parametrize("flt", [PixelFilter("gaussian", 0.5), PixelFilter("tent", 1.5)])
def test_splat_weights_given_are_the_gathers_own(flt):
    """:func:`film.splat_weights` (the pass's kernel computes them) give :func:`gather_splats`
    the sums it computes itself, bit for bit, with the samples' pixel columns and rows given
    (a band of rows from ``r0`` 2); where the film sums per source pixel (``K`` at least
    ``SOURCE_MIN_SAMPLES``) there are none. Negative control: the weights of positions moved by
    0.01 pixel give other sums."""
    x, y, L, ok = _samples(1.0)
    pix = dr.arange(UInt32, W * H * K) // K
    col, row = pix % W, pix // W + 2
    y = y + 2.0
    own = gather_splats(flt, W, H + 4, 2, H, K, x, y, L, ok, moment=True)
    weights = film.splat_weights(flt, W, H, K, True, col, row, x, y, ok)
    given = gather_splats(flt, W, H + 4, 2, H, K, x, y, L, ok, True, weights)
    assert own[0] == given[0]
    assert all(np.array_equal(a, b) for a, b in zip(own[1:], given[1:]))
    moved = film.splat_weights(flt, W, H, K, True, col, row, x + 0.01, y, ok)
    off = gather_splats(flt, W, H + 4, 2, H, K, x, y, L, ok, True, moved)
    assert not np.array_equal(off[1], own[1])
    assert film.splat_weights(flt, W, H, film.SOURCE_MIN_SAMPLES, True, col, row, x, y, ok) is None


def test_per_source_way_where_it_pays():
    """:func:`_source_groups` sums per source pixel from SOURCE_MIN_SAMPLES samples per pixel
    on, in groups of offset rows within SOURCE_PARTIALS_BYTES, and not where one row does
    not fit."""
    g = PixelFilter("gaussian", 0.5)
    assert _source_groups(g, 192, 192, film.SOURCE_MIN_SAMPLES - 1, True, Float) is None
    assert _source_groups(g, 192, 192, film.SOURCE_MIN_SAMPLES, True, Float) == [[-2, -1, 0, 1, 2]]
    row = 5 * (14 + 16) * 4  # bytes of one row of offsets per source pixel (moment, float32; packed)
    big = film.SOURCE_PARTIALS_BYTES // row  # source pixels of one row's budget
    assert _source_groups(g, big // 2, 1, 16, True, Float) == [[-2, -1], [0, 1], [2]]
    assert _source_groups(g, big + 1, 1, 16, True, Float) is None


@pytest.mark.parametrize("m", [1, 2, 3, 8, 9, 16, 27, 40])
@pytest.mark.parametrize("wide", [False, True])
def test_lane_sums_are_each_pixels_own(m, wide):
    """Each pixel's sums of its ``m`` lanes, bit for bit the same wherever the pixel lies in the
    pass and whatever the pass's size (the bands, chunks and resumed renders of one image add
    the same lanes): read as records (2 to ``film.RECORD_LANES`` lanes, whose offsets in their
    records move with the pixel's place), the lanes added in lane order; else by
    ``dr.block_sum`` (in its own order: the exact sums to within ``m`` roundings). The lanes
    past the pixels' (``film.pass_lanes`` pads to whole records) hold NaN, which no sum may
    read. Control: one lane's value changed in its last bit changes its pixel's sum and no
    other."""
    pixels, C = 37, 5
    rng = np.random.default_rng(m)
    dtype = np.float64 if wide else np.float32
    cols = (rng.standard_normal((C, pixels * m)) * 10.0 ** rng.uniform(-3, 3, (C, pixels * m))).astype(dtype)
    Value = Float64 if wide else Float

    def sums(c):
        p = c.shape[1] // m
        padded = np.full((C, film.pass_lanes(p, m)), np.nan, dtype)
        padded[:, :c.shape[1]] = c
        a, b = film.lane_sums([[Value(x) for x in padded[:2]], [Value(x) for x in padded[2:]]], m, p)
        assert len(a) == 2 and len(b) == 3
        return np.stack([x.numpy() for x in (*a, *b)])

    got = sums(cols)
    blocks = cols.reshape(C, pixels, m)
    if film.by_records(m):
        in_order = np.zeros((C, pixels), dtype)
        for j in range(m):
            in_order = (in_order + blocks[..., j]).astype(dtype)
        np.testing.assert_array_equal(got, in_order)
    else:
        # a sum of m terms in any order: within m roundings of the terms' magnitudes
        bound = m * np.finfo(dtype).eps * np.abs(blocks.astype(np.float64)).sum(-1)
        assert np.all(np.abs(got - blocks.astype(np.float64).sum(-1)) <= bound)
    # the same pixels after 11 others, and pixels 5-9 alone
    before = (rng.standard_normal((C, 11 * m)) * 100.0).astype(dtype)
    shifted = sums(np.concatenate([before, cols], axis=1))
    np.testing.assert_array_equal(shifted[:, 11:], got)
    part = sums(cols[:, 5 * m:10 * m])
    np.testing.assert_array_equal(part, got[:, 5:10])
    if m > 1:  # control
        bumped = cols.copy()
        bumped[0, 7 * m + 1] = np.nextafter(bumped[0, 7 * m + 1], np.inf)
        other = sums(bumped)
        differs = np.flatnonzero((other != got).any(axis=0))
        assert list(differs) in ([7], [])  # a change below the sum's last bit may round away
        bumped[0, 7 * m + 1] += np.abs(cols[0, 7 * m:8 * m]).sum()
        other = sums(bumped)
        assert list(np.flatnonzero((other != got).any(axis=0))) == [7]


def test_pass_lanes_are_whole_records_where_read_as_records():
    """``pass_lanes``: the pixels' lanes, rounded up to whole records where ``lane_sums`` reads
    records (a packet gather reads whole records), not otherwise. Control: an array of lanes
    that is not whole records is refused, not read past its end."""
    assert film.pass_lanes(37, 9) == 336 and film.pass_lanes(40, 9) == 360
    assert film.pass_lanes(37, 1) == 37 and film.pass_lanes(37, 27) == 37 * 27
    with pytest.raises(ValueError, match="lanes"):
        film.lane_sums([[Float(np.ones(37 * 9, np.float32))]], 9, 37)


def test_dropped_total_adds_the_lanes_counts_in_their_kernel():
    """The total of per-lane counts, exact, for counts that are all zero, a few and many, made
    in the kernel that computes the counts: one kernel over the lanes, and no reduction that
    reads a per-lane array (Dr.Jit may launch a memset and a reduction of its threads' copies
    of the one-element total). Control: the same counts evaluated, then summed by ``dr.sum``,
    take a reduction over the lanes."""
    n = 100_003
    for every in (0, 7, 1):
        lane = dr.arange(UInt32, n)
        # (every 0: counts computed in the kernel, none of them above zero)
        flags = dr.select(lane % 5 == 7, UInt32(1), 0) if every == 0 else dr.select(lane % every == 0, lane % 3, 0)
        want = 0 if every == 0 else int(sum(i % 3 for i in range(0, n, every)))
        flags = flags + dr.zeros(UInt32, n)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # (clears it)
        total = film.dropped_total(flags)
        dr.eval(total)
        wide = [e["type"] for e in dr.kernel_history() if e.get("size", 0) >= n]
        assert total.numpy().tolist() == [want] and wide == [dr.KernelType.JIT]
        if every == 7:  # control
            flags = dr.select(lane % every == 0, lane % 3, 0) + dr.zeros(UInt32, n)
            dr.eval(flags)
            other = dr.sum(flags)
            dr.eval(other)
            wide = [e["type"] for e in dr.kernel_history() if e.get("size", 0) >= n]
            assert int(other[0]) == want and len(wide) > 1 and dr.KernelType.JIT in wide
        dr.set_flag(dr.JitFlag.KernelHistory, False)


@pytest.mark.parametrize("k", film.PACKET_SAMPLES)
@pytest.mark.parametrize("flt", [PixelFilter("gaussian", 0.5), PixelFilter("tent", 1.5)])
def test_packet_gather_sums_are_the_loops(k, flt):
    """:func:`film._gather_packets` (a source pixel's ``k`` samples read as one record) gives
    :func:`_gather`'s sums bit for bit, in float32 and float64, on a band of rows (``r0`` 2),
    with the weights computed by the film and given by :func:`film.splat_weights`, and
    :func:`gather_splats` takes it for these ``k``. Negative controls: one sample's radiance
    changed in its last bits changes the sums, and so do weights laid out sample-major (each
    sample's offsets adjacent), which the records would read across samples."""
    r0, n = 2, W * H * k
    rng = PCG32(n, initstate=7)
    pix = dr.arange(UInt32, n) // k
    col, row = pix % W, pix // W + r0
    x = Float(col) + rng.next_float32()
    y = Float(row) + rng.next_float32()
    L = Array3f(rng.next_float32(), rng.next_float32() * 2.0, 1.0)
    ok = rng.next_float32() < 0.9
    weights = film.splat_weights(flt, W, H, k, True, col, row, x, y, ok)
    for Partial in (Float, Float64):
        for moment in (False, True):
            want = _gather(flt, W, H + 4, r0, H, k, x, y, L, ok, moment, Partial)
            for given in (None, weights if moment else None):
                got = film._gather_packets(flt, W, H + 4, r0, H, k, x, y, L, ok, moment, Partial, given)
                assert got[0] == want[0] and all(np.array_equal(a, b) for a, b in zip(got[1:], want[1:]))
    calls = []
    real = film._gather_packets

    def spy(*a):
        calls.append(a[5])
        return real(*a)

    film._gather_packets = spy
    try:
        gather_splats(flt, W, H + 4, r0, H, k, x, y, L, ok, moment=True)
    finally:
        film._gather_packets = real
    assert calls == [k]
    want = _gather(flt, W, H + 4, r0, H, k, x, y, L, ok, True, Float)
    bumped = Array3f(L)
    counts = int(np.flatnonzero(ok.numpy())[3])  # a sample that counts
    bumped.x = dr.select(dr.arange(UInt32, n) == counts, L.x * (1.0 + 2.0**-22), L.x)
    off = film._gather_packets(flt, W, H + 4, r0, H, k, x, y, bumped, ok, True, Float)
    assert not np.array_equal(off[1], want[1])
    side = 2 * film._reach(flt) + 1
    # the same values, each sample's offsets adjacent (element s side + e)
    swapped = tuple(dr.gather(Float, w, (dr.arange(UInt32, n * side) % side) * n + dr.arange(UInt32, n * side) // side)
                    for w in weights)
    off = film._gather_packets(flt, W, H + 4, r0, H, k, x, y, L, ok, True, Float, swapped)
    assert not np.array_equal(off[1], want[1])
