"""A film that samples are splatted into: light tracing's image, and camera
samples under a tent or Gaussian pixel filter.

:class:`SplatFilm` adds each contribution into the pixels around its image
position ``(x, y)`` (continuous, from the image's top-left corner) with
Dr.Jit's ``scatter_reduce``, as Mitsuba's ``ImageBlock.put`` does:

* the box filter adds it to the pixel that contains ``(x, y)``;
* a tent or Gaussian filter (:mod:`drpt.filters`) adds ``value * w_i`` to
  every pixel ``i`` whose center lies within the filter's radius, with ``w_i``
  the product of the filter's values along both axes at the offset from the
  pixel's center.

Light tracing (``weights=False``, Mitsuba's particle tracer) divides the
weights of one contribution by their sum over the whole window, pixels
outside the image included (whose share is dropped), and keeps per pixel the
sum of the contributions and of their squares. Camera samples
(``weights=True``, Mitsuba's ``hdrfilm``) keep per pixel ``sum(w L)``,
``sum(w^2 L^2)``, ``sum(w)`` and ``sum(w^2)``: the pixel is ``sum(w L) /
sum(w)`` (Mitsuba's film divides by the accumulated weights) and the other
two estimate its variance (:func:`drpt.render.renderer.finish`). Sums of
passes, chunks and resumed renders add. The renderer computes the camera
samples' sums with :func:`gather_splats` (the same sums, gathered by each
receiving pixel from its neighbours' samples: no atomics, a fixed order),
and uses the scattering :class:`SplatFilm` for light paths, which land
anywhere.

The sums are float64, on the device, over the rows ``[y0, y0 + rows)`` of
the image (a pass of camera samples reaches only the rows around its band);
:meth:`arrays` returns them as numpy arrays. The film's arrays are written by
scatters inside the tracing kernel, so one film takes one pass's
contributions. The scatters are atomic additions from several threads, whose
order varies from run to run: float64 keeps that to the last bits of the
sums, so the float32 image of a light-traced render is the same in one
process, in chunks, on workers and resumed (the variance, float64, to about
1e-12 relative).
"""

from __future__ import annotations

import functools
import math

import drjit as dr
from drjit.auto import Array3f, ArrayXf, ArrayXf64, Bool, Float, Float64, Int32, UInt32

from ..filters import PixelFilter
from .loops import loops_once


def filter_weight(flt: PixelFilter, d: Float) -> Float:
    """The tent's or Gaussian's ``w(d)`` on the device (:meth:`PixelFilter.eval`'s formula)."""
    if flt.kind == "tent":
        return dr.maximum(0.0, 1.0 - dr.abs(d) / flt.param)
    s = flt.param
    return dr.maximum(0.0, dr.exp(-d * d / (2.0 * s * s)) - flt.cutoff)


