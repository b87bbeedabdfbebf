"""Image error metrics for comparing a render ``x`` with a reference ``ref``.

Everything here is plain numpy. Images are arrays of the same shape,
normally ``(H, W, C)`` linear radiance; every mean below is taken over all
``H * W * C`` values (pixels *and* channels) unless said otherwise, and is
computed in float64.

=================  ==========================================================
``rel_mse``        ``mean((x - ref)**2 / (ref**2 + eps))``, ``eps = 1e-2``
``mae``            ``mean(|x - ref|)``
``smape``          ``mean(2 |x - ref| / (|x| + |ref|))``, a ``0/0`` term is 0
``outside_ci``     fraction of values with ``|x - ref| > z sqrt(var_x + var_ref)``
``error_map``      per pixel ``mean_c |x - ref| / (|ref| + eps)``, ``(H, W)``
``estimated_rel_mse``  ``mean(var_x / (x**2 + eps))``: ``rel_mse``'s expectation
                   for an unbiased ``x`` with per-pixel variance ``var_x``,
                   estimated without a reference (``x`` stands in for ``ref``)
=================  ==========================================================

``eps`` keeps black reference pixels from dominating the relative errors
(the usual convention of denoising/rendering papers for relMSE).
"""

from __future__ import annotations

import numpy as np

__all__ = ["rel_mse", "mae", "smape", "outside_ci", "error_map", "estimated_rel_mse", "summary"]


def _pair(x, ref) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if x.shape != ref.shape:
        raise ValueError(f"image shapes differ: {x.shape} vs {ref.shape}")
    return x, ref


def rel_mse(x, ref, eps: float = 1e-2) -> float:
    """Relative mean squared error.

    ``relMSE = mean((x - ref)**2 / (ref**2 + eps))`` over all values. ``0``
    for identical images; scale-invariant for bright pixels, while ``eps``
    bounds the weight of (near-)black reference pixels at ``1/eps``.
    """
    x, ref = _pair(x, ref)
    return float(np.mean((x - ref) ** 2 / (ref * ref + eps)))


def estimated_rel_mse(x, var_x, eps: float = 1e-2) -> float:
    """The relMSE an unbiased render ``x`` with per-pixel variances ``var_x`` (of
    its means) has against the true image, ``mean(var_x / (ref**2 + eps))``, with
    ``x`` in place of the unknown ``ref``. Renders stop on it (``--target-error``)."""
    x = np.asarray(x, np.float64)
    return float(np.mean(np.asarray(var_x, np.float64) / (x * x + eps)))


def mae(x, ref) -> float:
    """Mean absolute error ``mean(|x - ref|)`` over all values."""
    x, ref = _pair(x, ref)
    return float(np.mean(np.abs(x - ref)))


def smape(x, ref) -> float:
    """Symmetric mean absolute percentage error, as a fraction in ``[0, 2]``.

    ``SMAPE = mean(t)`` with ``t = 2 |x - ref| / (|x| + |ref|)`` per value,
    and ``t = 0`` where ``|x| + |ref| = 0`` (both zero: no error).
    """
    x, ref = _pair(x, ref)
    num = 2.0 * np.abs(x - ref)
    den = np.abs(x) + np.abs(ref)
    t = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return float(np.mean(t))


def outside_ci(x, var_x, ref, var_ref=None, z: float = 3.0) -> float:
    """Fraction of values outside the ``z``-sigma interval of the difference.

    A value (one channel of one pixel) is *outside* when
    ``|x - ref| > z * sqrt(var_x + var_ref)``, where ``var_x`` and
    ``var_ref`` are the variances of the two estimates (for a Monte Carlo
    pixel mean: the per-sample variance divided by the sample count);
    ``var_ref=None`` means an exact reference (variance 0). The result is
    ``count(outside) / x.size``. A value with zero combined variance is
    inside exactly when ``x == ref``.

    If both estimates are unbiased and Gaussian with the given (true)
    variances, the expected fraction at ``z = 3`` is
    ``2 (1 - Phi(3)) = 0.0027`` (the 99.7% interval). Estimated variances
    from few samples have heavy tails, so a real render exceeds this
    somewhat even without bias; a bias shows up as a much larger fraction.
    """
    x, ref = _pair(x, ref)
    var = np.asarray(var_x, dtype=np.float64)
    if var_ref is not None:
        var = var + np.asarray(var_ref, dtype=np.float64)
    var = np.broadcast_to(var, x.shape)
    diff = np.abs(x - ref)
    outside = diff > z * np.sqrt(np.maximum(var, 0.0))
    return float(np.count_nonzero(outside) / max(x.size, 1))


