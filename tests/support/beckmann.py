"""The exact (float64) CDF of the alpha = 1 Beckmann distribution's visible slopes, to
measure how closely a slope sampler inverts it (tests/render/bsdf/test_microfacet.py,
benchmarks/beckmann_sampler_ab.py).

For ``wi = (sin theta, 0, cos theta)``, ``t = tan theta``, the first slope's CDF is
``(1 + erf(x) + t e^(-x^2) / sqrt(pi)) / (1 + erf(cot theta) + t e^(-cot^2 theta) / sqrt(pi))``
(``(1 + erf(x)) / 2`` at ``cos theta = 1``) and the second slope's ``(1 + erf(y)) / 2``;
the sampler's ``u`` is clamped to ``[1e-6, 1 - 1e-6]`` (float32) as Mitsuba's.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from drjit.auto import Array2f, Float
from scipy.special import erf


def grid() -> tuple[np.ndarray, np.ndarray]:
    """A dense grid of ``(cos theta, u)`` (float32, flattened): cos from 1e-3 to 1 and
    near 1, u over [0, 1] and near both ends."""
    ci = np.concatenate([np.linspace(1e-3, 1.0, 300), 1.0 - np.logspace(-7, -1, 30)]).astype(np.float32)
    u = np.concatenate([np.linspace(0.0, 1.0, 3001), np.logspace(-6, -2, 100),
                        1.0 - np.logspace(-6, -2, 100)]).astype(np.float32)
    c, uu = (a.ravel() for a in np.meshgrid(ci, u, indexing="ij"))
    return c, uu


def slope_cdf_error(slopes: Callable[[Float, Array2f], tuple]) -> tuple[float, float]:
    """Max over :func:`grid` of ``|CDF(slope sampled for u) - u|`` for both slopes: ``slopes(cos,
    u)`` returns the sampled ``(x, y)`` slopes, ``u.x = u`` and ``u.y`` the grid's ``u`` reversed."""
    c, uu = grid()
    sx, sy = slopes(Float(c), Array2f(Float(uu), Float(uu[::-1].copy())))
    sx, sy = np.array(sx, np.float64), np.array(sy, np.float64)
    assert np.isfinite(sx).all() and np.isfinite(sy).all()
    c64 = c.astype(np.float64)
    isp = 1.0 / np.sqrt(np.pi)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        tan = np.sqrt(1.0 - c64 * c64) / c64
        cot = 1.0 / tan
        norm = 1.0 + erf(cot) + isp * tan * np.exp(-cot * cot)
        cdf_x = (1.0 + erf(sx) + isp * tan * np.exp(-sx * sx)) / norm
    cdf_x = np.where(c64 == 1.0, 0.5 * (1.0 + erf(sx)), cdf_x)  # tan = 0
    cdf_y = 0.5 * (1.0 + erf(sy))
    lo, hi = np.float32(1e-6), np.float32(1.0 - 1e-6)
    ux = np.clip(uu.astype(np.float64), lo, hi)
    uy = np.clip(uu[::-1].astype(np.float64), lo, hi)
    return float(np.max(np.abs(cdf_x - ux))), float(np.max(np.abs(cdf_y - uy)))
