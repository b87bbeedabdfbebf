"""Pixel reconstruction filters: Mitsuba 3's ``box``, ``tent`` and ``gaussian``.

This module is the host side (Python and numpy, no Dr.Jit): the filter
vocabulary, :func:`parse_filter` for ``--filter``, the filter functions
themselves (:meth:`PixelFilter.eval`, for tests and documentation) and the
Mitsuba ``rfilter`` the exporter writes. The renderer splats samples
through them (:mod:`drpt.render.film`), or with ``--filter-sampling``
samples them (:mod:`drpt.render.filter_sampling`).

The filters (1-D; the 2-D filter is the product ``w(dx) w(dy)``, separable,
as in Mitsuba; ``x`` is the offset from the pixel center in pixels)
------------------------------------------------------------------------
``box``       ``w(x) = 1`` on ``[-1/2, 1/2)``: the pixel's own square (radius
              1/2). drpt's default, and the seed's.
``tent``      ``w(x) = max(0, 1 - |x| / r)``, ``r = radius`` (Mitsuba's
              default 1).
``gaussian``  ``w(x) = max(0, exp(-x^2 / (2 s^2)) - exp(-r^2 / (2 s^2)))``,
              ``s = stddev`` (Mitsuba's default 0.5), ``r = 4 s``: the
              Gaussian shifted down to reach 0 at its cut-off radius.
              Mitsuba's CUDA variants evaluate exactly this; on the CPU a
              degree-9 polynomial fit of it (``gaussian.cpp``, off by at most
              4.2e-4 of the peak; the step response of the normalized
              filter, the quantity an image shows at an edge, differs by at
              most 4.3e-5 of the edge's contrast, measured at stddev 0.25,
              0.5 and 1). drpt uses the exact function.

Mitsuba's JIT variants (``llvm_ad_rgb``, the reference here, and CUDA) call
the filter's ``eval`` for every splat; only its scalar variants splat with
a table (``eval_discretized``: 31 steps over ``[0, r)``, piecewise
constant, ``MI_FILTER_RESOLUTION``). drpt follows the JIT variants. For
the box filter Mitsuba's film skips the filter altogether: a sample counts
in full in the pixel it falls in, as in drpt.

What a pixel is
---------------
Mitsuba's ``hdrfilm`` with a non-box filter *splats*: a sample at image
position ``p`` (uniform in its pixel; every pixel gets ``spp`` samples, and
with the default ``sample_border=false`` only pixels of the image are
sampled) adds ``w(c - p) L`` and ``w(c - p)`` to every pixel center ``c``
within the filter's reach, and the developed pixel is the ratio
``sum w L / sum w``. As ``spp`` grows the ratio converges to

    I(c) = integral_A w(c - p) L(p) dp / integral_A w(c - p) dp,

``A = [0, W) x [0, H)`` the image (the numerator and denominator are sums
of ``spp`` i.i.d. terms per pixel area; their ratio has a bias of order
``1 / spp``, Mitsuba's, which vanishes in the limit). Near the border the
filter is therefore *truncated* to the image and renormalized.

drpt does the same by default (:mod:`drpt.render.film`: the samples of a
pass are splatted with Dr.Jit's ``scatter_reduce`` into ``sum w L``, ``sum
w`` and, for the variance, ``sum w^2 L^2`` and ``sum w^2``; the pixel is the
ratio), so its filtered pixels are Mitsuba's, estimator included.

``--filter-sampling`` (``RenderOptions.filter_sampling``) samples ``I(c)``
directly instead, by *filter importance sampling*: each sample of pixel
``c`` is placed at ``c + x`` with ``x`` drawn from the density ``w(x) /
integral_T w`` on ``T = (A - c) intersected with the support``, the
truncated filter; the pixel is the plain mean of its samples. The
expectation is exactly ``I(c)``, with no ``1 / spp`` bias. Plain filter
importance sampling over the whole plane (no truncation) would *not* agree
at the border: it would average in what lies outside the frame, while
Mitsuba normalizes over the inside.

Noise: with splatting a sample feeds several pixels, so each pixel averages
more samples, but neighbours share samples and their noise is correlated.
Where the radiance's mean and its per-sample variance ``v`` do not change
across the filter's footprint, a splatted pixel's variance is about ``v / spp * J`` with
``J = (integral w^2) / (integral w)^2`` over the 2-D filter, a filter-
importance-sampled pixel's ``v / spp``: ``J`` is 4/9 for the tent of radius
1 and ``1 / (4 pi s^2)``, 0.32, for the Gaussian of stddev 0.5 (truncation
changes it by < 1%). So at equal spp a filter-importance-sampled pixel's variance is
``1 / J`` times a splatted one's (9/4 for the tent, about 3.1 for the Gaussian),
but independent of each other: averages over regions much larger than the
filter have the same variance in both. A splatted pixel's variance estimate
is that of a weighted mean (:func:`drpt.render.renderer.finish`); a
filter-importance-sampled pixel's is the plain sample variance of its own
samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import DrptError

FILTERS = ("box", "tent", "gaussian")

# Mitsuba's parameter of each filter, its default, and drpt's allowed range:
# up to 64 pixels of reach (a larger filter is a blur, not a pixel filter).
PARAMETERS = {"tent": ("radius", 1.0, 1e-3, 64.0), "gaussian": ("stddev", 0.5, 1e-3, 16.0)}


@dataclass(frozen=True)
class PixelFilter:
    """A reconstruction filter: ``kind`` of :data:`FILTERS` and its one
    parameter (the tent's ``radius``, the Gaussian's ``stddev``; 0.5, the
    radius, for the box)."""

    kind: str = "box"
    param: float = 0.5

    @property
    def is_box(self) -> bool:
        """Whether this is the box filter (each sample counts in its own pixel only)."""
        return self.kind == "box"

    @property
    def radius(self) -> float:
        """Half the width of the filter's support, in pixels."""
        if self.kind == "gaussian":
            return 4.0 * self.param
        return self.param

    @property
    def cutoff(self) -> float:
        """The Gaussian's value at its radius, ``exp(-8)``, subtracted from it (0 otherwise)."""
        return math.exp(-8.0) if self.kind == "gaussian" else 0.0

    def eval(self, x) -> np.ndarray:
        """``w(x)`` (float64), Mitsuba's definition (module docs)."""
        x = np.asarray(x, np.float64)
        if self.kind == "box":
            return ((x >= -0.5) & (x < 0.5)).astype(np.float64)
        if self.kind == "tent":
            return np.maximum(0.0, 1.0 - np.abs(x) / self.param)
        s = self.param
        return np.maximum(0.0, np.exp(-x * x / (2.0 * s * s)) - self.cutoff)

    def integral(self, lo, hi) -> np.ndarray:
        """``integral_lo^hi w`` (float64, closed form), for ``lo <= hi``."""
        r = self.radius
        a = np.clip(np.asarray(lo, np.float64), -r, r)
        b = np.clip(np.asarray(hi, np.float64), -r, r)
        if self.kind == "box":
            return b - a
        if self.kind == "tent":
            def cdf(t):  # integral_{-r}^t of the tent
                return np.where(t <= 0, (t + r) ** 2 / (2 * r), r - (r - t) ** 2 / (2 * r))
            return cdf(b) - cdf(a)
        s = self.param
        k = s * math.sqrt(math.pi / 2.0)
        erf = np.vectorize(math.erf)
        return k * (erf(b / (s * math.sqrt(2.0))) - erf(a / (s * math.sqrt(2.0)))) - self.cutoff * (b - a)

    def to_mitsuba(self) -> dict:
        """The Mitsuba 3 ``rfilter`` plugin dict of this filter."""
        if self.kind == "box":
            return {"type": "box"}
        return {"type": self.kind, PARAMETERS[self.kind][0]: float(self.param)}

    def __str__(self) -> str:
        """The ``--filter`` spelling: ``box``, ``tent``, ``gaussian:stddev=0.25``."""
        if self.kind == "box" or self.param == PARAMETERS[self.kind][1]:
            return self.kind
        return f"{self.kind}:{PARAMETERS[self.kind][0]}={self.param!r}"


