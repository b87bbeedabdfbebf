"""``python -m drpt converge``: error against samples and seconds, drpt vs Mitsuba 3.

::

    python -m drpt converge SCENE [render flags] [--max-spp N] [--ref-spp M]
                                  [--ref-batches B] [--levels E ...]
                                  [--cache DIR | --no-cache] [--out DIR]

The render flags are ``render``'s (:func:`drpt.cli.args.add_render_flags`,
``--size`` default 64 64; no ``--spp``: the levels set it). drpt and Mitsuba
(``path`` on drpt's backend, the exported scene) each render
the scene at 1, 2, 4, ..., ``--max-spp`` samples per pixel, every level with
its own seed (so the levels are independent estimates, not prefixes of one
another). Each image is compared with a high-spp Mitsuba reference, the one
``compare`` uses and caches (:func:`drpt.tools.reference.get_reference`, same key, so
a reference made by ``compare`` with the same settings is reused).

Error
    ``relMSE = mean((x - ref)^2 / (ref^2 + 0.01))`` (:func:`drpt.metrics.rel_mse`).
    The reference is a finite-spp estimate itself: with ``x`` and ``ref``
    independent, ``E[relMSE] ~= mean((var_x + var_ref + bias^2) / (ref^2 + 0.01))``,
    so relMSE levels off at the *reference noise floor*
    ``floor = mean(var_ref / (ref^2 + 0.01))``, ``var_ref`` being the variance
    of the reference's mean estimated from its independent batches. The
    curves, fits and ratios use ``excess relMSE = relMSE - floor``, which
    falls as ``1/N`` for an unbiased renderer; raw relMSE and the floor are in
    the CSV/JSON. A level whose excess is not positive (the render is as good
    as the reference) is left out of the curves. MAE and SMAPE are recorded
    too (they have floors of their own and are not corrected).

Time
    Wall seconds of the render call alone (drpt: :meth:`Renderer.render`,
    which returns numpy arrays; Mitsuba: ``mi.render`` plus the copy to
    numpy, which waits for the result). Excluded and reported separately:
    scene loading, drpt's acceleration build (``build_seconds``), Mitsuba's
    ``load_dict``, and kernel compilation: each renderer first renders one
    1-spp warm-up image (discarded), which compiles its kernels; Dr.Jit then
    reuses them at every spp (the sample count is not baked into either
    renderer's kernels). drpt and Mitsuba render each level back to back, so
    load from other processes perturbs both alike; their *ratios* are what
    to read, absolute seconds depend on the machine's load.

Ratios
    *Equal-time error ratio*: drpt's excess relMSE divided by Mitsuba's at
    the same seconds, each curve interpolated linearly in log-log; reported
    at each drpt level whose time lies in Mitsuba's measured range, and as
    the geometric mean over 9 log-spaced times across the overlap. Below 1:
    drpt is more accurate for the same time.
    *Time-to-error ratio*: for each ``--levels`` error ``e``, the seconds
    each renderer needs to reach excess relMSE ``e`` and stay there (the
    crossing after its last level above ``e``, interpolated log-log), drpt /
    Mitsuba, where both reach it. Below 1: drpt gets there sooner.

Mitsuba XML scenes
    As ``compare`` does them: the file's own size, depths, ``hide_emitters`` and
    filter apply where no flag was given (:func:`~drpt.options.with_scene_settings`),
    and Mitsuba renders the file itself (:class:`~drpt.tools.xmlref.MitsubaXML`), for
    the reference and for its own curve, not drpt's export of it. A file drpt does not
    read completely is refused unless ``--ignore-unsupported``.

Denoising (``--denoise``, needs ``pyoidn``)
    drpt also renders each level with the denoiser's albedo and normal guides and
    denoises it with Intel Open Image Denoise (as ``render --denoise``): rows
    ``drpt+oidn``, whose seconds are the render's (guides included) plus the
    denoiser's. The denoised error splits into a *variance* part, from a second
    independent render of the level denoised too (``mean((D1 - D2)^2 / (ref^2 +
    0.01)) / 2``), and a *bias* part, the excess relMSE minus the variance part:
    the error the denoiser leaves that more samples take away slowly (noisy at
    low spp). The raw drpt rows stay the unbiased renders without guides.

Output in ``--out`` (default ``converge_<scene stem>/``): ``converge.csv``
(one row per renderer and level), ``converge.json`` (settings, reference,
levels, fitted slopes, ratios) and ``converge.png`` (excess relMSE against
spp and against seconds, log-log, with a ``1/N`` line). A table goes to
stdout.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import llvm_tuning, metrics
from ..cli.args import add_render_flags, given_settings, options_from_args
from ..denoise import denoise_result, require
from ..errors import DrptError, warn
from ..export.mitsuba import to_mitsuba_dict
from ..metrics import rel_mse
from ..options import with_scene_settings
from ..render.renderer import Renderer
from ..scene import load_scene
from .compare import _prepare_out, _write_json
from .reference import (
    add_reference_args,
    cache_dir_from_args,
    check_reference_args,
    get_reference,
)
from .xmlref import MitsubaXML

EPS = 1e-2  # relMSE's eps (drpt.metrics.rel_mse)
DEFAULT_LEVELS = (1e-1, 3e-2, 1e-2)

__all__ = ["add_parser", "main", "noise_floor", "excess_rel_mse", "loglog_slope",
           "interp_loglog", "equal_time_ratios", "time_to_error", "time_to_error_ratios",
           "converge_study", "spp_levels", "efficiency_rounds"]


# ------------------------------------------------------------------ parser
def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``converge`` subcommand on an ``add_subparsers()`` object."""
    p = subparsers.add_parser(
        "converge", allow_abbrev=False,
        help="error vs spp and vs seconds, drpt against Mitsuba 3",
        description="render SCENE with drpt and Mitsuba 3 at 1, 2, 4, ... spp, measure the "
                    "error against a cached high-spp Mitsuba reference and the time; report "
                    "equal-time error and time-to-error ratios")
    p.add_argument("scene", help="scene file")
    add_render_flags(p, omit=("spp",), size=(64, 64))
    p.add_argument("--max-spp", type=int, default=256,
                   help="largest samples per pixel; levels are the powers of 2 up to it "
                        "(default 256)")
    p.add_argument("--levels", type=float, nargs="+", default=list(DEFAULT_LEVELS),
                   metavar="E", help="excess relMSE levels for the time-to-error ratio "
                                     "(default 0.1 0.03 0.01)")
    p.add_argument("--out", default=None, help="output folder (default converge_<name>/)")
    p.add_argument("--denoise", action="store_true",
                   help="also measure drpt's image denoised by Intel Open Image Denoise "
                        "(pyoidn): its error, bias and variance at each spp")
    p.add_argument("--adaptive", action="store_true",
                   help="also render each level of at least 8 spp with adaptive sampling "
                        "(render --adaptive): rows drpt+adaptive, its equal-time error ratio "
                        "against uniform drpt")
    add_reference_args(p, ref_spp=4096)
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from dataclasses import replace

    options = options_from_args(args, adaptive=False)  # (--adaptive adds rows of its own)
    if args.denoise:
        require()
        options = replace(options, denoise=True)
    scene = Path(args.scene)
    out = Path(args.out) if args.out else Path(f"converge_{scene.stem}")
    report = converge_study(scene, out, options, max_spp=args.max_spp, ref_spp=args.ref_spp,
                            ref_batches=args.ref_batches, levels=args.levels,
                            cache_dir=cache_dir_from_args(args), adaptive=args.adaptive, args=args)
    print(format_table(report))
    print(f"{out}: converge.csv, converge.json, converge.png")
    return 0


