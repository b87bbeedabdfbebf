"""Adaptive sampling (``--adaptive``): samples per pixel allocated from each pixel's
estimated error, with an unbiased image.

A render of ``spp`` samples per pixel on average runs two kernels of path-regeneration
lanes (:meth:`~drpt.render.integrators.path.PathIntegrator.sample_sequence`) whose
per-lane sample counts come from per-pixel count arrays:

1. **Two pilots**, A and B, of ``a = max(2, spp // 8)`` independent samples in every
   pixel. From each, every pixel's relative per-sample standard deviation ``sqrt(sum_c
   var_c / (mean_c^2 + 0.01))`` (relMSE sums the variances), ``OWN_SHARE`` of it and the
   rest its mean over the ``SMOOTH x SMOOTH`` pixels around it (a pilot of a few samples
   is too noisy alone; averaged as standard deviations, one outlier sample weighs less
   than averaged as variances).
2. **Allocation**: the rest of the budget, the work of ``(spp - 2a) W H`` samples, in two halves:
   half over the pixels as pilot A's estimate says and half as pilot B's, each in
   proportion to ``(1 - UNIFORM_SHARE) s / mean(s) + UNIFORM_SHARE``, ``s`` that
   estimate over the square root of the smoothed cost per sample (from the
   pilot's bounces per sample: Neyman allocation for equal time, mixed with a uniform
   share as a guard against a pilot that missed a pixel's rare paths), at least 1 sample
   each, as many as cost what ``spp - 2a`` samples per pixel spread uniformly would: the
   render takes about a uniform render's time, and its sample count differs from ``W H
   spp`` where cheap and expensive pixels differ in error.

The image is the mean of two estimators (cross-fitting): pilot B's samples with those
pilot A chose, and pilot A's with those pilot B chose. Pilot A decided only how many
samples its half drew; they and pilot B are independent of A, so given A the first
estimator is the mean of a fixed number of independent samples, whose expectation is
the pixel's value whatever A was: both estimators, and their mean, are unbiased. No
sample is thrown away, and with the weights fixed at 1/2 each sample counts about
``1 / spp`` where the two pilots agree. (Averaging every sample of a pixel together is
biased: a pilot that drew a bright outlier gives its pixel more samples, which dilute
it; ``tests/render/test_adaptive.py`` shows the z-test catches it.)

Adaptive renders draw independent samples (PCG32 streams of their own), trace the
path integrator's megakernel (``path``, ``volpath``) with a box filter (or
``--filter-sampling``), in this process: other options are refused in one line
(:func:`check`).
"""

from __future__ import annotations

import time

import drjit as dr
import numpy as np
from drjit.auto import UInt32

from .. import llvm_tuning
from ..backend import policy
from ..errors import DrptError
from .renderer import RenderResult, _check_range, _mix_seed
from .sampler import pcg_streams

#: mixed into the seed of the adaptive phases' random streams
ADAPTIVE_STREAM = 0xADA5EED
#: the share of the allocated samples given out uniformly (the rest: Neyman allocation)
UNIFORM_SHARE = 0.1
#: the side of the square of pixels whose pilot estimates (square roots of relative
#: variances) are averaged
SMOOTH = 5
#: the weight of a pixel's own pilot estimate next to that average
OWN_SHARE = 0.25
#: allocate by relative variance over cost (bounces per sample), not variance alone
COST_AWARE = True
#: lanes per kernel, in units of the backend's min_lanes
LANES_PER_MIN = 1
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
    if opts.sampler not in ("independent", "auto"):  # auto: independent (resolve_sampler)
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