BOX = PixelFilter()


def parse_filter(text: str) -> PixelFilter:
    """``--filter``'s value: ``box``, ``tent[:radius=R]`` or ``gaussian[:stddev=S]``
    (Mitsuba's plugin and parameter names and defaults). A bad one raises
    :class:`~drpt.errors.DrptError`."""
    usage = "use box, tent[:radius=R] or gaussian[:stddev=S]"
    kind, colon, rest = str(text).strip().partition(":")
    if kind not in FILTERS:
        raise DrptError(f"--filter: unknown filter {text!r} ({usage})")
    if kind == "box":
        if colon:
            raise DrptError(f"--filter: the box filter takes no parameter, got {text!r}")
        return BOX
    name, default, low, high = PARAMETERS[kind]
    value = default
    if colon:
        key, eq, num = rest.partition("=")
        if key.strip() != name or not eq:
            raise DrptError(f"--filter: {kind} takes '{name}=VALUE', got {text!r}")
        try:
            value = float(num)
        except ValueError:
            raise DrptError(f"--filter: {kind} {name} must be a number, got {num.strip()!r}") from None
    if not low <= value <= high:  # also refuses nan
        raise DrptError(f"--filter: {kind} {name} must be between {low:g} and {high:g} pixels, "
                        f"got {value:g}")
    return PixelFilter(kind, value)