class SplatFilm:
    """The float64 sums of one pass's splats over the rows ``[y0, y0 + rows)`` of a
    ``width x height`` image (all rows by default), filtered by ``flt``: light tracing's
    with ``weights=False``, camera samples' (with the sums of the weights) with
    ``weights=True``, and, with ``moment`` too, the channels' products for Mitsuba's
    ``moment`` integrator (the module docstring has the sums and their meaning). Without
    ``squares`` (light tracing without a variance estimate) the sums of squares are not
    kept (:meth:`arrays` gives zeros)."""

    def __init__(self, width: int, height: int, flt: PixelFilter, weights: bool = False,
                 y0: int = 0, rows: int | None = None, moment: bool = False, squares: bool = True):
        self.width, self.height = width, height
        self.filter = flt
        self.weights = weights
        self.y0 = y0
        self.rows = height - y0 if rows is None else rows
        n = width * self.rows
        self.sum = [dr.zeros(Float64, n) for _ in range(3)]
        self.sq = [dr.zeros(Float64, n) for _ in range(3)] if squares else []
        self.w = [dr.zeros(Float64, n) for _ in range(2)] if weights else []
        # with moment (camera samples): sum(w L_a L_b) for r^2, g^2, b^2, rg, rb, gb, after sq
        self.moment = [dr.zeros(Float64, n) for _ in range(6)] if moment and weights else []

    def _weight(self, d: Float) -> Float:
        return filter_weight(self.filter, d)

    def _add(self, index: UInt32, value: Array3f, active: Bool, w: Float | None = None) -> None:
        for c in range(3):
            v = Float64(value[c] if w is None else value[c] * w)
            dr.scatter_reduce(dr.ReduceOp.Add, self.sum[c], v, index, active)
            if self.sq:
                dr.scatter_reduce(dr.ReduceOp.Add, self.sq[c], v * v, index, active)
        if self.weights:
            w = Float64(1.0) if w is None else Float64(w)
            dr.scatter_reduce(dr.ReduceOp.Add, self.w[0], w, index, active)
            dr.scatter_reduce(dr.ReduceOp.Add, self.w[1], w * w, index, active)
            if self.moment:
                v = [Float64(value[c]) for c in range(3)]
                products = (v[0] * v[0], v[1] * v[1], v[2] * v[2], v[0] * v[1], v[0] * v[2], v[1] * v[2])
                for target, prod in zip(self.moment, products):
                    dr.scatter_reduce(dr.ReduceOp.Add, target, w * prod, index, active)

    def put(self, x: Float, y: Float, value: Array3f, active: Bool) -> None:
        """Add ``value`` at image position ``(x, y)`` (lanes where ``active``)."""
        W, y0, y1 = self.width, self.y0, self.y0 + self.rows
        if self.filter.is_box:
            ix, iy = Int32(dr.floor(x)), Int32(dr.floor(y))
            ok = active & (ix >= 0) & (ix < W) & (iy >= y0) & (iy < y1)
            self._add(UInt32((iy - y0) * W + ix), value, ok)
            return
        r = self.filter.radius
        reach = int(math.ceil(r))
        bx, by = dr.floor(x - 0.5), dr.floor(y - 0.5)  # the pixels whose centers are left/above
        offsets = range(-reach + 1, reach + 1)
        wx = [self._weight(bx + o + 0.5 - x) for o in offsets]
        wy = [self._weight(by + o + 0.5 - y) for o in offsets]
        sx, sy = wx[0], wy[0]
        for w in wx[1:]:
            sx = sx + w
        for w in wy[1:]:
            sy = sy + w
        if self.weights:
            norm = Float(1.0)
        else:
            norm = dr.select((sx > 0.0) & (sy > 0.0), dr.rcp(sx * sy), 0.0)
        for j, oy in enumerate(offsets):
            iy = Int32(by) + oy
            row_ok = active & (iy >= y0) & (iy < y1)
            for i, ox in enumerate(offsets):
                ix = Int32(bx) + ox
                w = wx[i] * wy[j] * norm
                ok = row_ok & (ix >= 0) & (ix < W) & (w > 0.0)
                self._add(UInt32((iy - y0) * W + ix), value, ok, w)

    def arrays(self):
        """``(sum, sum of squares, weights)``: ``(rows, W, 3)`` float64 numpy arrays
        (with ``moment``, the squares are followed by the 6 ``sum(w L_a L_b)``), and
        with ``weights`` ``(rows, W, 2)`` (``sum(w)``, ``sum(w^2)``), else None."""
        import numpy as np

        dr.eval(self.sum, self.sq, self.w, self.moment)

        def stack(cs):
            return np.stack([c.numpy() for c in cs], axis=-1).reshape(self.rows, self.width, len(cs)
                                                                      ).astype(np.float64)

        sq = stack(self.sq + self.moment) if self.sq else np.zeros((self.rows, self.width, 3), np.float64)
        return stack(self.sum), sq, stack(self.w) if self.weights else None