# ------------------------------------------------------------ statistics
def noise_floor(ref, ref_var, eps: float = EPS) -> float:
    """``mean(var_ref / (ref^2 + eps))``: the relMSE an exact image would get."""
    ref = np.asarray(ref, np.float64)
    return float(np.mean(np.asarray(ref_var, np.float64) / (ref * ref + eps)))


def excess_rel_mse(x, ref, ref_var, eps: float = EPS) -> float:
    """relMSE of ``x`` against ``ref`` minus the reference's noise floor."""
    return rel_mse(x, ref, eps) - noise_floor(ref, ref_var, eps)


def spp_levels(max_spp: int) -> list[int]:
    """1, 2, 4, ... up to ``max_spp`` (``max_spp`` itself last if not a power of 2)."""
    out, n = [], 1
    while n < max_spp:
        out.append(n)
        n *= 2
    out.append(int(max_spp))
    return out


def loglog_slope(n, e) -> tuple[float, float]:
    """Least-squares slope of ``log e`` against ``log n`` and its standard error.

    Points with ``e <= 0`` or non-finite are left out; ``nan`` with fewer
    than 2 points (standard error ``nan`` with fewer than 3).
    """
    n, e = np.asarray(n, np.float64), np.asarray(e, np.float64)
    ok = (n > 0) & (e > 0) & np.isfinite(e)
    x, y = np.log(n[ok]), np.log(e[ok])
    if x.size < 2 or np.ptp(x) == 0:
        return float("nan"), float("nan")
    A = np.stack([x, np.ones_like(x)], 1)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    if x.size < 3:
        return float(coef[0]), float("nan")
    resid = y - A @ coef
    s2 = float(resid @ resid) / (x.size - 2)
    se = np.sqrt(s2 / float(((x - x.mean()) ** 2).sum()))
    return float(coef[0]), float(se)


