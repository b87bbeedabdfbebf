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
from drjit.auto import Array3f, Bool, Float, Float64, Int32, UInt32

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
                  px: Float, py: Float, L: Array3f, ok: Bool, moment: bool = False):
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
    Returns ``(y0, sum, sumsq, weight)`` as :meth:`SplatFilm.arrays` (rows from ``y0``)."""
    import numpy as np

    out = _gather(flt, width, height, r0, rows, k, px, py, L, ok, moment, Float)
    if not all(np.isfinite(a).all() for a in out[1:]):  # (radiance near the float32 maximum)
        out = _gather(flt, width, height, r0, rows, k, px, py, L, ok, moment, Float64)
    return out


@loops_once
@dr.syntax
def _gather(flt: PixelFilter, width: int, height: int, r0: int, rows: int, k: int,
            px: Float, py: Float, L: Array3f, ok: Bool, moment: bool, Partial: type):
    """:func:`gather_splats` with partial sums (per source pixel) of type ``Partial``
    (``Float`` or ``Float64``): an outer loop over the source pixels, an inner one over
    each one's samples, each recorded once (:func:`~drpt.render.loops.loops_once`)."""
    import numpy as np

    W = width
    R = int(math.ceil(flt.radius + 0.5)) - 1
    y0, y1 = max(0, r0 - R), min(height, r0 + rows + R)
    n = (y1 - y0) * W
    out = dr.arange(UInt32, n)
    ox = Int32(out % W)
    oy = Int32(out // W) + y0
    cx, cy = Float(ox) + 0.5, Float(oy) + 0.5
    side = 2 * R + 1
    kk = dr.opaque(UInt32, k)
    sources = dr.opaque(UInt32, side * side)
    # a plain function, not the filter: the loop would take a dataclass for loop state
    weight = functools.partial(filter_weight, flt)
    channels = 3 + 3 + 2 + (6 if moment else 0)  # sum, squares, weights, channel products

    total = [dr.zeros(Float64, n) for _ in range(channels)]
    src = dr.zeros(UInt32, n)
    # the samples and the counts are read, not changed, and of another width than the loops:
    # outside their state (as loop variables they would make Dr.Jit record each loop again)
    while dr.hint(src < sources, exclude=[px, py, L, ok, kk, sources]):
        sx = ox + Int32(src % side) - R
        sy = oy + Int32(src // side) - R
        inside = (sx >= 0) & (sx < W) & (sy >= r0) & (sy < r0 + rows)
        first = dr.select(inside, UInt32((sy - r0) * W + sx) * kk, 0)
        part = [dr.zeros(Partial, n) for _ in range(channels)]
        j = dr.zeros(UInt32, n)
        while dr.hint(inside & (j < kk), exclude=[px, py, L, ok, kk]):
            lane = first + j
            valid = dr.gather(Bool, ok, lane)
            x = dr.gather(Float, px, lane, valid)
            y = dr.gather(Float, py, lane, valid)
            v = dr.gather(Array3f, L, lane, valid)
            w = Partial(dr.select(valid, weight(cx - x) * weight(cy - y), 0.0))
            r_, g_, b_ = Partial(v.x), Partial(v.y), Partial(v.z)
            a, b, c = r_ * w, g_ * w, b_ * w
            terms = [a, b, c, a * a, b * b, c * c, w, w * w]
            if moment:
                terms += [a * r_, b * g_, c * b_, a * g_, a * b_, b * b_]
            part = [part[i] + terms[i] for i in range(channels)]
            j += 1
        total = [total[i] + Float64(part[i]) for i in range(channels)]
        src += 1
    dr.eval(total)

    def stack(cs):
        return np.stack([c.numpy() for c in cs], axis=-1).reshape(y1 - y0, W, len(cs))

    return y0, stack(total[:3]), stack(total[3:6] + total[8:]), stack(total[6:8])