def allocate(mean: np.ndarray, var: np.ndarray, budget: float, cost: np.ndarray | None = None
             ) -> np.ndarray:
    """Samples per pixel ``(H, W)`` int64, at least 1 each, from a pilot's per-pixel means
    and per-sample variances ``(H, W, 3)``: in proportion to ``sqrt(relative variance)``
    (partly averaged over the pixels around, mixed with a uniform share), ``budget`` in
    all. With each pixel's cost per sample ``(H, W)`` (bounces), in proportion to
    ``sqrt(relative variance / cost)`` (the error at equal time falls most so), as many as
    cost the work of ``budget`` samples spread uniformly: an adaptive render takes about a
    uniform render's time."""
    H, W, _ = mean.shape
    r = np.sqrt((var / (np.square(mean) + 0.01)).sum(-1))
    s = OWN_SHARE * r + (1.0 - OWN_SHARE) * np.maximum(_smooth(r, SMOOTH), 0.0)  # (sums round below 0)
    c = np.maximum(_smooth(cost, SMOOTH), 1.0) if cost is not None and COST_AWARE else None
    if c is not None:
        s = s / np.sqrt(c)
    ms = s.mean()
    share = s / ms if ms > 0 else np.ones_like(s)
    share = (1.0 - UNIFORM_SHARE) * share + UNIFORM_SHARE
    if c is None:
        per = budget / (H * W) * share
    else:
        per = budget * c.mean() / (share * c).sum() * share
    return np.maximum(np.floor(per + 0.5).astype(np.int64), 1)


def render_adaptive(renderer, reuse_pilot: bool = False):
    """The :class:`~drpt.render.renderer.RenderResult` of an adaptive render (module
    docstring). ``reuse_pilot`` (a negative control for tests only) averages all of a
    pixel's samples, each pilot's included, into it: biased."""
    opts = renderer.opt
    check(opts)
    if not hasattr(renderer.integrator, "sample_sequence"):
        raise DrptError("--adaptive: volpath traces a scene with participating media one sample "
                        "per lane, which adaptive sampling does not support")
    t0 = time.perf_counter()
    W, H, spp = opts.width, opts.height, opts.spp
    a = pilot_spp(spp)
    P = W * H
    # the two pilots, in one kernel: slots 0..P-1 are pilot A's pixels, P..2P-1 pilot B's
    s, q, bad, work = trace_counts(renderer, 0, np.full(2 * P, a, np.int64), P)
    # cost per sample: bounces per sample, each but the last also traced a shadow ray and
    # shaded (a path that escapes ends with a cheap miss): about 2 bounces - 1
    cost = 2.0 * work / a - 1.0
    mean_p = s / a
    var_p = np.maximum(q / a - mean_p * mean_p, 0.0) * a / (a - 1)  # per sample
    half = (spp - 2 * a) * P / 2
    nA = allocate(mean_p[:P].reshape(H, W, 3), var_p[:P].reshape(H, W, 3), half,
                  cost[:P].reshape(H, W)).reshape(-1)
    nB = allocate(mean_p[P:].reshape(H, W, 3), var_p[P:].reshape(H, W, 3), half,
                  cost[P:].reshape(H, W)).reshape(-1)
    # the allocated samples: slots 0..P-1 join pilot B (pilot A chose their counts), P..2P-1 pilot A
    sN, qN, badN, _ = trace_counts(renderer, 1, np.concatenate([nA, nB]), P)
    s_all, q_all = s + sN[np.r_[P:2 * P, 0:P]], q + qN[np.r_[P:2 * P, 0:P]]
    # estimator 1 (pilot B + the samples A chose) in slots P.., estimator 2 in slots ..P
    cnt = (a + np.concatenate([nB, nA]))[:, None].astype(np.float64)
    if reuse_pilot:
        n = cnt[:P] + cnt[P:]
        mean = (s_all[:P] + s_all[P:]) / n
        var = np.maximum((q_all[:P] + q_all[P:]) / n - mean * mean, 0.0) / (n - 1)
    else:
        means = s_all / cnt
        vars_ = np.maximum(q_all / cnt - means * means, 0.0) / (cnt - 1)  # of each estimator
        mean = 0.5 * (means[:P] + means[P:])
        var = 0.25 * (vars_[:P] + vars_[P:])
    mean = mean.reshape(H, W, 3)
    _check_range(mean)
    samples = int(2 * a * P + nA.sum() + nB.sum())
    return RenderResult(mean.astype(np.float32), var.reshape(H, W, 3), time.perf_counter() - t0,
                        renderer.build_seconds, samples, bad + badN)