def _curve(t, e):
    """Positive, finite points of a curve sorted by ``t``, as logs."""
    t, e = np.asarray(t, np.float64), np.asarray(e, np.float64)
    ok = (t > 0) & (e > 0) & np.isfinite(t) & np.isfinite(e)
    order = np.argsort(t[ok], kind="stable")
    return np.log(t[ok][order]), np.log(e[ok][order])


def interp_loglog(t, e, at) -> np.ndarray:
    """``e(at)`` interpolated linearly in log-log; ``nan`` outside ``t``'s range."""
    lt, le = _curve(t, e)
    at = np.atleast_1d(np.asarray(at, np.float64))
    out = np.full(at.shape, np.nan)
    if lt.size == 0:
        return out
    la = np.log(np.where(at > 0, at, np.nan))
    inside = (la >= lt[0]) & (la <= lt[-1])
    out[inside] = np.exp(np.interp(la[inside], lt, le))
    return out


def equal_time_ratios(t_a, e_a, t_b, e_b, points: int = 9) -> dict:
    """Error of ``a`` over error of ``b`` at equal seconds (log-log interpolation).

    Returns ``{"at_a_times": [(t, ratio), ...]}`` for each of ``a``'s times
    inside ``b``'s range, ``"overlap": (t0, t1)`` (``None`` if the curves do
    not overlap in time), and ``"geomean"``: the geometric mean of the ratio
    at ``points`` log-spaced times across the overlap (``nan`` without one).
    """
    la, _ = _curve(t_a, e_a)
    lb, _ = _curve(t_b, e_b)
    res = {"at_a_times": [], "overlap": None, "geomean": float("nan")}
    if la.size == 0 or lb.size == 0:
        return res
    lo, hi = max(la[0], lb[0]), min(la[-1], lb[-1])
    if lo > hi:
        return res
    res["overlap"] = (float(np.exp(lo)), float(np.exp(hi)))
    grid = np.exp(np.linspace(lo, hi, points if hi > lo else 1))
    r = interp_loglog(t_a, e_a, grid) / interp_loglog(t_b, e_b, grid)
    res["geomean"] = float(np.exp(np.mean(np.log(r))))
    ta = np.exp(la)
    rb = interp_loglog(t_b, e_b, ta)
    ra = interp_loglog(t_a, e_a, ta)
    res["at_a_times"] = [(float(t), float(x / y)) for t, x, y in zip(ta, ra, rb)
                         if np.isfinite(y)]
    return res


def time_to_error(t, e, level: float) -> float | None:
    """Seconds from which the curve stays at or below error ``level``, or ``None``.

    Points are taken in the order of ``t``. The last point above ``level``
    and the one after it are interpolated in log-log (so a lucky low error
    at few samples, followed by higher ones, does not count as reaching the
    level). A curve entirely at or below ``level`` reaches it at its first
    time; one that ends above it never does.
    """
    lt, le = _curve(t, e)
    if lt.size == 0:
        return None
    ll = np.log(level)
    above = np.nonzero(le > ll)[0]
    if above.size == 0:
        return float(np.exp(lt[0]))
    i = int(above[-1])
    if i == lt.size - 1:
        return None
    f = (ll - le[i]) / (le[i + 1] - le[i])
    return float(np.exp(lt[i] + f * (lt[i + 1] - lt[i])))


def time_to_error_ratios(t_a, e_a, t_b, e_b, levels) -> list[dict]:
    """For each level: seconds of ``a``, of ``b`` and ``a / b`` (``None`` where one never gets there)."""
    rows = []
    for level in levels:
        sa, sb = time_to_error(t_a, e_a, level), time_to_error(t_b, e_b, level)
        ratio = sa / sb if sa is not None and sb is not None else None
        rows.append({"level": float(level), "seconds_a": sa, "seconds_b": sb, "ratio": ratio})
    return rows


def image_room(rounds: int, shape: tuple, kept: np.ndarray | None = None) -> np.ndarray:
    """A float64 stack of ``rounds`` images of ``shape`` to keep a timed loop's images in, its
    pages written now (zeros, after the images of ``kept``, the rounds so far): a loop that
    kept a new array each round would grow the heap, and a timed render that then allocates
    memory of its own would pay for the fresh pages (docs/performance.md, "The benchmark's
    kept images")."""
    room = np.empty((rounds, *shape))
    done = 0 if kept is None else len(kept)
    if done:
        room[:done] = kept
    room[done:] = 0.0
    return room


