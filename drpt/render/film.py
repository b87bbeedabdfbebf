"""A film that samples are splatted into: light tracing's image.

A camera path belongs to one pixel, and the renderer sums each pixel's own
samples (:mod:`drpt.render.renderer`). A light path lands wherever its
vertices project, so :class:`SplatFilm` adds each contribution into the
pixels around its image position ``(x, y)`` (continuous, from the image's
top-left corner) with Dr.Jit's ``scatter_reduce``, as Mitsuba's
``ImageBlock.put`` does for its particle tracer:

* the box filter adds it to the pixel that contains ``(x, y)``;
* a tent or Gaussian filter (:mod:`drpt.filters`) adds ``value * w_i / sum(w)``
  to every pixel ``i`` whose center lies within the filter's radius, with
  ``w_i`` the product of the filter's values along both axes at the offset
  from the pixel's center; the sum runs over the whole window, pixels outside
  the image included (their share is dropped), so the weights of one
  contribution sum to 1 inside the image.

It keeps per pixel the sum of the contributions and the sum of their squares
(float32, on the device); :meth:`arrays` returns them as ``(H, W, 3)`` numpy
arrays. The film's arrays are written by scatters inside the tracing kernel,
so one film takes one pass's contributions.
"""

from __future__ import annotations

import math

import drjit as dr
from drjit.auto import Array3f, Bool, Float, Int32, UInt32

from ..filters import PixelFilter


class SplatFilm:
    def __init__(self, width: int, height: int, flt: PixelFilter):
        self.width, self.height = width, height
        self.filter = flt
        n = width * height
        self.sum = [dr.zeros(Float, n) for _ in range(3)]
        self.sq = [dr.zeros(Float, n) for _ in range(3)]

    def _weight(self, d: Float) -> Float:
        f = self.filter
        if f.kind == "tent":
            return dr.maximum(0.0, 1.0 - dr.abs(d) / f.param)
        s = f.param
        return dr.maximum(0.0, dr.exp(-d * d / (2.0 * s * s)) - f.cutoff)

    def _add(self, index: UInt32, value: Array3f, active: Bool) -> None:
        for c in range(3):
            v = value[c]
            dr.scatter_reduce(dr.ReduceOp.Add, self.sum[c], v, index, active)
            dr.scatter_reduce(dr.ReduceOp.Add, self.sq[c], v * v, index, active)

    def put(self, x: Float, y: Float, value: Array3f, active: Bool) -> None:
        """Add ``value`` at image position ``(x, y)`` (lanes where ``active``)."""
        W, H = self.width, self.height
        if self.filter.is_box:
            ix, iy = Int32(dr.floor(x)), Int32(dr.floor(y))
            ok = active & (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
            self._add(UInt32(iy * W + ix), value, ok)
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
        norm = dr.select((sx > 0.0) & (sy > 0.0), dr.rcp(sx * sy), 0.0)
        for j, oy in enumerate(offsets):
            iy = Int32(by) + oy
            row_ok = active & (iy >= 0) & (iy < H)
            for i, ox in enumerate(offsets):
                ix = Int32(bx) + ox
                w = wx[i] * wy[j] * norm
                ok = row_ok & (ix >= 0) & (ix < W) & (w > 0.0)
                self._add(UInt32(iy * W + ix), value * w, ok)

    def arrays(self):
        """``(sum, sum of squares)``, each ``(H, W, 3)`` float32 numpy."""
        import numpy as np

        dr.eval(self.sum, self.sq)
        s = np.stack([c.numpy() for c in self.sum], axis=-1).reshape(self.height, self.width, 3)
        q = np.stack([c.numpy() for c in self.sq], axis=-1).reshape(self.height, self.width, 3)
        return s, q
