"""``python -m drpt knobs``: what each quality knob costs and buys, in one table.

::

    python -m drpt knobs SCENE [render flags] [--ref-spp M] [--ref-batches B]
                               [--knobs depth rr accel bsdf light sampler filter integrator adaptive
                                        env-compensation triangle-sampling denoise]
                               [--depths D ...] [--rr-depths K ...] [--rr-probs P ...]
                               [--repeats R] [--cache DIR | --no-cache] [--out DIR]

The render flags are ``render``'s (:func:`drpt.cli.args.add_render_flags`,
``--size`` default 64 64, ``--spp`` 64) except the knobs it varies
(``--max-depth``, ``--rr-depth``, ``--rr-prob``, ``--accel`` and the BVH's).

Every row renders the scene with drpt at ``--spp`` and changes one knob from
the default (``auto`` accelerator, ``--bsdf`` materials, unbounded depth,
Russian roulette from depth 5 with the adaptive probability
``min(max(throughput) * eta^2, 0.95)``, Mitsuba's):

``depth``  ``max_depth`` 2 (direct light only), 3, 5, 8 (``--depths``);
``rr``     Russian roulette from depth 1, 3, 10 (``--rr-depths``, adaptive
           probability); a fixed continuation probability 0.5, 0.8 from depth 1
           (``--rr-probs``, the seed's ``-RR_cutdown``); and off (no roulette,
           paths end after 64 segments: the energy beyond that is ~albedo^64);
``accel``  the 4-wide BVH and the uniform grid instead of the default
           (``auto``: inline for tiny scenes, else Embree where installed, else
           the BVH; same image up to float order);
``bsdf``   the other material mode (Phong <-> Cook-Torrance). That changes the
           scene, so that row is compared with its own reference;
``light``  ``--light-sampler uniform`` and ``bvh`` instead of the default (``mixed``);
``sampler`` each of ``--sampler independent``, ``ldsampler``, ``zsobol``, ``stratified``,
           ``multijitter`` and ``orthogonal`` other than the default row's (``--sampler``, or the scene file's);
``filter`` ``--filter-sampling`` instead of the splatting film (only with a tent or
           Gaussian filter);
``integrator`` light tracing (``ptracer``) and bidirectional path tracing (``bdpt``); a
           scene one cannot render lists its row as not rendered (``skipped``);
``env-compensation`` the sky's next-event estimation with MIS compensation off
           (``--env-compensation off``; ``on`` where the default row's is off): only in a
           scene with an environment map whose file does not set ``mis_compensation``,
           not nearly constant, sampled by luminance (not ``--env-sampling uniform``),
           rendered by an integrator that compensates (``path``, ``volpath``) and whose
           media (if any) lie inside closed shapes (:func:`env_compensation_knob`);
           elsewhere the two settings render the same image and there is no row;
``triangle-sampling`` emissive triangles sampled for next-event estimation by the
           other of ``--triangle-sampling area`` and ``solid-angle`` than the one the
           default row's setting takes (``auto`` takes ``solid-angle`` where volpath renders a scene with media):
           only in a scene with emissive triangles, rendered by an integrator other than
           the light tracers (which sample by area whatever the flag);
``adaptive`` adaptive sampling (``render --adaptive``: the same budget of samples,
           allocated per pixel from two pilots' error estimates; needs ``--spp`` of at
           least 8, else the row is ``skipped``);
``denoise`` the default row's settings, its image denoised by Intel Open Image
           Denoise (``render --denoise``; needs ``pyoidn``, and is in the default
           ``--knobs`` only where it is installed): the seconds include the
           albedo/normal guide kernel and the denoiser, the error and bias are the
           denoised image's, its noise part (``mean(var / w)``) is the variance of
           the denoised images across the ``--repeats`` (none with one repeat).

Columns: render seconds (the fastest of ``--repeats`` timed renders, taken
round robin over the rows so that load from other processes spreads over
all of them; the acceleration build and kernel compilation are excluded: a
1-spp warm-up render per row compiles its kernel first), samples/s, the
error (of the first render) against the
Mitsuba reference of the unbounded, unbiased scene (``excess relMSE``:
relMSE minus the reference's noise floor, as in ``drpt converge``), the
work-normalised error ``relMSE x seconds`` relative to the default row
(``efficiency``: above 1 means a better trade than the default at equal
time, as long as the row is unbiased), and the bias: the relative
difference of the image means, ``(mean(x) - mean(ref)) / mean(ref)``, with
its standard error ``mean_c sqrt(sum_p (var_x + var_ref)) / n_pixels / mean(ref)``
(per-pixel variances of drpt and of the reference's batches, the channels taken
as perfectly correlated, which they nearly are: :func:`image_bias`), from the mean
of all ``--repeats`` renders (independent seeds, ``repeats x spp`` samples
per pixel), so more repeats resolve smaller biases. Rows whose
difference is more than 3 standard errors are marked biased. Truncating
the depth is biased (light is lost); Russian roulette is not (it only adds
noise). ``bias relMSE`` is ``excess - mean(var_x / w)``: the part of the
error that more samples will not remove (noisy; ~0 for unbiased rows).

The references are the ones ``compare`` and ``converge`` cache
(:func:`drpt.tools.reference.get_reference`). Output in ``--out`` (default
``knobs_<scene stem>/``): ``knobs.md`` (the table and these notes),
``knobs.csv`` and ``knobs.json``. The table goes to stdout. Seconds depend on
the machine's load; the ratios between rows are what to read.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import metrics
from ..cli.args import add_render_flags, options_from_args
from ..denoise import available, denoise_result, require
from ..errors import DrptError
from ..options import LIGHT_TRACED, RR_THRESHOLD, PathOptions, RenderOptions, resolve_sampler
from ..render.adaptive import check
from ..render.lights.area import triangle_sampling_rule
from ..render.lights.envmap import EnvironmentLight
from ..render.renderer import Renderer
from ..render.scene import emitting, env_compensated
from ..scene import load_scene
from ..scene.model import Skybox
from . import table as _table
from .compare import _prepare_out, _write_json
from .converge import noise_floor, write_csv
from .reference import (
    add_reference_args,
    cache_dir_from_args,
    check_reference_args,
    get_reference,
)

KNOBS = ("depth", "rr", "accel", "bsdf", "light", "sampler", "filter", "integrator", "adaptive",
         "env-compensation", "triangle-sampling", "denoise")
#: the ``sampler`` knob's settings
SAMPLER_KNOB = ("independent", "ldsampler", "zsobol", "stratified", "multijitter", "orthogonal")
RR_OFF_DEPTH = 64

__all__ = ["add_parser", "main", "Config", "configs", "knobs_study", "image_bias", "env_compensation_knob",
           "triangle_sampling_knob"]


@dataclass
class Config:
    knob: str
    setting: str
    bsdf: str
    accel: str = "auto"
    max_depth: int = -1
    rr_depth: int = 5
    rr_prob: float | None = None
    rr_threshold: float | None = None  # None: the default row's (the options')
    denoise: bool = False
    integrator: str = "path"
    light_sampler: str = RenderOptions.light_sampler
    filter_sampling: bool = False
    adaptive: bool = False
    sampler: str | None = None  # None: the default row's (the options')
    env_compensation: str | None = None  # None: the default row's (the options')
    triangle_sampling: str | None = None  # None: the default row's (the options')


def default_knobs() -> list[str]:
    """Every knob; ``denoise`` only where pyoidn is installed."""
    return [k for k in KNOBS if k != "denoise" or available()]


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``knobs`` subcommand on an ``add_subparsers()`` object."""
    p = subparsers.add_parser(
        "knobs", allow_abbrev=False,
        help="time, error and bias of each quality knob (depth, RR, accel, material)",
        description="render SCENE with drpt changing one quality knob at a time; report "
                    "time, samples/s, error against a Mitsuba reference and bias")
    p.add_argument("scene", help="scene file")
    add_render_flags(p, omit=("max_depth", "rr_depth", "rr_prob", "hide_emitters", "accel"), size=(64, 64),
                     spp=64)
    p.add_argument("--knobs", nargs="+", choices=KNOBS, default=None,
                   help="which knobs to vary (default all; denoise where pyoidn is installed)")
    p.add_argument("--depths", type=int, nargs="+", default=[2, 3, 5, 8], metavar="D",
                   help="max depths to try (default 2 3 5 8; unbounded is the default row)")
    p.add_argument("--rr-depths", type=int, nargs="+", default=[1, 3, 10], metavar="K",
                   help="Russian roulette start depths to try (default 1 3 10)")
    p.add_argument("--rr-probs", type=float, nargs="+", default=[0.5, 0.8], metavar="P",
                   help="fixed continuation probabilities to try (default 0.5 0.8)")
    p.add_argument("--repeats", type=int, default=3,
                   help="renders per row: the fastest time counts, all of them go into the "
                        "bias estimate (default 3)")
    p.add_argument("--out", default=None, help="output folder (default knobs_<name>/)")
    add_reference_args(p, ref_spp=4096)
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    options = options_from_args(args)
    scene = Path(args.scene)
    out = Path(args.out) if args.out else Path(f"knobs_{scene.stem}")
    report = knobs_study(scene, out, options, ref_spp=args.ref_spp,
                         ref_batches=args.ref_batches,
                         knobs=args.knobs if args.knobs is not None else default_knobs(),
                         depths=args.depths,
                         rr_depths=args.rr_depths, rr_probs=args.rr_probs,
                         repeats=args.repeats, cache_dir=cache_dir_from_args(args))
    print(report["markdown_table"])
    print(f"{out}: knobs.md, knobs.csv, knobs.json")
    return 0