def efficiency_rounds(ways: dict, rounds: int, warm_seed: int = 999_999,
                      more: Callable[[dict], bool] | None = None, max_rounds: int = 0) -> dict:
    """Equal-spp efficiency of several ways of rendering one image, measured interleaved.

    ``ways``: name -> ``render(seed) -> image`` (an ``(H, W, C)`` array; all ways at the
    same spp). Each way renders once with ``warm_seed`` (discarded: it compiles the
    kernels), then the ways take turns for ``rounds`` rounds, round ``k`` with seed ``k``,
    so that load from other processes falls on all of them alike. A render's time is its
    call alone: the images are kept (in float64) in room made before the rounds start, so
    that the bookkeeping's memory is not paged in during a timed render. Returns name ->
    ``{"seconds": median wall seconds of a render, "variance": per-pixel variance across
    the rounds' images (ddof 1) averaged over pixels and channels, "efficiency":
    1 / (seconds * variance), "loo_variances": the variance with each round left out in
    turn (round order; empty below 3 rounds), "mean": the mean of the rounds' images,
    "nonfinite_pixels": the pixels with a NaN or infinite value in at least one of this
    way's rounds}``: the efficiency is the inverse of the variance a render reaches per
    second; :func:`variance_ratio_error` reads ``loo_variances``. A pixel that is not finite
    in some round of any way is left out of every way's variance, leave-one-out variances
    and mean (all ways are scored on the same pixels; the count says how many each way
    lost); with no such pixel every pixel counts; ``"rounds"``: how many rounds it read.

    With ``more`` (``more(result) -> bool``, e.g. whether a variance ratio's error is still
    large) the rounds go on, doubling, while ``more`` says so and they are fewer than
    ``max_rounds``: round ``k`` still seed ``k``, so a longer run extends a shorter one.
    """
    if rounds < 2:
        raise DrptError(f"efficiency needs at least 2 rounds, got {rounds}")
    shapes = {name: np.shape(np.asarray(render(warm_seed))) for name, render in ways.items()}
    times: dict = {name: [] for name in ways}
    images: dict = {name: None for name in ways}
    done, total = 0, rounds
    while True:
        # room for this stretch's images: a render's timed span allocates nothing of the
        # bookkeeping's
        images = {name: image_room(total, shapes[name], images[name]) for name in ways}
        for k in range(done, total):
            for name, render in ways.items():
                t = time.perf_counter()
                img = np.asarray(render(k))  # (a lazy array is evaluated inside the span)
                times[name].append(time.perf_counter() - t)
                images[name][k] = img
                del img  # (freed before the next render, which may reuse its memory)
        done = total
        out = _efficiency_of(times, images)
        if more is None or total >= max_rounds or not more(out):
            return out
        total = min(2 * total, max_rounds)


def _efficiency_of(times: dict, stacks: dict) -> dict:
    """:func:`efficiency_rounds`' result from each way's times and images so far (a stack
    of ``(H, W, C)`` images, one a round)."""
    finite = {name: finite_in_every_round(st) for name, st in stacks.items()}
    scored = np.logical_and.reduce(list(finite.values()))
    out = {}
    for name, st in stacks.items():
        sec = float(np.median(times[name]))
        var = float(st[:, scored].var(0, ddof=1).mean()) if scored.any() else float("nan")
        out[name] = {"seconds": sec, "variance": var,
                     "efficiency": (1.0 / (sec * var) if sec * var > 0 else
                                    float("inf") if var == 0 else float("nan")),
                     "loo_variances": _loo_variances(st[:, scored]) if scored.any() else [],
                     "mean": float(st[:, scored].mean()) if scored.any() else float("nan"),
                     "nonfinite_pixels": int((~finite[name]).sum()), "rounds": len(st)}
    return out


def finite_in_every_round(stack: np.ndarray) -> np.ndarray:
    """Per pixel of ``stack`` (rounds first, then ``(H, W)`` and any channels): whether it is
    finite in every round and channel, an ``(H, W)`` mask. The pixels to score a set of
    renderers on are those finite in all of theirs (``np.logical_and`` of their masks)."""
    return np.isfinite(stack.reshape(stack.shape[0], stack.shape[1], stack.shape[2], -1)).all(axis=(0, 3))


def _loo_variances(stack: np.ndarray) -> list[float]:
    """Per round ``k`` of ``stack`` (rounds first): the per-pixel variance (ddof 1) of the
    other rounds, averaged over pixels and channels; empty below 3 rounds."""
    n = len(stack) - 1
    if n < 2:
        return []
    s1, s2 = stack.sum(0), np.square(stack).sum(0)
    out = []
    for x in stack:
        m = (s1 - x) / n
        out.append(float(np.mean((s2 - x * x - n * m * m) / (n - 1))))
    return out