def gather_splats(flt: PixelFilter, width: int, height: int, r0: int, rows: int, k: int,
                  px: Float, py: Float, L: Array3f, ok: Bool, moment: bool = False,
                  weights: tuple[Float, Float] | None = None):
    """What :class:`SplatFilm` with ``weights`` sums for camera samples, computed per
    *receiving* pixel: no atomics, the same sums in the same order every run.

    The samples are a pass's, pixel-major: lanes ``p k .. p k + k - 1`` are the ``k``
    samples of pixel ``p`` of rows ``r0 .. r0 + rows`` (positions ``px``, ``py`` inside
    that pixel, radiance ``L``, finite, ``ok`` where it counts). A receiving pixel's sums
    run over the samples of the source pixels within ``R = ceil(r + 1/2) - 1`` pixels of
    it (the only ones whose samples its filter of radius ``r`` reaches), in a fixed order:
    each source pixel's ``k`` samples are summed in float32 (cheap: full-width SIMD, no
    conversions), and these partial sums added in float64. Where a float32 partial sum
    (or square) overflows, the pass is gathered again with float64 partial sums.
    Returns ``(y0, sum, sumsq, weight)`` as :meth:`SplatFilm.arrays` (rows from ``y0``).
    ``weights``, where given, are :func:`splat_weights`' arrays of these samples (the
    per-receiving-pixel way then reads them, not ``px`` and ``py``).

    Two ways compute these very sums, bit for bit: each receiving pixel's loop over its
    source pixels' samples (:func:`_gather`: every sample read once per pixel it reaches,
    ``(2R + 1)^2`` times, with its weights along each axis computed beforehand,
    :func:`_axis_weights`; where a pass has :data:`PACKET_SAMPLES` samples per pixel,
    :func:`_gather_packets`, which reads a source pixel's samples as one record), or, where a
    pass has :data:`SOURCE_MIN_SAMPLES` or more samples per pixel and the partial sums fit
    :data:`SOURCE_PARTIALS_BYTES`
    (:func:`_source_groups`), each source pixel's loop over its own samples, which weights
    each sample once for all the pixels it reaches and keeps one partial sum per receiving
    offset (:func:`_by_source`); the receiving pixels then add their neighbours' partial sums."""
    import numpy as np

    def run(Partial):
        groups = _source_groups(flt, width, rows, k, moment, Partial)
        if groups is None:
            gather = _gather_packets if k in PACKET_SAMPLES else _gather
            return gather(flt, width, height, r0, rows, k, px, py, L, ok, moment, Partial, weights)
        return _by_source(flt, width, height, r0, rows, k, px, py, L, ok, moment, Partial, groups)

    out = run(Float)
    # (radiance near the float32 maximum; a NaN or an infinity passes into the largest or
    # smallest value: no temporary per element)
    if not all(np.isfinite(a.max()) and np.isfinite(a.min()) for a in out[1:]):
        out = run(Float64)
    return out


#: the most bytes of partial sums (per source pixel and receiving offset) that
#: :func:`_by_source` holds at once; beyond, it runs its offsets in groups of rows, and where
#: one row does not fit, :func:`gather_splats` gathers per receiving pixel
SOURCE_PARTIALS_BYTES = 1 << 27
#: the fewest samples per pixel of a pass that :func:`gather_splats` sums per source pixel:
#: with fewer, the receiving pixels' reads of each sample cost less than adding up the
#: ``(2R + 1)^2`` partial sums of each channel (measured on the Gaussian of stddev 0.5 with
#: the moment products: docs/performance.md, "Splat gathering per source pixel")
SOURCE_MIN_SAMPLES = 12


def _reach(flt: PixelFilter) -> int:
    """``R``: the filter of radius ``r`` reaches the pixels within ``R = ceil(r + 1/2) - 1``
    pixels of a sample's own, along each axis."""
    return int(math.ceil(flt.radius + 0.5)) - 1