def env_compensation_knob(scene, options: RenderOptions) -> str | None:
    """The default row's ``--env-compensation`` where the other setting renders ``scene``
    differently, else None (no ``env-compensation`` row): where
    :func:`~drpt.render.scene.env_compensated` differs (an environment map whose file
    leaves ``mis_compensation`` unset, a compensating integrator, media inside closed
    shapes), the sky is sampled by luminance (not ``--env-sampling uniform``) and the map
    is not so nearly constant or black that compensation leaves it as it is
    (:meth:`~drpt.render.lights.envmap.EnvironmentLight.compensated`; the map is read)."""
    if options.env_sampling == "uniform":
        return None
    for sky in (light for light in scene.lights if isinstance(light, Skybox)):
        if env_compensated(sky, replace(options, env_compensation="on"), scene) != \
                env_compensated(sky, replace(options, env_compensation="off"), scene):
            light = EnvironmentLight.from_file(sky.path, scale=sky.scale)
            if light.compensated() is not light:
                return options.env_compensation
    return None


def triangle_sampling_knob(scene, options: RenderOptions) -> str | None:
    """What next-event estimation of the default row does with emissive triangles,
    ``area`` or ``solid-angle`` (``options.triangle_sampling`` with ``auto`` resolved,
    :func:`~drpt.render.lights.area.triangle_sampling_rule`), or None where the flag does
    not change the image: no emissive triangle, or a light tracer (``ptracer``, ``bdpt``:
    always by area)."""
    if options.integrator in LIGHT_TRACED or not len(scene.triangles):
        return None
    emits = emitting(scene)
    if not emits.any() or not emits[np.asarray(scene.triangles.material, np.int64)].any():
        return None
    return "solid-angle" if triangle_sampling_rule(options.triangle_sampling, scene, options.integrator) else "area"