def variance_ratio_error(a: dict, b: dict) -> float:
    """The jackknife standard error, over the rounds, of ``a["variance"] / b["variance"]``
    (two ways of one :func:`efficiency_rounds` call: the same rounds); NaN below 3 rounds.
    Where a few pixels hold most of the variance (a sub-pixel highlight, a caustic) a ratio
    read from a few rounds can be far from its expectation, and this error says how far."""
    la, lb = np.asarray(a["loo_variances"]), np.asarray(b["loo_variances"])
    if len(la) < 3 or len(la) != len(lb) or not np.all(lb > 0):
        return float("nan")
    r = la / lb
    return float(np.sqrt((len(r) - 1) / len(r) * np.sum((r - r.mean()) ** 2)))


# ------------------------------------------------------------ rendering
def make_mitsuba(scene, width, height, max_depth, rr_depth, seed, bsdf, rfilter="box", source=None,
                 hide_emitters=False, sampler="independent"):
    """A loaded Mitsuba scene and a ``render(spp, seed) -> (image, seconds)``: drpt's
    export of ``scene`` (with Mitsuba's plugin for drpt's resolved ``sampler``:
    :func:`drpt.export.mitsuba.mitsuba_sampler`), or with ``source`` (a
    :class:`~drpt.tools.xmlref.MitsubaXML`) that XML file as Mitsuba reads it."""
    import mitsuba as mi

    t0 = time.perf_counter()
    integrator = None
    if source is not None:
        ms, integrator = source.load()
    else:
        ms = mi.load_dict(to_mitsuba_dict(scene, width, height, 1, max_depth=max_depth,
                                          rr_depth=rr_depth, seed=seed, bsdf=bsdf, rfilter=rfilter,
                                          hide_emitters=hide_emitters, sampler=sampler))
    load_seconds = time.perf_counter() - t0

    def render(spp: int, s: int):
        with llvm_tuning.dr_default():  # Mitsuba as it ships (see drpt.llvm_tuning)
            t = time.perf_counter()
            img = np.asarray(mi.render(ms, spp=int(spp), seed=int(s), integrator=integrator),
                             np.float32)
            return img[..., :3], time.perf_counter() - t

    return render, load_seconds


def make_drpt(scene, options):
    """A built drpt Renderer and a ``render(spp, seed) -> (RenderResult)``."""
    renderer = Renderer(scene, options)

    def render(spp: int, s: int):
        renderer.opt.spp, renderer.opt.seed = int(spp), int(s)
        return renderer.render()

    return renderer, render


def _log(progress: bool, msg: str) -> None:
    if progress:
        print(msg, file=sys.stderr, flush=True)


