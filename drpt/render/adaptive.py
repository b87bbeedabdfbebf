"""Adaptive sampling (``--adaptive``): samples per pixel allocated from each pixel's
estimated error, with an unbiased image.

A render of ``spp`` samples per pixel on average runs in three phases, each a
kernel of path-regeneration lanes (:meth:`~drpt.render.integrators.path.PathIntegrator.sample_sequence`)
whose per-lane sample counts come from a per-pixel count array:

1. **Pilot A**: ``a = max(2, spp // 8)`` samples in every pixel. From them, each
   pixel's relative per-sample variance ``sum_c var_c / (mean_c^2 + 0.01)`` (the
   quantity relMSE sums), averaged over the 5x5 pixels around it (a pilot of a few
   samples is too noisy alone).
2. **Pilot B**: ``a`` more samples in every pixel, independent of A.
3. **Allocation**: the rest of the budget, ``(spp - 2a) W H`` samples, over the
   pixels in proportion to ``0.8 s / mean(s) + 0.2``, ``s`` the square root of the
   smoothed relative variance (Neyman allocation, mixed with a uniform share as a
   guard against a pilot that missed a pixel's rare paths), at least 1 sample each.

The image is ``w mean_A + (1 - w) mean_BN`` with the fixed weight ``w = a / spp``,
``mean_BN`` each pixel's mean of its pilot-B and allocated samples. Only pilot A
decided the allocation, and B and the allocated samples are independent of A, so
given A, ``mean_BN`` is the mean of a fixed number of independent samples: its
expectation is the pixel's value whatever A was, and ``mean_A``'s too, so the image
is unbiased. (Averaging A in with the others, its samples deciding how many
samples dilute them, is biased: a pilot that drew a bright outlier gives its pixel
more samples, which dilute it; ``tests/test_adaptive.py`` shows the z-test catches
it.) With uniform variance the allocation is near uniform and the weights give each
sample ``1 / spp``, as a uniform render does.

Adaptive renders draw independent samples (PCG32 streams of their own), trace the
path integrator's megakernel (``path``, ``volpath``) with a box filter (or
``--filter-sampling``), in this process: other options are refused in one line
(:func:`check`).
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import PCG32, UInt32, UInt64

from .. import llvm_tuning
from ..backend import policy
from ..errors import DrptError

#: mixed into the seed of the adaptive phases' random streams
ADAPTIVE_STREAM = 0xADA5EED
#: the share of the allocated samples given out uniformly (the rest: Neyman allocation)
UNIFORM_SHARE = 0.2
#: the side of the square of pixels whose pilot variances are averaged
SMOOTH = 5
#: the fewest samples per pixel of an adaptive render (two pilots of 2, and 4 to allocate)
MIN_SPP = 8


def pilot_spp(spp: int) -> int:
    """Samples per pixel of each pilot (A and B)."""
    return max(2, spp // 8)


def check(opts) -> None:
    """Refuse, in one line, the options an adaptive render does not support."""
    if opts.spp < MIN_SPP:
        raise DrptError(f"--adaptive needs --spp of at least {MIN_SPP}, got {opts.spp}")
    if opts.integrator not in ("path", "volpath") or opts.mode != "megakernel":
        raise DrptError("--adaptive renders with the path or volpath integrator's megakernel only")
    if not (opts.pixel_filter.is_box or opts.filter_sampling):
        raise DrptError("--adaptive needs the box filter or --filter-sampling (a splatted sample "
                        "counts in several pixels)")
    if opts.sampler != "independent":
        raise DrptError("--adaptive draws independent samples: --sampler must be independent")
    if opts.target_error is not None or opts.time_limit is not None:
        raise DrptError("--adaptive allocates a fixed --spp budget: it cannot stop at "
                        "--target-error or --time-limit")
    if opts.moment or opts.aovs or opts.denoise:
        raise DrptError("--adaptive renders the image alone (no AOVs, --denoise or moment)")
    if opts.chunk_spp is not None:
        raise DrptError("--adaptive renders in one process: --chunk-spp does not apply")


def _smooth(a: np.ndarray, side: int) -> np.ndarray:
    """The mean of ``a`` (H, W) over the ``side x side`` pixels around each pixel
    (edge pixels: over those inside the image)."""
    r = side // 2
    H, W = a.shape
    c = np.zeros((H + 1, W + 1))
    c[1:, 1:] = a.cumsum(0).cumsum(1)
    y0 = np.clip(np.arange(H) - r, 0, H)[:, None]
    y1 = np.clip(np.arange(H) + r + 1, 0, H)[:, None]
    x0 = np.clip(np.arange(W) - r, 0, W)[None, :]
    x1 = np.clip(np.arange(W) + r + 1, 0, W)[None, :]
    total = c[y1, x1] - c[y0, x1] - c[y1, x0] + c[y0, x0]
    return total / ((y1 - y0) * (x1 - x0))


def allocate(mean: np.ndarray, var: np.ndarray, budget: int) -> np.ndarray:
    """Samples per pixel ``(H, W)`` int64 summing to about ``budget``, at least 1 each,
    from a pilot's per-pixel means and per-sample variances ``(H, W, 3)``."""
    H, W, _ = mean.shape
    rel = (var / (np.square(mean) + 0.01)).sum(-1)
    s = np.sqrt(np.maximum(_smooth(rel, SMOOTH), 0.0))  # (cumulative sums round below 0)
    ms = s.mean()
    share = s / ms if ms > 0 else np.ones_like(s)
    share = (1.0 - UNIFORM_SHARE) * share + UNIFORM_SHARE
    per = budget / (H * W) * share
    return np.maximum(np.floor(per + 0.5).astype(np.int64), 1)