def configs(bsdf: str, knobs=KNOBS[:4], depths=(2, 3, 5, 8), rr_depths=(1, 3, 10),
            rr_probs=(0.5, 0.8), filtered: bool = False, sampler: str = "independent",
            env_compensation: str | None = None, triangle_sampling: str | None = None,
            rr_threshold: float = RR_THRESHOLD, rr_thresholds=(0.0, 0.1, 0.3)) -> list[Config]:
    """The default row, then one row per knob setting (``filter`` only for a tent or
    Gaussian filter, ``filtered``; ``sampler``: the default row's ``--sampler``;
    ``rr_threshold``: the default row's ``--rr-threshold``, whose other settings
    ``rr_thresholds`` are rows of the ``rr`` knob;
    ``env_compensation`` and ``triangle_sampling``: the default row's settings
    (:func:`env_compensation_knob`, :func:`triangle_sampling_knob`), None where the scene
    has no such feature: no row)."""
    below = f", below throughput {rr_threshold:g} before it" if rr_threshold > 0.0 else ""
    rows = [Config("default", f"auto accel, unbounded depth, RR from depth 5 (adaptive){below}", bsdf)]
    # light tracing (ptracer) and adaptive sampling draw independent samples (drpt.options.resolve_sampler):
    # where the default row's sampler is another, their rows say so, as that is part of their change
    indep = "" if sampler == "independent" else "; independent samples"
    if "depth" in knobs:
        rows += [Config("max depth", str(d), bsdf, max_depth=d) for d in depths]
    if "rr" in knobs:
        rows += [Config("RR", f"from depth {k}, adaptive", bsdf, rr_depth=k)
                 for k in rr_depths if k != 5]
        rows += [Config("RR", f"from depth 1, fixed p = {p:g}", bsdf, rr_depth=1, rr_prob=p)
                 for p in rr_probs]
        rows += [Config("RR", f"below throughput {t:g} before depth 5" if t > 0.0
                        else "none before depth 5 (Mitsuba's rule)", bsdf, rr_threshold=t)
                 for t in rr_thresholds if t != rr_threshold]
        rows.append(Config("RR", f"off (depth <= {RR_OFF_DEPTH})", bsdf,
                           max_depth=RR_OFF_DEPTH, rr_depth=RR_OFF_DEPTH + 1, rr_threshold=0.0))
    if "accel" in knobs:
        rows += [Config("accel", a, bsdf, accel=a) for a in ("bvh", "grid")]
    if "bsdf" in knobs:
        other = "cook-torrance" if bsdf == "phong" else "phong"
        rows.append(Config("material", f"{other} (own reference)", other))
    if "light" in knobs:
        rows.append(Config("light sampler", "uniform (Mitsuba's: every emitter alike)", bsdf,
                           light_sampler="uniform"))
        rows.append(Config("light sampler", "bvh (light BVH: importance at the shading point)", bsdf,
                           light_sampler="bvh"))
    if "sampler" in knobs:
        rows += [Config("sampler", name, bsdf, sampler=name) for name in SAMPLER_KNOB if name != sampler]
    if "filter" in knobs and filtered:
        rows.append(Config("filter", "filter importance sampling instead of splatting", bsdf,
                           filter_sampling=True))
    if "integrator" in knobs:
        rows.append(Config("integrator", f"ptracer (light tracing{indep})", bsdf, integrator="ptracer"))
        rows.append(Config("integrator", "bdpt (bidirectional)", bsdf, integrator="bdpt"))
    if "env-compensation" in knobs and env_compensation is not None:
        other = "off" if env_compensation == "on" else "on"
        rows.append(Config("env compensation", f"{other} (--env-compensation {other})", bsdf,
                           env_compensation=other))
    if "triangle-sampling" in knobs and triangle_sampling is not None:
        other = "area" if triangle_sampling == "solid-angle" else "solid-angle"
        rows.append(Config("triangle sampling", f"{other} (--triangle-sampling {other})", bsdf,
                           triangle_sampling=other))
    if "adaptive" in knobs:
        rows.append(Config("sampling", f"adaptive (--adaptive{indep})", bsdf, adaptive=True))
    if "denoise" in knobs:
        rows.append(Config("denoise", "OIDN on the default row's image", bsdf, denoise=True))
    return rows