def converge_study(scene_path: Path, out: Path, options, max_spp: int = 256,
                   ref_spp: int = 4096, ref_batches: int = 8, levels=DEFAULT_LEVELS,
                   cache_dir: Path | None = None, adaptive: bool = False, args=None) -> dict:
    """Run the study (see the module docs) with drpt's ``options`` (a
    :class:`~drpt.options.RenderOptions`; the levels set its spp and seed);
    write the outputs; return the report. A Mitsuba XML scene: with ``args`` (the
    parsed command line) the file's settings apply where no flag was given, and
    Mitsuba renders the file itself."""
    from dataclasses import replace

    options.validate()
    scene_path = Path(scene_path)
    scene = load_scene(scene_path)
    source = None
    if scene_path.suffix.lower() == ".xml":
        if args is not None:
            options, scene = with_scene_settings(options, scene, given_settings(args))
            options.validate()
        not_read = list(getattr(scene.settings, "not_read", ()))
        if not_read and not getattr(args, "ignore_unsupported", False):
            raise DrptError(f"{scene_path}: drpt does not read all of the file ({not_read[0]}"
                            + (f"; and {len(not_read) - 1} more" if len(not_read) > 1 else "")
                            + "): Mitsuba's rendering of the file as written would not be the scene "
                            "drpt renders (--ignore-unsupported measures anyway)")
        source = MitsubaXML.for_scene(scene, options)
    width, height, seed, bsdf = options.width, options.height, options.seed, options.bsdf
    max_depth, rr_depth = options.path.max_depth, options.path.rr_depth
    progress = options.progress
    if max_spp < 1:
        raise DrptError(f"--max-spp must be positive, got {max_spp}")
    if not levels or any(not (v > 0) for v in levels):
        raise DrptError(f"--levels must be positive errors, got {list(levels)}")
    check_reference_args(ref_spp, ref_batches, max_depth, rr_depth, announce=False)
    if ref_spp <= max_spp:
        raise DrptError(f"--ref-spp ({ref_spp}) must exceed --max-spp ({max_spp}): the "
                        "reference must be better than the renders it judges")
    _prepare_out(out)
    reference = get_reference(
        scene, scene_path.stem, width, height, ref_spp=ref_spp, ref_batches=ref_batches,
        bsdf=bsdf, max_depth=max_depth, rr_depth=rr_depth, seed=seed, cache_dir=cache_dir,
        progress=progress, rfilter=options.filter, source=source,
        hide_emitters=options.path.hide_emitters)
    ref, ref_var = reference.image, reference.variance
    import mitsuba as mi

    floor = noise_floor(ref, ref_var)
    denoising = options.denoise
    renderer, drpt_render = make_drpt(scene, replace(options, spp=1, progress=False, denoise=False))
    if denoising:
        _, dn_render = make_drpt(scene, replace(options, spp=1, progress=False))
        dn_render(1, seed + 999_998)  # warm-up
    for message in renderer.warnings:
        warn(message)
    if adaptive:
        _, ad_render = make_drpt(scene, replace(options, spp=8, progress=False, denoise=False,
                                                adaptive=True))
        ad_render(8, seed + 999_997)  # warm-up
    mits_render, mits_load = make_mitsuba(scene, width, height, max_depth, rr_depth, seed, bsdf,
                                          options.filter, source, options.path.hide_emitters)
    # Warm-up: compiles both renderers' kernels (reused at every spp), discarded.
    t = time.perf_counter()
    drpt_render(1, seed + 999_999)
    drpt_warm = time.perf_counter() - t
    mits_warm = mits_render(1, seed + 999_999)[1]

    rows = []
    spps = spp_levels(max_spp)
    for i, spp in enumerate(spps):
        # Independent seeds per level and renderer; the reference uses
        # seed + 100000 + 7919 k, so these never coincide with it.
        r = drpt_render(spp, seed + 1 + i)
        if r.nonfinite:
            warn(f"{r.nonfinite} samples were NaN/Inf at {spp} spp")
        img_m, sec_m = mits_render(spp, seed + 200_000 + i)
        for name, img, sec in (("drpt", r.image, r.seconds), ("mitsuba", img_m, sec_m)):
            m = metrics.summary(img, ref)
            rows.append({"renderer": name, "spp": int(spp), "seconds": float(sec),
                         "rel_mse": m["rel_mse"], "floor": floor,
                         "excess_rel_mse": m["rel_mse"] - floor, "mae": m["mae"],
                         "smape": m["smape"]})
        d, mm = rows[-2], rows[-1]
        _log(progress, f"converge: {spp:>5} spp  drpt {d['seconds']:7.3f} s "
                       f"{d['excess_rel_mse']:.3e}   mitsuba {mm['seconds']:7.3f} s "
                       f"{mm['excess_rel_mse']:.3e}")
        if adaptive and spp >= 8:
            ra = ad_render(spp, seed + 500_000 + i)
            m = metrics.summary(ra.image, ref)
            rows.append({"renderer": "drpt+adaptive", "spp": int(spp), "seconds": float(ra.seconds),
                         "rel_mse": m["rel_mse"], "floor": floor,
                         "excess_rel_mse": m["rel_mse"] - floor, "mae": m["mae"],
                         "smape": m["smape"]})
        if denoising:
            rows.append(_denoised_row(dn_render, denoise_result, spp, seed + 300_000 + i,
                                      seed + 400_000 + i, ref, floor))

    report = analyse(rows, levels)
    if adaptive:
        report["adaptive"] = adaptive_ratio(rows)
    report.update({
        "scene": str(scene_path), "width": int(width), "height": int(height), "bsdf": bsdf,
        "max_depth": int(max_depth), "rr_depth": int(rr_depth), "seed": int(seed),
        "rows": rows,
        "noise_floor": floor,
        "noise_floor_note": "mean(var_ref / (ref^2 + 0.01)), var_ref from the reference's "
                            "batches; subtracted from relMSE (excess_rel_mse)",
        "timing_note": "render call only; excluded: scene load, drpt build "
                       f"({renderer.build_seconds:.3f} s), Mitsuba load_dict ({mits_load:.3f} s) "
                       f"and kernel compilation (1-spp warm-up render each: drpt "
                       f"{drpt_warm:.3f} s, Mitsuba {mits_warm:.3f} s); drpt and Mitsuba "
                       "alternate per level, so machine load affects both alike",
        "drpt": {"build_seconds": renderer.build_seconds, "warmup_seconds": drpt_warm},
        "mitsuba": {"version": mi.__version__, "load_seconds": mits_load,
                    "warmup_seconds": mits_warm},
        "reference": reference.info(),
    })
    write_csv(out / "converge.csv", rows)
    _write_json(out / "converge.json", report)
    plot(out / "converge.png", report)
    return report


