"""Filter importance sampling of a pixel's sample positions (device side).

:func:`sample_position` places a sample of pixel ``(i, j)`` of a ``W x H``
image at ``(i + 1/2 + dx, j + 1/2 + dy)`` with ``dx`` and ``dy`` drawn
independently from the pixel filter truncated to the image (see
:mod:`drpt.filters` for the filters, why the truncation, and what this does
to noise). Per axis, with ``c`` the pixel center and ``r`` the filter's
radius, the offset lives on ``T = [max(-c, -r), min(N - c, r)]`` (``N`` the
image's width or height): the positions of the image that the filter
reaches. Interior pixels have ``T = [-r, r]``.

``tent``
    Exact inversion of the truncated CDF: with ``F(t) = (t + r)^2 / (2 r^2)``
    for ``t <= 0`` and ``1 - (r - t)^2 / (2 r^2)`` for ``t >= 0``,
    ``v = F(lo) + u (F(hi) - F(lo))`` and ``x = r (sqrt(2 v) - 1)`` if
    ``v < 1/2``, else ``r (1 - sqrt(2 (1 - v)))``. Weight 1.
``gaussian``
    ``w = g - b`` (``g(x) = exp(-x^2 / (2 s^2))``, ``b = g(r)``) has no
    closed-form inverse CDF, so ``x`` is drawn from ``g`` truncated to ``T``
    (exactly, by inverting ``erf``: ``e = erf(lo / (s sqrt 2)) + u (erf(hi /
    (s sqrt 2)) - erf(lo / (s sqrt 2)))``, ``x = s sqrt(2) erfinv(e)``) and
    the sample carries the weight ``(w(x) / g(x)) * G_T / W_T = (1 - exp((x^2
    - r^2) / (2 s^2))) * G_T / (G_T - b |T|)``, ``G_T`` and ``W_T = G_T - b |T|``
    the integrals of ``g`` and ``w`` over ``T`` (``G_T = s sqrt(pi / 2)
    (erf(hi / (s sqrt 2)) - erf(lo / (s sqrt 2)))``). The expectation is
    exactly the truncated, normalized filter's; the weight (``b = exp(-8) =
    3.4e-4`` whatever the stddev) lies in ``[0, 1.00074]`` per axis (``[0,
    1.0015]`` in 2-D) and has mean 1 and variance 7.1e-5 per axis, so it adds
    about 1.4e-4 to a sample's relative variance.

The 2-D weight is the product of the two axes' (``None``, for weight 1,
when neither axis has one). The box filter is not handled here: the renderer
keeps its own uniform jitter for it (the kernel of a box-filtered render is
the one it always was).
"""

from __future__ import annotations

import math

import drjit as dr
from drjit.auto import Float

from ..filters import PixelFilter


def _tent(r: float, u: Float, lo: Float, hi: Float) -> Float:
    inv = 1.0 / (2.0 * r * r)

    def cdf(t):
        return dr.select(t <= 0.0, dr.square(t + r) * inv, 1.0 - dr.square(r - t) * inv)

    fa, fb = cdf(lo), cdf(hi)
    v = dr.fma(u, fb - fa, fa)
    x = dr.select(v < 0.5, r * (dr.safe_sqrt(2.0 * v) - 1.0), r * (1.0 - dr.safe_sqrt(2.0 * (1.0 - v))))
    return dr.clip(x, lo, hi)


def _gaussian(s: float, u: Float, lo: Float, hi: Float) -> tuple[Float, Float]:
    r = 4.0 * s
    k = 1.0 / (s * math.sqrt(2.0))
    b = math.exp(-8.0)
    ea, eb = dr.erf(lo * k), dr.erf(hi * k)
    e = dr.fma(u, eb - ea, ea)
    x = dr.clip(dr.erfinv(e) * (s * math.sqrt(2.0)), lo, hi)
    g_t = (s * math.sqrt(math.pi / 2.0)) * (eb - ea)
    ratio = 1.0 - dr.exp((dr.square(x) - r * r) * (0.5 / (s * s)))
    return x, dr.maximum(ratio, 0.0) * g_t / (g_t - b * (hi - lo))


def sample_offset(flt: PixelFilter, u: Float, lo: Float, hi: Float) -> tuple[Float, Float | None]:
    """An offset from the pixel center on ``[lo, hi]`` (clamped to the filter's
    support here), distributed as the filter truncated to it, and its weight
    (``None``: 1)."""
    r = flt.radius
    lo, hi = dr.maximum(lo, -r), dr.minimum(hi, r)
    if flt.kind == "tent":
        return _tent(r, u, lo, hi), None
    if flt.kind == "gaussian":
        return _gaussian(flt.param, u, lo, hi)
    raise ValueError(f"sample_offset: no sampler for the {flt.kind!r} filter")


def sample_position(flt: PixelFilter, i: Float, j: Float, u1: Float, u2: Float,
                    width: int, height: int) -> tuple[Float, Float, Float | None]:
    """The image position ``(x, y)`` of a sample of pixel ``(i, j)`` (pixel
    indices as Float) drawn from ``flt`` truncated to the ``width x height``
    image, and its weight (``None``: 1)."""
    cx, cy = i + 0.5, j + 0.5
    dx, wx = sample_offset(flt, u1, -cx, width - cx)
    dy, wy = sample_offset(flt, u2, -cy, height - cy)
    weight = None if wx is None else wx * wy
    return cx + dx, cy + dy, weight