def _receivers(flt: PixelFilter, width: int, height: int, r0: int, rows: int) -> tuple:
    """The pixels that the samples of rows ``[r0, r0 + rows)`` reach through ``flt``: rows
    ``[y0, y1)`` (the band widened by :func:`_reach`, clipped to the image), as
    ``(R, y0, y1, ox, oy)`` with each receiving pixel's column and row (one lane each)."""
    R = _reach(flt)
    y0, y1 = max(0, r0 - R), min(height, r0 + rows + R)
    out = dr.arange(UInt32, (y1 - y0) * width)
    return R, y0, y1, Int32(out % width), Int32(out // width) + y0


def _channels(moment: bool) -> int:
    return 3 + 3 + 2 + (6 if moment else 0)  # sum, squares, weights, channel products


def _terms(w, r, g, b, moment: bool) -> list:
    """One sample's terms of weight ``w`` and radiance ``(r, g, b)``, in the order of
    :func:`_channels`: ``w L``, ``(w L)^2``, ``w``, ``w^2`` and with ``moment`` ``w L_a L_b``
    (rr, gg, bb, rg, rb, gb; both ways of :func:`gather_splats` add these very terms)."""
    wr, wg, wb = r * w, g * w, b * w
    terms = [wr, wg, wb, wr * wr, wg * wg, wb * wb, w, w * w]
    if moment:
        terms += [wr * r, wg * g, wb * b, wr * g, wr * b, wg * b]
    return terms


def _packet(moment: bool) -> int:
    """The channels of a packed partial sum (:func:`_by_source`): :func:`_channels` padded to
    a power of two, for Dr.Jit's packet gathers."""
    return 16 if _channels(moment) > 8 else 8


def _source_groups(flt: PixelFilter, width: int, rows: int, k: int, moment: bool,
                   Partial: type) -> list[list[int]] | None:
    """The receiving rows' offsets ``dy`` (source row minus receiving row, ``-R .. R``) in
    groups that :func:`_by_source` traces one after another, each group's partial sums (as
    the loop leaves them and packed, which are both held while they are packed) within
    :data:`SOURCE_PARTIALS_BYTES`; None where the pass has fewer than
    :data:`SOURCE_MIN_SAMPLES` samples per pixel or one row of offsets does not fit."""
    R = _reach(flt)
    side = 2 * R + 1
    size = 8 if Partial is Float64 else 4
    row_bytes = side * (_channels(moment) + _packet(moment)) * rows * width * size
    per = SOURCE_PARTIALS_BYTES // max(row_bytes, 1)
    if k < SOURCE_MIN_SAMPLES or per < 1:
        return None
    dys = list(range(-R, R + 1))
    return [dys[i:i + per] for i in range(0, side, per)]


def _by_source(flt: PixelFilter, width: int, height: int, r0: int, rows: int, k: int, px: Float,
               py: Float, L: Array3f, ok: Bool, moment: bool, Partial: type, groups: list[list[int]]):
    """:func:`_gather`'s sums, bit for bit, from per-source partial sums: for each group of
    receiving offsets (:func:`_source_groups`, in :func:`_gather`'s order of source pixels),
    one kernel sums each source pixel's samples into one partial sum per offset and channel
    (:func:`_source_partials`: the same float32 additions, in the same order, as
    :func:`_gather`'s inner loop), one packs each offset's channels into one array (a record
    per source pixel, :func:`_packet` wide), and one adds them to the receiving pixels' float64
    sums, in :func:`_gather`'s order."""
    W = width
    R, y0, y1, ox, oy = _receivers(flt, W, height, r0, rows)
    n = (y1 - y0) * W
    side = 2 * R + 1
    channels = _channels(moment)
    total = [dr.zeros(Float64, n) for _ in range(channels)]
    for dys in groups:
        part = _source_partials(flt, W, r0, rows, k, px, py, L, ok, moment, Partial, [-d for d in dys])
        # each offset's channels interleaved, padded to a power of two: the receiving pixels
        # read a source pixel's channels with one packet gather (Dr.Jit's PacketOps: aligned
        # loads and a transpose) instead of a gather per channel, each from an array of its own
        size = _packet(moment)
        ArrayX = ArrayXf64 if Partial is Float64 else ArrayXf
        pad = [Partial(0.0)] * (size - channels)
        packed = [dr.ravel(ArrayX(*part[o * channels:(o + 1) * channels], *pad))
                  for o in range(len(dys) * side)]
        dr.eval(packed)
        del part
        for g, dy in enumerate(dys):
            sy = oy + dy
            for dx in range(-R, R + 1):
                sx = ox + dx
                inside = (sx >= 0) & (sx < W) & (sy >= r0) & (sy < r0 + rows)
                src = UInt32((sy - r0) * W + sx)
                # (the receiving offset is -dx, -dy)
                rec = dr.gather(ArrayX, packed[g * side + R - dx], src, inside, shape=(size, n))
                total = [total[i] + Float64(rec[i]) for i in range(channels)]
        dr.eval(total)
    return (y0, *_interleaved(total, y1 - y0, W))


@loops_once
@dr.syntax
def _source_partials(flt: PixelFilter, width: int, r0: int, rows: int, k: int, px: Float, py: Float,
                     L: Array3f, ok: Bool, moment: bool, Partial: type, fs: list[int]) -> list:
    """For each source pixel of rows ``r0 .. r0 + rows`` and each receiving offset ``(e, f)``
    (the receiving pixel minus the source pixel; ``f`` in ``fs``, ``e`` in ``-R .. R``), the
    sums of its samples' terms as :func:`_gather` adds them for that receiving pixel (``w L``,
    ``(w L)^2``, ``w``, ``w^2`` and with ``moment`` ``w L_a L_b``; ``w`` the filter's weight at
    the receiving pixel's center), of type ``Partial``: a flat list, ``f``-major, then ``e``,
    then the channel. One loop over each pixel's samples (recorded once), which weights a
    sample along each axis once for all the offsets, :func:`_source_step` samples an
    iteration."""
    W = width
    R = _reach(flt)
    npix = rows * W
    p = dr.arange(UInt32, npix)
    sx = Int32(p % W)
    sy = Int32(p // W) + r0
    # the receiving pixels' centers, as _gather computes them from their own row and column
    cxs = [Float(sx + e) + 0.5 for e in range(-R, R + 1)]
    cys = [Float(sy + f) + 0.5 for f in fs]
    kk = dr.opaque(UInt32, k)
    first = p * kk
    weight = functools.partial(filter_weight, flt)
    channels = _channels(moment)
    part = [dr.zeros(Partial, npix) for _ in range(len(fs) * len(cxs) * channels)]
    step = _source_step(k)
    j = dr.zeros(UInt32, npix)
    # the samples and the count are read, not changed, and of another width than the loop
    while dr.hint(j < kk, exclude=[px, py, L, ok, kk]):
        part = _source_terms(part, first + j, step, cxs, cys, weight, px, py, L, ok, moment, Partial)
        j += step
    return part


#: the samples per iteration of :func:`_source_partials`' loop: the first that divides ``k``
#: (:func:`_source_step`)
SOURCE_STEPS = (4, 3, 2)


def _source_step(k: int) -> int:
    """The samples of a pixel that each iteration of :func:`_source_partials`' loop adds, in
    order: the first of :data:`SOURCE_STEPS` that divides ``k`` (every iteration then adds
    whole samples of the pixel), else 1. An iteration costs, beyond its samples' terms, an
    update of every partial sum (``(2R + 1)^2`` offsets times up to 14 channels: the loop
    state), which a few samples per iteration share (docs/performance.md)."""
    return next((u for u in SOURCE_STEPS if k % u == 0), 1)


def _source_terms(part: list, first: UInt32, step: int, cxs: list, cys: list, weight, px: Float,
                  py: Float, L: Array3f, ok: Bool, moment: bool, Partial: type) -> list:
    """``part`` plus the terms of the ``step`` samples from lane ``first``, one after the
    other (:func:`_source_partials`)."""
    for u in range(step):
        lane = first + u
        valid = dr.gather(Bool, ok, lane)
        x = dr.gather(Float, px, lane, valid)
        y = dr.gather(Float, py, lane, valid)
        v = dr.gather(Array3f, L, lane, valid)
        wx = [weight(c - x) for c in cxs]
        wy = [weight(c - y) for c in cys]
        r_, g_, b_ = Partial(v.x), Partial(v.y), Partial(v.z)
        terms = []
        for wf in wy:
            for we in wx:
                terms += _terms(Partial(dr.select(valid, we * wf, 0.0)), r_, g_, b_, moment)
        part = [part[i] + terms[i] for i in range(len(part))]
    return part


def splat_weights(flt: PixelFilter, width: int, rows: int, k: int, moment: bool, x: UInt32,
                  y: UInt32, px: Float, py: Float, ok: Bool) -> tuple[Float, Float] | None:
    """The arrays that :func:`gather_splats` reads besides the radiance where it gathers per
    receiving pixel: :func:`_axis_weights` of the pass's samples (sample ``s`` of pixel
    column ``x`` and row ``y``), unevaluated, so that the kernel that traces the samples
    computes them too (no kernel of their own, which would read ``px``, ``py`` and ``ok``
    back and divide each lane's index by ``k`` again); None where it sums per source pixel
    (:func:`_source_groups`: it reads ``px`` and ``py``)."""
    if _source_groups(flt, width, rows, k, moment, Float) is not None:
        return None
    return _axis_weights(flt, width, 0, k, px, py, ok, Int32(x), Int32(y), evaluate=False)


def _axis_weights(flt: PixelFilter, width: int, r0: int, k: int, px: Float, py: Float, ok: Bool,
                  sx: Int32 | None = None, sy: Int32 | None = None, evaluate: bool = True
                  ) -> tuple[Float, Float]:
    """Each sample's filter weights along each axis at the centers of the ``2R + 1`` columns
    and rows it reaches, for :func:`_gather`: ``w(c_e - x)`` with ``c_e`` the center of column
    ``sx + e`` (``e`` in ``-R .. R``, ``sx`` the sample's own column), 0 where the sample does
    not count (not ``ok``: its weight ``w_x w_y`` is then 0), and ``w(c_e - y)`` along ``y``.
    Two arrays, offset-major (element ``(e + R) n + s`` of ``n`` samples: for each offset the
    samples in lane order, so that a pixel's ``k`` samples' weights at one offset are one
    record of ``k``, :func:`_gather_packets`), evaluated: each sample weighted
    once per axis and offset, not for every receiving pixel, and without a gather of ``ok``
    there (a gather of bytes, which the CPU has no instruction for). ``sx`` and ``sy``, the
    samples' pixel columns and rows (``r0`` included), where the caller has them (else from
    the lane's index, pixel-major); without ``evaluate`` the arrays are returned unevaluated."""
    R = _reach(flt)
    if sx is None:
        n = dr.width(px)
        lane = dr.arange(UInt32, n)
        p = lane // dr.opaque(UInt32, k)
        sx = Int32(p % width)
        sy = Int32(p // width) + r0
    # the receiving pixels' centers, as _source_partials computes them
    wxs = dr.concat([dr.select(ok, filter_weight(flt, (Float(sx + e) + 0.5) - px), 0.0)
                     for e in range(-R, R + 1)])
    wys = dr.concat([filter_weight(flt, (Float(sy + e) + 0.5) - py) for e in range(-R, R + 1)])
    if evaluate:
        dr.eval(wxs, wys)
    return wxs, wys


@loops_once
@dr.syntax
def _gather(flt: PixelFilter, width: int, height: int, r0: int, rows: int, k: int,
            px: Float, py: Float, L: Array3f, ok: Bool, moment: bool, Partial: type,
            weights: tuple[Float, Float] | None = None):
    """:func:`gather_splats` with partial sums (per source pixel) of type ``Partial``
    (``Float`` or ``Float64``): an outer loop over the source pixels, an inner one over
    each one's samples, each recorded once (:func:`~drpt.render.loops.loops_once`), which
    reads each sample's radiance and its two weights for this pixel (:func:`_axis_weights`,
    or ``weights``, :func:`splat_weights`' arrays of the samples)."""
    W = width
    R, y0, y1, ox, oy = _receivers(flt, W, height, r0, rows)
    n = (y1 - y0) * W
    side = 2 * R + 1
    kk = dr.opaque(UInt32, k)
    ns = dr.opaque(UInt32, rows * W * k)  # the pass's samples: the weights' offsets' stride
    sources = dr.opaque(UInt32, side * side)
    channels = _channels(moment)
    wxs, wys = _axis_weights(flt, width, r0, k, px, py, ok) if weights is None else weights

    total = [dr.zeros(Float64, n) for _ in range(channels)]
    src = dr.zeros(UInt32, n)
    # the samples and the counts are read, not changed, and of another width than the loops:
    # outside their state (as loop variables they would make Dr.Jit record each loop again)
    while dr.hint(src < sources, exclude=[wxs, wys, L, kk, ns, sources]):
        sx = ox + Int32(src % side) - R
        sy = oy + Int32(src // side) - R
        inside = (sx >= 0) & (sx < W) & (sy >= r0) & (sy < r0 + rows)
        first = dr.select(inside, UInt32((sy - r0) * W + sx) * kk, 0)
        # this pixel's offset from the source pixel, plus R: the index of its weights
        ex = UInt32(2 * R) - src % side
        ey = UInt32(2 * R) - src // side
        part = [dr.zeros(Partial, n) for _ in range(channels)]
        j = dr.zeros(UInt32, n)
        while dr.hint(inside & (j < kk), exclude=[wxs, wys, L, kk, ns]):
            lane = first + j
            # (a sample that does not count has weight 0, and finite radiance: its terms are 0)
            w = Partial(dr.gather(Float, wxs, ex * ns + lane) * dr.gather(Float, wys, ey * ns + lane))
            v = dr.gather(Array3f, L, lane)
            terms = _terms(w, Partial(v.x), Partial(v.y), Partial(v.z), moment)
            part = [part[i] + terms[i] for i in range(channels)]
            j += 1
        total = [total[i] + Float64(part[i]) for i in range(channels)]
        src += 1
    return (y0, *_interleaved(total, y1 - y0, W))


#: the samples per pixel of a pass for which :func:`gather_splats` (per receiving pixel) reads a
#: source pixel's samples as records (:func:`_gather_packets`): Dr.Jit's packet gathers take a
#: power of two, and :func:`_gather_packets` traces its ``k`` samples' terms one after another
PACKET_SAMPLES = (2, 4, 8)


@loops_once
@dr.syntax
def _gather_packets(flt: PixelFilter, width: int, height: int, r0: int, rows: int, k: int,
                    px: Float, py: Float, L: Array3f, ok: Bool, moment: bool, Partial: type,
                    weights: tuple[Float, Float] | None = None):
    """:func:`_gather`'s sums, bit for bit, for ``k`` in :data:`PACKET_SAMPLES`: the same loop
    over the source pixels, but a source pixel's ``k`` samples are adjacent in each array (its
    radiance's channels, and at each offset its weights along each axis, :func:`_axis_weights`),
    so each is read as one record of ``k`` (Dr.Jit's packet gather: aligned loads and a
    transpose, where :func:`_gather`'s inner loop runs ``k`` gathers of each), and the samples'
    terms are added in the same order, traced one after another."""
    W = width
    R, y0, y1, ox, oy = _receivers(flt, W, height, r0, rows)
    n = (y1 - y0) * W
    side = 2 * R + 1
    npix = dr.opaque(UInt32, rows * W)  # the pass's source pixels: records of k samples
    sources = dr.opaque(UInt32, side * side)
    channels = _channels(moment)
    wxs, wys = _axis_weights(flt, width, r0, k, px, py, ok) if weights is None else weights

    total = [dr.zeros(Float64, n) for _ in range(channels)]
    src = dr.zeros(UInt32, n)
    # (the samples and the counts are read, not changed: outside the loop's state, as _gather's)
    while dr.hint(src < sources, exclude=[wxs, wys, L, npix, sources]):
        sx = ox + Int32(src % side) - R
        sy = oy + Int32(src // side) - R
        inside = (sx >= 0) & (sx < W) & (sy >= r0) & (sy < r0 + rows)
        pixel = dr.select(inside, UInt32((sy - r0) * W + sx), 0)
        ex = UInt32(2 * R) - src % side
        ey = UInt32(2 * R) - src // side
        # (outside the pass the records read 0: terms of 0, as _gather's loop adds none)
        wx = dr.gather(ArrayXf, wxs, ex * npix + pixel, inside, shape=(k, n))
        wy = dr.gather(ArrayXf, wys, ey * npix + pixel, inside, shape=(k, n))
        r_ = dr.gather(ArrayXf, L.x, pixel, inside, shape=(k, n))
        g_ = dr.gather(ArrayXf, L.y, pixel, inside, shape=(k, n))
        b_ = dr.gather(ArrayXf, L.z, pixel, inside, shape=(k, n))
        part = [dr.zeros(Partial, n) for _ in range(channels)]
        for j in range(k):
            terms = _terms(Partial(wx[j] * wy[j]), Partial(r_[j]), Partial(g_[j]), Partial(b_[j]), moment)
            part = [part[i] + terms[i] for i in range(channels)]
        total = [total[i] + Float64(part[i]) for i in range(channels)]
        src += 1
    return (y0, *_interleaved(total, y1 - y0, W))


def _interleaved(total: list, rows: int, width: int) -> tuple:
    """The gathered float64 sums ``total`` (in :func:`_channels`' order) as
    :func:`gather_splats` returns them: the sums, the squares (and channel products) and the
    weights, each ``(rows, width, C)``, interleaved on the device by ``dr.ravel`` (in the
    kernel that computes ``total`` where it is not evaluated yet) and read back as numpy
    views, without a copy on the host."""
    groups = (total[:3], total[3:6] + total[8:], total[6:8])
    tables = [dr.ravel(ArrayXf64(*g)) for g in groups]
    dr.eval(tables)
    return tuple(t.numpy().reshape(rows, width, len(g)) for t, g in zip(tables, groups))


#: values in a record of Dr.Jit's packet gathers, as :func:`lane_sums` reads a pass's lanes
RECORD = 8

#: the most lanes per pixel that :func:`lane_sums` adds from records; above it, Dr.Jit's
#: block sums (docs/performance.md, "A pixel's lanes read as records")
RECORD_LANES = 16


def by_records(m: int) -> bool:
    """Whether :func:`lane_sums` reads ``m`` lanes per pixel as records (from 2 to
    :data:`RECORD_LANES` lanes)."""
    return 2 <= m <= RECORD_LANES


def pass_lanes(pixels: int, m: int) -> int:
    """The lanes of a camera pass of ``pixels`` pixels of ``m`` lanes each: ``pixels m``, rounded
    up to a multiple of :data:`RECORD` where :func:`lane_sums` reads them as records (a packet
    gather reads an array of whole records). The lanes past ``pixels m`` trace nothing."""
    n = pixels * m
    return -(-n // RECORD) * RECORD if by_records(m) else n


def lane_sums(groups: list[list], m: int, pixels: int) -> list:
    """Each pixel's sums of a pass's lanes, a group of channels to an array: the box filter's film.

    ``groups`` are lists of per-lane values of one type (``Float`` or ``Float64``),
    a sum per channel, ``m`` lanes per pixel of ``pixels`` pixels, pixel-major (lanes ``p m ..
    p m + m - 1`` are pixel ``p``'s), :func:`pass_lanes` lanes in all. Returns for each group
    its channels' per-pixel sums, an array a channel (element ``p`` the sum over pixel ``p``'s
    lanes; with ``m`` 1 the channels themselves), which the host reads into the group's
    ``(pixels, C)`` image a channel at a time: a kernel that interleaved them on the device
    (``dr.ravel``) cost more (docs/performance.md).

    Where :func:`by_records`, one kernel adds every channel's lanes (:func:`_record_sums`):
    each pixel reads the aligned records of :data:`RECORD` lanes that its lanes lie in, by
    packet gathers, and adds its own lanes in lane order, ``((l_0 + l_1) + l_2) + ...``.
    Otherwise each channel is a ``dr.block_sum`` of blocks of ``m`` (Dr.Jit's block reduction,
    which adds a block in an order of its own that neither the block's place in the array,
    the pass's size, the CPU's vector width nor the thread count changes). Either way a
    pixel's sum is a function of its own lanes alone, the same in every run, chunk, worker
    and resumed render (``tests/render/test_film.py``), up to the sign of a zero sum, which the
    host's float64 merge makes +0.0. Adding the lanes by a plain gather per lane and channel
    costs more than either (docs/performance.md, "A pixel's lanes read as records")."""
    columns = [c for g in groups for c in g]
    if m == 1:
        sums = columns
    else:
        dr.eval(columns)  # (the path kernel once, not once per channel's sum)
        sums = _record_sums(columns, m, pixels) if by_records(m) else [dr.block_sum(c, m) for c in columns]
    tables, i = [], 0
    for g in groups:
        tables.append(sums[i:i + len(g)])
        i += len(g)
    return tables


def _record_sums(columns: list, m: int, pixels: int) -> list:
    """:func:`lane_sums` by records: pixel ``p``'s lanes start at offset ``o = m p mod 8`` of
    record ``m p // 8`` and fill ``m`` slots from there. A slot of the ``K`` records a pixel
    may reach is added where it is one of the pixel's lanes and 0.0 where not (in the first
    record before ``o``, in the last after ``o + m``): the nonzero terms are the pixel's lanes
    in order, and ``x + 0.0`` is ``x``. The offsets are multiples of ``g = gcd(m, 8)`` up to
    ``8 - g``, so which slots are always, never or sometimes a pixel's is known when tracing:
    only the sometimes slots are selected. An index past the array's last record (read only
    for slots no pixel uses) is clamped to it."""
    n = dr.width(columns[0])
    if n % RECORD != 0 or n < pixels * m:
        raise ValueError(f"lane_sums: {n} lanes for {pixels} pixels of {m} (pass_lanes: {pass_lanes(pixels, m)})")
    o_max = RECORD - math.gcd(m, RECORD)
    K = (o_max + m - 1) // RECORD + 1
    first = dr.arange(UInt32, pixels) * m
    rec0 = first // RECORD
    o = first - rec0 * RECORD
    last = dr.opaque(UInt32, n // RECORD - 1)
    index = [dr.minimum(rec0 + k, last) for k in range(K)]
    sums = []
    for c in columns:
        Rec = ArrayXf64 if isinstance(c, Float64) else ArrayXf
        s = None
        for k in range(K):
            rec = dr.gather(Rec, c, index[k], shape=(RECORD, pixels))
            for j in range(RECORD):
                slot = k * RECORD + j
                if slot >= o_max + m:
                    break  # (no pixel's lane from here on)
                v = rec[j]
                if slot < o_max or slot >= m:  # (a lane of some pixels only)
                    v = dr.select((o <= slot) & (o + m > slot), v, 0.0)
                s = v if s is None else s + v
        sums.append(s)
    return sums


def dropped_total(flags: UInt32) -> UInt32:
    """The sum of the per-lane counts ``flags`` (the non-finite samples a lane dropped), as a
    one-element array added in the kernel that computes them (a masked atomic addition on
    the lanes with a count, so a pass without one stores nothing; integers, so the order of
    the additions does not matter): no per-lane array is written."""
    total = dr.zeros(UInt32, 1)
    dr.scatter_reduce(dr.ReduceOp.Add, total, flags, UInt32(0), active=flags > 0)
    return total