def _denoised_row(render, denoise_result, spp: int, seed_a: int, seed_b: int, ref, floor: float) -> dict:
    """The ``drpt+oidn`` row of a level: two independent renders with guides, both
    denoised; the first's error, split into variance (from the pair) and bias."""
    r = render(spp, seed_a)
    t0 = time.perf_counter()
    d1 = denoise_result(r)
    seconds = r.seconds + time.perf_counter() - t0
    d2 = denoise_result(render(spp, seed_b))
    w = np.asarray(ref, np.float64) ** 2 + EPS
    var = float(np.mean((d1.astype(np.float64) - d2) ** 2 / w)) / 2.0
    m = metrics.summary(d1, ref)
    excess = m["rel_mse"] - floor
    return {"renderer": "drpt+oidn", "spp": int(spp), "seconds": float(seconds),
            "rel_mse": m["rel_mse"], "floor": floor, "excess_rel_mse": excess, "mae": m["mae"],
            "smape": m["smape"], "variance_rel_mse": var, "bias_rel_mse": excess - var}


def analyse(rows: list[dict], levels) -> dict:
    """Slopes and ratios from the per-level rows (excess relMSE)."""
    def curve(name):
        rs = [r for r in rows if r["renderer"] == name]
        return (np.array([r["spp"] for r in rs], float), np.array([r["seconds"] for r in rs]),
                np.array([r["excess_rel_mse"] for r in rs]))

    n_d, t_d, e_d = curve("drpt")
    n_m, t_m, e_m = curve("mitsuba")
    slopes = {}
    for name, n, e in (("drpt", n_d, e_d), ("mitsuba", n_m, e_m)):
        sel = n >= 4  # below ~4 spp relMSE is dominated by a few outlier pixels
        if sel.sum() < 2:
            sel = n > 0
        s, se = loglog_slope(n[sel], e[sel])
        slopes[name] = {"slope": s, "stderr": se, "from_spp": int(n[sel].min())}
    eq = equal_time_ratios(t_d, e_d, t_m, e_m)
    return {
        "slopes": slopes,
        "equal_time": {"ratio_geomean": eq["geomean"], "overlap_seconds": eq["overlap"],
                       "at_drpt_times": [{"seconds": t, "ratio": r} for t, r in eq["at_a_times"]]},
        "time_to_error": [{"level": row["level"], "drpt_seconds": row["seconds_a"],
                           "mitsuba_seconds": row["seconds_b"], "ratio": row["ratio"]}
                          for row in time_to_error_ratios(t_d, e_d, t_m, e_m, levels)],
    }


def adaptive_ratio(rows: list[dict]) -> dict:
    """Adaptive against uniform drpt: the equal-time error ratio (geometric mean over the
    common time range) and the error ratio at equal spp (geometric mean over the levels)."""
    def curve(name):
        rs = [r for r in rows if r["renderer"] == name and r["excess_rel_mse"] > 0]
        return {r["spp"]: r for r in rs}

    u, a = curve("drpt"), curve("drpt+adaptive")
    common = sorted(set(u) & set(a))
    if len(common) < 2:
        return {"equal_time_ratio": None, "equal_spp_ratio": None}
    t_u = np.array([u[n]["seconds"] for n in common])
    e_u = np.array([u[n]["excess_rel_mse"] for n in common])
    t_a = np.array([a[n]["seconds"] for n in common])
    e_a = np.array([a[n]["excess_rel_mse"] for n in common])
    eq = equal_time_ratios(t_a, e_a, t_u, e_u)
    return {"equal_time_ratio": eq["geomean"],
            "equal_spp_ratio": float(np.exp(np.mean(np.log(e_a / e_u))))}


# ------------------------------------------------------------ output
FIELDS = ["renderer", "spp", "seconds", "rel_mse", "floor", "excess_rel_mse", "mae", "smape",
          "variance_rel_mse", "bias_rel_mse"]


def write_csv(path: Path, rows: list[dict], fields=FIELDS) -> None:
    try:
        with open(path, "w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    except OSError as e:
        raise DrptError(f"{path}: cannot write: {e.strerror or e}") from e


def _fmt(x, spec=".3g", none="-"):
    return none if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)