def error_map(x, ref, eps: float = 1e-2) -> np.ndarray:
    """Per-pixel relative error, an ``(H, W)`` float64 array.

    ``e[i, j] = mean_c |x[i, j, c] - ref[i, j, c]| / (|ref[i, j, c]| + eps)``
    (the mean over channels; a 2-D input is one channel). ``0`` where the
    images agree, ``~1`` for a 100% error on a bright pixel.
    """
    x, ref = _pair(x, ref)
    e = np.abs(x - ref) / (np.abs(ref) + eps)
    return e.mean(axis=2) if e.ndim == 3 else e


def summary(x, ref, var_x=None, var_ref=None, z: float = 3.0) -> dict:
    """All metrics as a JSON-ready dict.

    Keys: ``rel_mse``, ``mae``, ``smape``, ``outside_ci`` (``None`` unless
    ``var_x`` is given: without a variance there is no interval),
    ``ci_z`` (the ``z`` used), ``max_rel_error`` and ``mean_rel_error``
    (of :func:`error_map`).
    """
    emap = error_map(x, ref)
    return {
        "rel_mse": rel_mse(x, ref),
        "mae": mae(x, ref),
        "smape": smape(x, ref),
        "outside_ci": None if var_x is None else outside_ci(x, var_x, ref, var_ref, z),
        "ci_z": float(z),
        "mean_rel_error": float(emap.mean()),
        "max_rel_error": float(emap.max()) if emap.size else 0.0,
    }


# ------------------------------------------------------------------ block z-test
BLOCK_SIZES = (2, 4, 8, 16)  # block sizes whose variances the reference caches keep


def block_sums(img, b: int) -> np.ndarray:
    """Sums of ``img`` (``(H, W, C)``) over ``b x b`` blocks, ``(ceil(H/b), ceil(W/b), C)``;
    the blocks at the right and bottom edges hold what remains of the image."""
    img = np.asarray(img, dtype=np.float64)
    h, w = img.shape[:2]
    ph, pw = -h % b, -w % b
    if ph or pw:
        img = np.pad(img, ((0, ph), (0, pw)) + ((0, 0),) * (img.ndim - 2))
    hb, wb = img.shape[0] // b, img.shape[1] // b
    return img.reshape(hb, b, wb, b, *img.shape[2:]).sum(axis=(1, 3))


def block_counts(shape, b: int) -> np.ndarray:
    """Pixels in each ``b x b`` block of an image of ``shape`` (``(H, W, ...)``), ``(hb, wb, 1)``."""
    return block_sums(np.ones(tuple(shape[:2]) + (1,)), b)


def block_means(img, b: int) -> np.ndarray:
    """Means of ``img`` over ``b x b`` blocks (:func:`block_sums` / pixels per block)."""
    return block_sums(img, b) / block_counts(np.shape(img), b)


def block_variance_independent(var, b: int) -> np.ndarray:
    """Variance of each block's mean when the pixels are independent (drpt's are: each
    averages its own samples, whatever the filter): ``sum(var) / n^2``."""
    n = block_counts(np.shape(var), b)
    return block_sums(var, b) / (n * n)


def filter_j(pixel_filter) -> float:
    """``J = integral w^2 / (integral w)^2`` of a 2-D pixel filter ``w(x) w(y)`` (a
    :class:`drpt.filters.PixelFilter`): 1 for the box, 4/9 for the unit tent, ~0.32 for
    the Gaussian of stddev 0.5. A splatted pixel's variance is about ``J`` times a
    box-filtered one's, while the mean of a block much larger than the filter is about
    as noisy as the box's: so such a block's variance is ``sum(var) / (J n^2)``, where
    the pixels' independent sum would be ``J`` times too small."""
    if pixel_filter.is_box:
        return 1.0
    r = pixel_filter.radius
    x = np.linspace(-r, r, 8001)
    w = pixel_filter.eval(x)
    j1 = float(np.trapezoid(w * w, x) / np.trapezoid(w, x) ** 2)
    return j1 * j1


def sidak_z(tests: int, alpha: float = 0.01) -> float:
    """The two-sided ``|z|`` threshold that ``tests`` independent standard-normal tests all
    stay below with probability ``1 - alpha`` (Sidak's correction, as Mitsuba's render
    tests use)."""
    from statistics import NormalDist

    per_test = 1.0 - (1.0 - alpha) ** (1.0 / max(tests, 1))
    return float(NormalDist().inv_cdf(1.0 - per_test / 2.0))


def block_z(x, ref, var_x_block, var_ref_block, b: int) -> np.ndarray:
    """Per block and channel, ``(mean_x - mean_ref) / sqrt(var_x + var_ref)`` of the
    ``b x b`` block means (variances of the block means given). A block with zero
    combined variance has ``z = 0`` where the means agree, else ``inf``."""
    d = block_means(x, b) - block_means(ref, b)
    v = np.asarray(var_x_block, np.float64) + np.asarray(var_ref_block, np.float64)
    sd = np.sqrt(np.maximum(v, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sd > 0, d / np.where(sd > 0, sd, 1.0), np.where(d == 0, 0.0, np.inf))
    return z