def image_bias(x, var_x, ref, var_ref) -> tuple[float, float]:
    """Relative difference of the image means (over pixels and channels) and its
    standard error.

    The variances are per pixel and channel; the channels of one sample are
    correlated (a path that finds the light brightens R, G and B at once), and the
    renderers report no covariance. So the standard error is the bound for perfectly
    correlated channels, ``mean_c sqrt(sum_p var_pc) / n_pixels / mean(ref)``, exact
    for gray scenes and at most sqrt(3) too large: summing the channels' variances as
    if independent (``sqrt(sum var) / n``) made it up to sqrt(3) too small, and
    unbiased settings read "biased"."""
    x, ref = np.asarray(x, np.float64), np.asarray(ref, np.float64)
    m = float(ref.mean())
    if m <= 0:
        return float("nan"), float("nan")
    diff = float(x.mean() - m) / m
    var = np.asarray(var_x, np.float64) + np.asarray(var_ref, np.float64)
    var = np.broadcast_to(var, x.shape)
    channels = var.reshape(-1, var.shape[-1]) if var.ndim == 3 else var.reshape(-1, 1)
    pixels = channels.shape[0]
    se = float(np.mean(np.sqrt(channels.sum(axis=0))) / pixels / m)
    return diff, se


def knobs_study(scene_path: Path, out: Path, options, ref_spp: int = 4096,
                ref_batches: int = 8, knobs=None, depths=(2, 3, 5, 8), rr_depths=(1, 3, 10),
                rr_probs=(0.5, 0.8), repeats: int = 3, cache_dir: Path | None = None) -> dict:
    """Run the study (see the module docs) from drpt's ``options`` (a
    :class:`~drpt.options.RenderOptions`: size, spp, seed and material mode of
    the default row; each row changes its knob); write the outputs; return
    the report."""
    options.validate()
    width, height, spp, seed, bsdf = (options.width, options.height, options.spp,
                                      options.seed, options.bsdf)
    progress = options.progress
    scene_path = Path(scene_path)
    if spp < 2:
        raise DrptError(f"--spp must be at least 2 (for a variance), got {spp}")
    if repeats < 1:
        raise DrptError(f"--repeats must be positive, got {repeats}")
    if any(d < 1 for d in depths):
        raise DrptError(f"--depths must be >= 1, got {list(depths)}")
    if any(k < 1 for k in rr_depths):
        raise DrptError(f"--rr-depths must be >= 1, got {list(rr_depths)}")
    if any(not (0.0 < p <= 1.0) for p in rr_probs):
        raise DrptError(f"--rr-probs must be in (0, 1], got {list(rr_probs)}")
    check_reference_args(ref_spp, ref_batches, -1, 5, announce=False)
    knobs = default_knobs() if knobs is None else knobs
    if "denoise" in knobs:
        require()
    scene = load_scene(scene_path)
    _prepare_out(out)

    refs = {}

    def reference(mode):
        if mode not in refs:
            r = get_reference(
                scene, scene_path.stem, width, height, ref_spp=ref_spp, ref_batches=ref_batches,
                bsdf=mode, max_depth=-1, rr_depth=5, seed=seed, cache_dir=cache_dir,
                progress=progress, rfilter=options.filter)
            refs[mode] = {"image": r.image, "variance": r.variance,
                          "floor": noise_floor(r.image, r.variance), "info": r.info()}
        return refs[mode]

    cfgs = configs(bsdf, knobs, depths, rr_depths, rr_probs,
                   filtered=not options.pixel_filter.is_box, sampler=resolve_sampler(options).sampler,
                   env_compensation=env_compensation_knob(scene, options),
                   triangle_sampling=triangle_sampling_knob(scene, options),
                   rr_threshold=options.path.rr_threshold)
    renderers = []
    skipped = []
    for c in list(cfgs):
        if c.adaptive and spp < 8:
            skipped.append(f"{c.knob} {c.setting}: --adaptive needs --spp of at least 8")
            cfgs.remove(c)
            continue
        opts = replace(options, spp=8 if c.adaptive else 1, seed=seed + 999_999, accel=c.accel,
                       bsdf=c.bsdf, adaptive=c.adaptive, variance=True,
                       progress=False, denoise=c.denoise, integrator=c.integrator,
                       light_sampler=c.light_sampler, filter_sampling=c.filter_sampling,
                       sampler=c.sampler or options.sampler,
                       env_compensation=c.env_compensation or options.env_compensation,
                       triangle_sampling=c.triangle_sampling or options.triangle_sampling,
                       path=PathOptions(max_depth=c.max_depth, rr_depth=c.rr_depth,
                                        rr_prob=c.rr_prob,
                                        rr_threshold=options.path.rr_threshold if c.rr_threshold is None
                                        else c.rr_threshold))
        try:
            if c.adaptive:
                check(opts)  # (a splatting filter, light tracing, ...: one line, the row skipped)
            renderer = Renderer(scene, opts)
        except DrptError as e:  # a setting this scene cannot take (light tracing a rough glass)
            if c.knob == "default":
                raise
            skipped.append(f"{c.knob} {c.setting}: {e}")
            cfgs.remove(c)
            continue
        reference(c.bsdf)
        renderer.render()  # warm-up: compiles this row's kernel
        renderer.opt.spp = spp
        renderers.append(renderer)
    # Round robin over the rows, so load from other processes spreads over all of them.
    results = [[] for _ in cfgs]
    for k in range(repeats):
        for i, renderer in enumerate(renderers):
            renderer.opt.seed = seed + 1 + i + 1000 * k
            results[i].append(_render(renderer))
            if progress:
                print(f"\rknobs: repeat {k + 1}/{repeats}, row {i + 1}/{len(cfgs)}", end="",
                      file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)

    rows = []
    for c, renderer, rs in zip(cfgs, renderers, results):
        ref = refs[c.bsdf]
        best = min(r.seconds for r in rs)
        first = rs[0]
        x, w = first.image, ref["image"].astype(np.float64) ** 2 + 1e-2
        rel = metrics.rel_mse(x, ref["image"])
        excess = rel - ref["floor"]
        # The bias uses every repeat (independent seeds): the mean image of R
        # renders, with variance of the mean var / R.
        mean_img = np.mean([r.image for r in rs], axis=0)
        if c.denoise:  # the denoised images' variance: their spread across the repeats
            var = (np.var([r.image for r in rs], axis=0, ddof=1, dtype=np.float64)
                   if len(rs) > 1 else np.full(x.shape, np.nan))
            pred = float(np.mean(var / w))
            mean_var = var / len(rs)
        else:
            pred = float(np.mean(first.variance / w))
            mean_var = np.mean([r.variance for r in rs], axis=0) / len(rs)
        bias, bias_se = image_bias(mean_img, mean_var, ref["image"], ref["variance"])
        rows.append({
            "knob": c.knob, "setting": c.setting, "bsdf": c.bsdf, "accel": c.accel,
            "max_depth": c.max_depth, "rr_depth": c.rr_depth, "rr_prob": c.rr_prob,
            "rr_threshold": renderer.opt.path.rr_threshold,
            "spp": int(spp), "seconds": best, "build_seconds": renderer.build_seconds,
            "samples_per_second": width * height * spp / max(best, 1e-9),
            "rel_mse": rel, "excess_rel_mse": excess, "noise_rel_mse": pred,
            "bias_rel_mse": excess - pred, "mean_bias": bias, "mean_bias_se": bias_se,
            "bias_spp": int(spp * len(rs)), "biased": bool(abs(bias) > 3 * bias_se),
            "nonfinite": int(sum(r.nonfinite for r in rs)),
        })
    base = rows[0]["excess_rel_mse"] * rows[0]["seconds"]
    for r in rows:
        work = r["excess_rel_mse"] * r["seconds"]
        r["efficiency"] = base / work if work > 0 else float("nan")

    table = markdown_table(rows)
    if skipped:
        table += "\n\nNot rendered (the scene cannot take them):\n" + "\n".join(f"* {s}" for s in skipped)
    report = {
        "scene": str(scene_path), "width": int(width), "height": int(height), "spp": int(spp),
        "bsdf": bsdf, "repeats": int(repeats), "seed": int(seed), "rows": rows,
        "references": {m: dict(r["info"], noise_floor=r["floor"]) for m, r in refs.items()},
        "markdown_table": table, "skipped": skipped,
    }
    fields = ["knob", "setting", "bsdf", "accel", "max_depth", "rr_depth", "rr_prob", "rr_threshold", "spp",
              "seconds", "build_seconds", "samples_per_second", "rel_mse", "excess_rel_mse",
              "noise_rel_mse", "bias_rel_mse", "efficiency", "mean_bias", "mean_bias_se",
              "bias_spp", "biased", "nonfinite"]
    write_csv(out / "knobs.csv", rows, fields)
    _write_json(out / "knobs.json", report)
    doc = (f"# Quality knobs: {scene_path.name}, {width}x{height}, {spp} spp\n\n{table}\n\n"
           + "\n".join(f"- reference ({m}): Mitsuba {r['info']['spp']} spp in "
                       f"{r['info']['batches']} batches, noise floor {r['floor']:.1e}"
                       for m, r in refs.items())
           + "\n\n" + __doc__.split("\n\n", 2)[2])
    try:
        (out / "knobs.md").write_text(doc, encoding="utf-8")
    except OSError as e:
        raise DrptError(f"{out / 'knobs.md'}: cannot write: {e.strerror or e}") from e
    return report


def _render(renderer):
    """``renderer.render()``; with ``denoise`` the result's image is the denoised one and
    its seconds include the denoiser's."""
    import time

    r = renderer.render()
    if renderer.opt.denoise:
        t0 = time.perf_counter()
        r.image = denoise_result(r)
        r.seconds += time.perf_counter() - t0
    return r


def markdown_table(rows: list[dict]) -> str:
    header = ["knob", "setting", "seconds", "Msamples/s", "excess relMSE",
              "efficiency vs default", f"mean bias (± s.e., {rows[0]['bias_spp']} spp)"]
    cells = []
    for r in rows:
        bias = f"{100 * r['mean_bias']:+.2f}%"
        bias += f" ± {100 * r['mean_bias_se']:.2f}%" if np.isfinite(r["mean_bias_se"]) else " (no s.e.)"
        bias += " **biased**" if r["biased"] else ""
        eff = r["efficiency"]
        cells.append([r["knob"], r["setting"], f"{r['seconds']:.2f}",
                      f"{r['samples_per_second'] / 1e6:.3f}", f"{r['excess_rel_mse']:.2e}",
                      f"{eff:.2f}" if np.isfinite(eff) else "-", bias])
    return _table.markdown_table(header, cells, align="--rrrr-")