def format_table(report: dict) -> str:
    rows = report["rows"]
    lines = [f"{'spp':>6}  {'drpt s':>8}  {'drpt err':>9}  {'Mitsuba s':>9}  "
             f"{'Mits err':>9}  {'err ratio':>9}"]
    d = [r for r in rows if r["renderer"] == "drpt"]
    m = [r for r in rows if r["renderer"] == "mitsuba"]
    for a, b in zip(d, m):
        ratio = a["excess_rel_mse"] / b["excess_rel_mse"] if b["excess_rel_mse"] > 0 else None
        lines.append(f"{a['spp']:>6}  {a['seconds']:>8.3f}  {_fmt(a['excess_rel_mse'], '.3e'):>9}  "
                     f"{b['seconds']:>9.3f}  {_fmt(b['excess_rel_mse'], '.3e'):>9}  "
                     f"{_fmt(ratio, '.3f'):>9}")
    dn = {r["spp"]: r for r in rows if r["renderer"] == "drpt+oidn"}
    if dn:
        lines[0] += f"  {'oidn s':>8}  {'oidn err':>9}  {'bias part':>9}  {'var part':>9}"
        for k, a in enumerate(d, start=1):
            r = dn.get(a["spp"])
            if r is not None:
                lines[k] += (f"  {r['seconds']:>8.3f}  {_fmt(r['excess_rel_mse'], '.3e'):>9}  "
                             f"{_fmt(r['bias_rel_mse'], '.2e'):>9}  "
                             f"{_fmt(r['variance_rel_mse'], '.2e'):>9}")
    lines.append(f"error = relMSE - reference noise floor ({report['noise_floor']:.2e}); "
                 "err ratio = drpt / Mitsuba at equal spp")
    for name in ("drpt", "mitsuba"):
        s = report["slopes"][name]
        se = _fmt(s["stderr"], ".3f", none="")
        se = f" +- {se}" if se else " (two levels: no standard error; raise --max-spp)"
        lines.append(f"{name} log-log slope (spp >= {s['from_spp']}): {_fmt(s['slope'], '.3f')}"
                     f"{se} (1/N: -1)")
    ad = report.get("adaptive")
    if ad is not None:
        for r in (r for r in rows if r["renderer"] == "drpt+adaptive"):
            lines.append(f"adaptive {r['spp']:>6} spp: {r['seconds']:.3f} s, error "
                         f"{_fmt(r['excess_rel_mse'], '.3e')}")
        lines.append(f"adaptive / uniform drpt: equal-time error ratio "
                     f"{_fmt(ad['equal_time_ratio'], '.3f')}, at equal spp "
                     f"{_fmt(ad['equal_spp_ratio'], '.3f')}")
    eq = report["equal_time"]
    lines.append(f"equal-time error ratio drpt/Mitsuba: {_fmt(eq['ratio_geomean'], '.3f')} "
                 "(geometric mean over the common time range)")
    for row in report["time_to_error"]:
        lines.append(f"time to error {row['level']:g}: drpt {_fmt(row['drpt_seconds'], '.3f')} s, "
                     f"Mitsuba {_fmt(row['mitsuba_seconds'], '.3f')} s, ratio "
                     f"{_fmt(row['ratio'], '.3f')}")
    return "\n".join(lines)


def plot(path: Path, report: dict) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rows = report["rows"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    styles = {"drpt": dict(color="C0", marker="o"), "mitsuba": dict(color="C1", marker="s"),
              "drpt+oidn": dict(color="C2", marker="^"), "drpt+adaptive": dict(color="C3", marker="v")}
    for name, st in styles.items():
        rs = [r for r in rows if r["renderer"] == name and r["excess_rel_mse"] > 0]
        if not rs:
            continue
        n = np.array([r["spp"] for r in rs], float)
        t = np.array([r["seconds"] for r in rs])
        e = np.array([r["excess_rel_mse"] for r in rs])
        label = {"mitsuba": "Mitsuba 3", "drpt+oidn": "drpt denoised (OIDN)",
                 "drpt+adaptive": "drpt adaptive"}.get(name, "drpt")
        axes[0].plot(n, e, label=label, **st)
        axes[1].plot(t, e, label=label, **st)
        if name == "drpt":
            # 1/N through the drpt points' geometric mean (spp >= 4 when there are some)
            sel = n >= 4 if (n >= 4).sum() >= 2 else n > 0
            c = float(np.exp(np.mean(np.log(e[sel] * n[sel]))))
            axes[0].plot(n, c / n, "k--", lw=1, label="1/N")
            ct = float(np.exp(np.mean(np.log(e[sel] * t[sel]))))
            axes[1].plot(t, ct / t, "k--", lw=1, label="1/t")
    for ax, xl in zip(axes, ("samples per pixel", "render seconds (compile excluded)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel("relMSE - reference floor")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{Path(report['scene']).name} {report['width']}x{report['height']}, "
                 f"{report['bsdf']}, depth {report['max_depth']}; reference "
                 f"{report['reference']['spp']} spp (floor {report['noise_floor']:.1e})",
                 fontsize=9)
    try:
        fig.savefig(path, dpi=100)
    except OSError as e:
        raise DrptError(f"{path}: cannot write: {e.strerror or e}") from e
    finally:
        plt.close(fig)