def render_adaptive(renderer, reuse_pilot: bool = False):
    """The :class:`~drpt.render.renderer.RenderResult` of an adaptive render (module
    docstring). ``reuse_pilot`` (a negative control for tests only) averages every
    sample, pilot A's included, into each pixel: biased."""
    from .renderer import RenderResult, _check_range

    opts = renderer.opt
    check(opts)
    if not hasattr(renderer.integrator, "sample_sequence"):
        raise DrptError("--adaptive: volpath traces a scene with participating media one sample "
                        "per lane, which adaptive sampling does not support")
    t0 = time.perf_counter()
    W, H, spp = opts.width, opts.height, opts.spp
    a = pilot_spp(spp)
    pixels = W * H
    uniform = np.full(pixels, a, np.int64)
    sA, qA, badA = trace_counts(renderer, 0, uniform)
    sB, qB, badB = trace_counts(renderer, 1, uniform)
    meanA = sA / a
    varA = np.maximum(qA / a - meanA * meanA, 0.0) * a / (a - 1)
    n = allocate(meanA.reshape(H, W, 3), varA.reshape(H, W, 3), (spp - 2 * a) * pixels).reshape(-1)
    sN, qN, badN = trace_counts(renderer, 2, n)
    cnt = (a + n)[:, None].astype(np.float64)
    if reuse_pilot:
        cnt = cnt + a
        mean = (sA + sB + sN) / cnt
        var1 = np.maximum((qA + qB + qN) / cnt - mean * mean, 0.0) * cnt / (cnt - 1)
        var = var1 / cnt
    else:
        w = a / spp
        meanBN = (sB + sN) / cnt
        varBN = np.maximum((qB + qN) / cnt - meanBN * meanBN, 0.0) * cnt / (cnt - 1)
        mean = w * meanA + (1.0 - w) * meanBN
        var = w * w * varA / a + (1.0 - w) ** 2 * varBN / cnt
    mean = mean.reshape(H, W, 3)
    _check_range(mean)
    samples = int(2 * a * pixels + n.sum())
    return RenderResult(mean.astype(np.float32), var.reshape(H, W, 3), time.perf_counter() - t0,
                        renderer.build_seconds, samples, badA + badB + badN)


def _mix(seed: int, index: int) -> int:
    from .renderer import _mix_seed

    return _mix_seed(seed ^ ADAPTIVE_STREAM, index)


def trace_counts(renderer, phase: int, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """``counts[p]`` samples in each pixel ``p`` (row-major): per pixel, the sums of the
    samples and of their squares ``(W H, 3)`` float64 and the non-finite samples
    dropped. A pixel's samples run on ``ceil(counts / L)`` lanes, ``L`` chosen so that
    the lanes number about the backend's ``min_lanes`` (and at least one per pixel);
    lanes go to the kernel in batches of at most ``max_lanes``."""
    W = renderer.opt.width
    pixels = counts.size
    total = int(counts.sum())
    target = max(policy().min_lanes, pixels)
    per_lane = max(1, -(-total // target))
    lanes = -(-counts // per_lane)  # lanes per pixel (a pixel of 0 samples has none)
    pixel = np.repeat(np.arange(pixels, dtype=np.int64), lanes)
    first = np.cumsum(lanes) - lanes  # each pixel's first lane
    j = np.arange(pixel.size) - first[pixel]
    m = lanes[pixel]
    c = counts[pixel]
    lane_count = c // m + (j < c % m)
    acc = np.zeros((pixels, 3))
    acc2 = np.zeros((pixels, 3))
    bad = 0
    step = max(1, renderer.max_lanes)
    for b, lo in enumerate(range(0, pixel.size, step)):
        hi = min(pixel.size, lo + step)
        index = phase * (1 << 20) + b
        s, q, nb = _trace_lanes(renderer, index, pixel[lo:hi], lane_count[lo:hi], W, wide=False)
        if not (np.isfinite(s).all() and np.isfinite(q).all()):
            s, q, nb = _trace_lanes(renderer, index, pixel[lo:hi], lane_count[lo:hi], W, wide=True)
        for ch in range(3):
            acc[:, ch] += np.bincount(pixel[lo:hi], weights=s[:, ch], minlength=pixels)
            acc2[:, ch] += np.bincount(pixel[lo:hi], weights=q[:, ch], minlength=pixels)
        bad += nb
    return acc, acc2, bad


def _trace_lanes(renderer, index: int, pixel: np.ndarray, count: np.ndarray, W: int, wide: bool):
    n = pixel.size
    p = UInt32(pixel.astype(np.uint32))
    x = p % dr.opaque(UInt32, W)
    y = p // dr.opaque(UInt32, W)
    rng = PCG32(n, initstate=dr.opaque(UInt64, _mix(renderer.opt.seed, index)),
                initseq=dr.opaque(UInt64, index * renderer.max_lanes))
    camera_ray = renderer._camera_ray(x, y)
    acc, acc2, nbad = renderer.integrator.sample_sequence(rng, camera_ray, UInt32(count.astype(np.uint32)),
                                                          wide=wide)
    with llvm_tuning.blocks_for(n):
        dr.eval(acc, acc2, nbad)
    s = np.stack([np.asarray(c, np.float64) for c in (acc.x, acc.y, acc.z)], -1)
    q = np.stack([np.asarray(c, np.float64) for c in (acc2.x, acc2.y, acc2.z)], -1)
    return s, q, int(dr.sum(nbad)[0])