def _mix(seed: int, index: int) -> int:
    return _mix_seed(seed ^ ADAPTIVE_STREAM, index)


def trace_counts(renderer, phase: int, counts: np.ndarray, pixels: int
                 ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """``counts[i]`` samples in each slot ``i``, slot ``i`` a sample set of pixel ``i %
    pixels`` (row-major): per slot, the sums of the samples and of their squares
    ``(len(counts), 3)`` float64, the non-finite samples dropped, and per slot the
    bounces its samples traced (their cost). A slot's samples run
    on ``ceil(counts / L)`` lanes, ``L`` chosen so that the lanes number about the
    backend's ``min_lanes`` (and at least one per slot); lanes go to the kernel in batches
    of at most ``max_lanes``."""
    W = renderer.opt.width
    slots = counts.size
    total = int(counts.sum())
    target = max(LANES_PER_MIN * policy().min_lanes, slots)
    per_lane = max(1, -(-total // target))
    lanes = -(-counts // per_lane)  # lanes per pixel (a pixel of 0 samples has none)
    slot = np.repeat(np.arange(slots, dtype=np.int64), lanes)
    first = np.cumsum(lanes) - lanes  # each slot's first lane
    j = np.arange(slot.size) - first[slot]
    m = lanes[slot]
    c = counts[slot]
    lane_count = c // m + (j < c % m)
    pixel = slot % pixels
    acc = np.zeros((slots, 3))
    acc2 = np.zeros((slots, 3))
    work = np.zeros(slots)
    bad = 0
    step = max(1, renderer.max_lanes)
    for b, lo in enumerate(range(0, pixel.size, step)):
        hi = min(pixel.size, lo + step)
        index = phase * (1 << 20) + b
        s, q, nb, st = _trace_lanes(renderer, index, pixel[lo:hi], lane_count[lo:hi], W, wide=False)
        if not (np.isfinite(s).all() and np.isfinite(q).all()):
            s, q, nb, st = _trace_lanes(renderer, index, pixel[lo:hi], lane_count[lo:hi], W, wide=True)
        work += np.bincount(slot[lo:hi], weights=st, minlength=slots)
        for ch in range(3):
            acc[:, ch] += np.bincount(slot[lo:hi], weights=s[:, ch], minlength=slots)
            acc2[:, ch] += np.bincount(slot[lo:hi], weights=q[:, ch], minlength=slots)
        bad += nb
    return acc, acc2, bad, work


def _trace_lanes(renderer, index: int, pixel: np.ndarray, count: np.ndarray, W: int, wide: bool):
    n = pixel.size
    p = UInt32(pixel.astype(np.uint32))
    x = p % dr.opaque(UInt32, W)
    y = p // dr.opaque(UInt32, W)
    rng = pcg_streams(n, _mix(renderer.opt.seed, index))
    camera_ray = renderer._camera_ray(x, y)
    acc, acc2, nbad, steps = renderer.integrator.sample_sequence(
        rng, camera_ray, UInt32(count.astype(np.uint32)), wide=wide, bounces=True)
    with llvm_tuning.blocks_for(n):
        dr.eval(acc, acc2, nbad, steps)
    s = np.stack([np.asarray(c, np.float64) for c in (acc.x, acc.y, acc.z)], -1)
    q = np.stack([np.asarray(c, np.float64) for c in (acc2.x, acc2.y, acc2.z)], -1)
    return s, q, int(dr.sum(nbad)[0]), np.asarray(steps, np.float64)
