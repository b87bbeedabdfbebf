"""The render flags: argparse for every command that renders, the seed renderer's
spellings among them, and the :class:`~drpt.options.RenderOptions` they give.

* :func:`add_render_flags` adds the shared render flags to a command's
  parser (size, spp, seed, depths and Russian roulette, hide_emitters, the accelerator and
  its BVH rule, integrator, material mode, sky sampling, pixel filter,
  lanes, backend, quiet; for ``render`` also the seed renderer's flags);
  their defaults are :class:`~drpt.options.RenderOptions`' own, so a command
  line without flags gives ``RenderOptions()``;
* :func:`options_from_args` turns the parsed flags into a validated
  :class:`~drpt.options.RenderOptions`. Bad values raise
  :class:`~drpt.errors.DrptError` (the command line prints it on one line and
  exits with status 2);
* :func:`given_settings` names the settings the command line fixed, which a
  scene file's own do not replace (:func:`drpt.options.with_scene_settings`);
* :func:`add_scene_flags`, :func:`add_distributed_flags`,
  :func:`add_view_flags`: the flags of how a Mitsuba XML scene is read, of
  chunked and distributed renders, and of the viewer.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from .. import backend
from ..accel import KINDS, METHODS
from ..errors import DrptError, note, warn
from ..options import (
    BSDF_MODES,
    BVH_KINDS,
    DELTA_LIGHTS,
    ENV_COMPENSATION,
    ENV_SAMPLING,
    GIVEN,
    INTEGRATORS,
    LIGHT_SAMPLERS,
    MODES,
    SAMPLER_CHOICES,
    TARGET_SPP,
    TRIANGLE_SAMPLING,
    PathOptions,
    RenderOptions,
    parse_accel,
)
from ..scene.mitsuba import parse_defines

# Flag groups of add_render_flags; a command leaves out those that it sets itself.
FLAGS = ("size", "spp", "seed", "max_depth", "rr_depth", "rr_prob", "hide_emitters", "accel", "integrator",
         "mode", "bsdf", "env_sampling", "filter", "max_lanes", "backend", "quiet", "scene")


class _AccelChoices(tuple):
    """``--accel``'s argparse choices: lists the kinds, also accepts ``KIND-RULE``."""

    def __contains__(self, value) -> bool:
        try:
            parse_accel(value)
        except DrptError:
            return False
        return True


# ------------------------------------------------------------------ flags
class _Given(argparse._StoreAction):
    """``store``, recording in ``namespace._given`` that the flag was on the command
    line (so a scene file's own settings apply only where the user gave none)."""

    def __call__(self, parser, namespace, values, option_string=None):
        super().__call__(parser, namespace, values, option_string)
        given = set(getattr(namespace, "_given", ()))
        given.add(self.dest)
        namespace._given = given


def given_flags(args: argparse.Namespace) -> set[str]:
    """The dests of the tracked render flags (size, spp, seed, sampler, max_depth,
    rr_depth, hide_emitters, integrator, filter) given on the command line."""
    return set(getattr(args, "_given", ()))


def given_settings(args: argparse.Namespace) -> frozenset[str]:
    """The settings the command line fixed, as :func:`drpt.options.with_scene_settings`
    names them (:data:`drpt.options.GIVEN`): the tracked flags, and the seed's
    ``-RR_cutdown`` (which sets the Russian roulette depth) and ``-MonteCarlo``
    (the integrator)."""
    given = given_flags(args)
    if getattr(args, "rr_cutdown", None) is not None:
        given.add("rr_depth")
    if getattr(args, "monte_carlo", False):
        given.add("integrator")
    if getattr(args, "sampler", None) == "auto":  # the scene file's where it names one
        given.discard("sampler")
    return frozenset(given & set(GIVEN))


def add_render_flags(parser: argparse.ArgumentParser, *, omit=(), seed_flags: bool = False,
                     **defaults) -> None:
    """Add the shared render flags to ``parser``.

    Args:
        omit: flag groups of :data:`FLAGS` the command sets itself (``"accel"``
            is ``--accel``, ``--bvh``, ``--min-leaf``, ``--sah-threshold`` and
            ``--resolution``).
        seed_flags: also the seed renderer's spellings (``-size``, ``-spp``,
            ``-RR_cutdown``, ``-SpatialTree``, ``-resolution``, ``-SAHeuristic``,
            ``-MonteCarlo``, ``-cook_torrance``): ``drpt render`` only.
        defaults: the command's defaults, by group: ``size`` (a pair), ``spp``,
            ``seed``, ``max_depth``, ``rr_depth``, ``accel``, ``integrator``,
            ``bsdf``, ``env_sampling``, ``filter``. ``None`` leaves the choice to
            :func:`options_from_args` (e.g. the seed's defaults with ``-input``).
    """
    unknown = set(omit) - set(FLAGS) | set(defaults) - set(FLAGS)
    if unknown:
        raise ValueError(f"unknown render flag groups {sorted(unknown)}")
    base = RenderOptions()  # drpt's defaults: no flags give RenderOptions()
    d = {"size": (base.width, base.height), "spp": base.spp, "seed": base.seed,
         "max_depth": base.path.max_depth, "rr_depth": base.path.rr_depth,
         "rr_threshold": base.path.rr_threshold,
         "accel": None, "integrator": None, "bsdf": None, "env_sampling": base.env_sampling,
         "filter": base.filter}
    d.update(defaults)

    def want(group: str) -> bool:
        return group not in omit

    def names(modern: str, seed: str | None = None) -> list[str]:
        return [modern, seed] if seed_flags and seed else [modern]

    if want("size"):
        w, h = d["size"]
        parser.add_argument(*names("--size", "-size"), dest="size", nargs=2, type=int, action=_Given,
                            metavar=("W", "H"), default=(w, h),
                            help=f"image size in pixels (default {w} {h})")
    if want("spp"):
        parser.add_argument(*names("--spp", "-spp"), dest="spp", type=int, default=d["spp"], action=_Given,
                            help=f"samples per pixel (default {d['spp']})")
    if want("max_depth"):
        parser.add_argument("--max-depth", type=int, default=d["max_depth"], action=_Given,
                            help="longest path in segments, Mitsuba's convention: 1 = emitters "
                                 "only, 2 = direct light, -1 = unbounded "
                                 f"(default {d['max_depth']})")
    if want("rr_depth"):
        parser.add_argument("--rr-depth", type=int, default=d["rr_depth"], action=_Given,
                            help="depth at which Russian roulette starts "
                                 f"(default {d['rr_depth']})")
    if want("rr_prob"):
        parser.add_argument("--rr-prob", type=float, default=None,
                            help="fixed path continuation probability for Russian roulette "
                                 "(default: adaptive, min(max(throughput) * eta^2, 0.95), "
                                 "Mitsuba's rule)")
        parser.add_argument("--rr-threshold", type=float, default=d["rr_threshold"], action=_Given,
                            help="before --rr-depth, a path whose throughput (times eta^2) is "
                                 "below T continues with probability throughput / T, "
                                 "unbiased; 0: Russian roulette only from --rr-depth, "
                                 "Mitsuba's rule (default "
                                 f"{d['rr_threshold']:g}, 0 for a Mitsuba XML scene)")
        if seed_flags:
            parser.add_argument("-RR_cutdown", dest="rr_cutdown", type=float, default=None,
                                help="seed flag: fixed continuation probability p at every "
                                     "bounce")
    if want("hide_emitters"):
        parser.add_argument("--hide-emitters", dest="hide_emitters", choices=("on", "off"), default=None,
                            action=_Given,
                            help="Mitsuba's hide_emitters: camera rays see no emitter, sky or "
                                 "background, and pass through the area lights they hit to what "
                                 "lies behind (on), or see them (off) (default off, or the scene "
                                 "file's)")
    if want("seed"):
        parser.add_argument("--seed", type=int, default=d["seed"], action=_Given,
                            help=f"random seed (default {d['seed']})")
        parser.add_argument("--sampler", choices=SAMPLER_CHOICES, default=None, action=_Given,
                            help="sample generator: auto (the scene file's where it names one, "
                                 "else ldsampler for the path, volpath, whitted and bdpt integrators "
                                 "and independent for ptracer and --adaptive), "
                                 "independent (a random stream per sample) or "
                                 "ldsampler (a padded Owen-scrambled Sobol (0,2)-sequence per "
                                 "pixel: less noise per sample), zsobol (one such sequence over the "
                                 "image in Morton order: its error as blue noise), Mitsuba's "
                                 "stratified (a square grid of strata), multijitter (Kensler's "
                                 "correlated multi-jittered grid) and orthogonal (a multi-jittered "
                                 "orthogonal array over a prime) "
                                 f"(default {base.sampler})")
        parser.add_argument("--jitter", choices=("on", "off"), default=None, action=_Given,
                            help="stratified, multijitter, orthogonal: a random offset inside each "
                                 "stratum (on, the default, or the scene file's) or its middle")
        parser.add_argument("--strength", type=int, default=None, action=_Given,
                            help="orthogonal: the orthogonal array's strength (default 2, or the "
                                 "scene file's)")
    if want("accel"):
        parser.add_argument("--accel", choices=_AccelChoices(KINDS), default=d["accel"],
                            metavar="{" + ",".join(KINDS) + "}",
                            help="acceleration structure: auto (default: inline up to 64 "
                                 "primitives, else embree on the CPU where Embree 3 is "
                                 "installed, else bvh), inline (every primitive compiled into "
                                 "the kernel as constants), embree (Embree 3's BVH queried "
                                 "from the kernels), bvh (drpt's 4-wide BVH; alias bvh4), "
                                 "bvh2 (the binary BVH it is collapsed from: 2-3x slower, for "
                                 "comparison), grid (uniform grid, 3D-DDA; -resolution N cells "
                                 "per axis) or brute; a BVH kind may name its build rule, "
                                 "bvh-RULE (bvh-sah is --accel bvh --bvh sah)")
        parser.add_argument("--bvh", dest="bvh_method", metavar="|".join(METHODS), default=None,
                            help="BVH build rule: auto (default: sah up to 100k primitives, "
                                 "ploc above), sah (binned SAH everywhere: best trees, slowest "
                                 "build), median (object median), threshold (the seed's: SAH "
                                 "only in nodes of at most 2K primitives, median above; K from "
                                 "--sah-threshold), morton (Morton-ordered binned SAH: fast "
                                 "build) or ploc (bottom-up clustering in Morton order: fast "
                                 "build, trees close to sah's)")
        parser.add_argument("--sah-threshold", *(["-SAHeuristic", "-SAH"] if seed_flags else []),
                            dest="sah_threshold", metavar="K", default=None,
                            help="K of --bvh threshold (implies it; 0 = median everywhere; "
                                 "default 2000, the seed's)")
        parser.add_argument("--min-leaf", dest="min_leaf", metavar="N", default=None,
                            help="minimum primitives per BVH leaf (default 1)")
        if seed_flags:
            parser.add_argument("-SpatialTree", dest="spatial_tree", action="store_true",
                                help="seed flag: use the BVH (the seed's default is the grid)")
        parser.add_argument(*(["--resolution", "-resolution"] if seed_flags else
                              ["--resolution"]), dest="resolution", metavar="N", default=None,
                            help="grid cells per axis (--accel grid), or with the BVH its "
                                 "minimum leaf size (as --min-leaf); the seed's -resolution")
    if want("integrator"):
        default = d["integrator"]
        parser.add_argument("--integrator", choices=INTEGRATORS, default=default, action=_Given,
                            help="path (MIS path tracing, default), whitted, ptracer (light "
                                 "tracing), bdpt (bidirectional) or volpath")
        if seed_flags:
            parser.add_argument("-MonteCarlo", dest="monte_carlo", action="store_true",
                                help="seed flag: Monte Carlo path tracing (the seed's default "
                                     "is Whitted)")
    if want("mode"):
        parser.add_argument("--mode", choices=MODES, default=base.mode,
                            help="how the path tracer (path, volpath) runs: megakernel (default: the whole "
                                 "path loop in one fused kernel) or wavefront (a kernel per stage and "
                                 "bounce: compacted, ray-sorted paths, per-material shading queues and "
                                 "with volpath a medium queue, batched shadow rays)")
        parser.add_argument("--wavefront-tail", dest="wavefront_tail", type=int, default=base.wavefront_tail,
                            metavar="N",
                            help="with --mode wavefront: once at most N paths of a pass are alive, finish "
                                 "them in one fused loop (default 0: every bounce as wavefront stages)")
    if want("bsdf"):
        default = d["bsdf"]
        shown = default or ("auto; phong with -input" if seed_flags else "auto")
        parser.add_argument("--bsdf", choices=BSDF_MODES, default=default,
                            help="how MTL materials are read: auto (each material's own statements "
                                 "decide its model, see docs/scene-format.md), or one model for every "
                                 "material: phong (Kd, Ks, Ns), cook-torrance (Kd, Roughness, Metalness), "
                                 f"diffuse (Kd only) (default {shown})")
        if seed_flags:
            parser.add_argument("-cook_torrance", dest="cook_torrance", action="store_true",
                                help="seed flag: Cook-Torrance shading")
    if want("env_sampling"):
        parser.add_argument("--env-sampling", choices=ENV_SAMPLING, default=d["env_sampling"],
                            help="how sky directions are sampled: by luminance (default) or "
                                 "uniformly over the sphere (for comparison)")
        parser.add_argument("--env-compensation", dest="env_compensation", choices=ENV_COMPENSATION,
                            default=base.env_compensation,
                            help="MIS compensation of the sky's next-event density in path and volpath "
                                 "(sample only where the map is brighter than its mean; the BSDF "
                                 "sample covers the rest) where the scene file does not say (a "
                                 f"Mitsuba envmap's mis_compensation wins) (default {base.env_compensation})")
        parser.add_argument("--light-sampler", dest="light_sampler", choices=LIGHT_SAMPLERS,
                            default=base.light_sampler,
                            help="how next-event estimation picks one emitter per vertex (emissive "
                                 "triangles and spheres, delta lights, the sky): power (each by its "
                                 "emitted power), uniform (Mitsuba's: every emitter alike, then a "
                                 "point by area), mixed (half of each) or bvh (the area emitters "
                                 "by a light BVH: by their importance at the shading point; the "
                                 "others as mixed) "
                                 f"(default {base.light_sampler})")
        parser.add_argument("--delta-lights", dest="delta_lights", choices=DELTA_LIGHTS,
                            default=base.delta_lights,
                            help="how the path tracer reaches delta lights (point, spot, projector, "
                                 "directional) in a scene with other emitters too: each (a shadow ray "
                                 "toward every delta light at every vertex; the light selection picks "
                                 "among the others) or select (in the light selection with the others) "
                                 f"(default {base.delta_lights})")
        parser.add_argument("--triangle-sampling", dest="triangle_sampling", choices=TRIANGLE_SAMPLING,
                            default=base.triangle_sampling,
                            help="how next-event estimation samples a point on an emissive "
                                 "triangle: area (uniform on it, Mitsuba's), solid-angle (uniform "
                                 "in the solid angle it subtends at the shading point, where that is "
                                 "neither tiny nor near a hemisphere; light tracing and bdpt stay "
                                 "on area) or auto (solid-angle where volpath renders a scene with media, "
                                 "area elsewhere) "
                                 f"(default {base.triangle_sampling})")
    if want("filter"):
        parser.add_argument("--filter", dest="filter", metavar="box|tent|gaussian", action=_Given,
                            default=d["filter"],
                            help="pixel reconstruction filter, Mitsuba's: box (the pixel's "
                                 "square), tent[:radius=R] (R default 1) or gaussian[:stddev=S] "
                                 "(S default 0.5; Mitsuba's default filter); tent and gaussian "
                                 "splat each sample into the pixels they cover, as Mitsuba's film "
                                 f"does (default {d['filter']})")
        parser.add_argument("--filter-sampling", dest="filter_sampling", action="store_true",
                            help="tent and gaussian filters: draw each pixel's samples from its "
                                 "filter (filter importance sampling) instead of splatting")
    if want("max_lanes"):
        parser.add_argument("--max-lanes", type=int, default=None,
                            help="samples traced at once; bounds memory (default: the "
                                 "backend's, 2097152 on LLVM)")
    if want("backend"):
        parser.add_argument("--backend", choices=backend.BACKENDS, default=None,
                            help=f"Dr.Jit backend: llvm (CPU) or cuda (NVIDIA GPU); default "
                                 f"${backend.ENV_VAR}, else llvm")
    if want("quiet"):
        parser.add_argument("--quiet", "-q", action="store_true", help="no progress output")
    if want("scene"):
        add_scene_flags(parser)


def add_scene_flags(parser: argparse.ArgumentParser) -> None:
    """How a Mitsuba XML scene is read: ``-D name=value``, ``--ignore-unsupported``, ``--strict``."""
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="NAME=VALUE",
                        help="Mitsuba XML: the value of $NAME in the scene (repeatable)")
    parser.add_argument("--ignore-unsupported", dest="ignore_unsupported", action="store_true",
                        help="Mitsuba XML: render without the plugins drpt does not support (a "
                             "warning each) instead of stopping")
    parser.add_argument("--strict", action="store_true",
                        help="Mitsuba XML: stop on parameters a plugin does not read (older "
                             "exporters' files) instead of ignoring them with a warning")


def scene_flags(args: argparse.Namespace) -> dict:
    """``load_scene``'s keyword arguments from the flags of :func:`add_scene_flags`."""
    return {"defines": parse_defines(getattr(args, "defines", None)),
            "ignore_unsupported": bool(getattr(args, "ignore_unsupported", False)),
            "strict": bool(getattr(args, "strict", False))}


def add_distributed_flags(parser: argparse.ArgumentParser) -> None:
    """``render``'s flags for chunked, distributed and resumable renders
    (:mod:`drpt.distributed`): ``--workers``, ``--cluster``, ``--chunk-spp``,
    ``--resume``, ``--checkpoint-seconds``."""
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="render on a local Dask cluster of N worker processes (needs the "
                             "'cluster' extra: pip install 'drpt[cluster]')")
    parser.add_argument("--cluster", default=None, metavar="ADDRESS",
                        help="render on the Dask scheduler at ADDRESS (tcp://host:8786)")
    parser.add_argument("--chunk-spp", dest="chunk_spp", type=int, default=None, metavar="S",
                        help="samples per pixel of a chunk, the unit of work of a distributed "
                             "render and of checkpoints (default: one pass's samples); part of "
                             "the image's identity, as --seed is")
    parser.add_argument("--resume", action="store_true",
                        help="continue the render from the checkpoint beside --output")
    parser.add_argument("--checkpoint-seconds", dest="checkpoint_seconds", type=float, default=30.0,
                        metavar="T", help="write a checkpoint at most every T seconds while "
                                          "rendering (default 30; 0: after every chunk)")
    parser.add_argument("--target-error", dest="target_error", type=float, default=None, metavar="E",
                        help="stop at the end of the first chunk whose estimated relMSE (from the "
                             "pixels' variances) is at most E; --spp is then the most "
                             f"(default {TARGET_SPP} when not given)")
    parser.add_argument("--time-limit", dest="time_limit", type=float, default=None, metavar="S",
                        help="stop at the end of the first chunk after S seconds of rendering; "
                             f"--spp is then the most (default {TARGET_SPP} when not given)")
    parser.add_argument("--adaptive", action="store_true",
                        help="adaptive sampling: two pilots of spp/8 samples per pixel estimate each "
                             "pixel's error, the rest of the budget (--spp on average) goes to the "
                             "pixels in proportion to it; the image stays unbiased")


# ------------------------------------------------------------------ options
def _int_flag(name: str, text) -> int | None:
    """Parse an integer flag value; a bad one is a one-line DrptError."""
    if text is None:
        return None
    try:
        return int(text)
    except ValueError:
        raise DrptError(f"{name} must be an integer, got {text!r}") from None


def _accel_fields(args, accel: str, seed_mode: bool) -> dict:
    """RenderOptions fields for the accelerator and the BVH build rule from the flags."""
    resolution = _int_flag("-resolution", getattr(args, "resolution", None))
    k = _int_flag("--sah-threshold/-SAHeuristic", getattr(args, "sah_threshold", None))
    min_leaf = _int_flag("--min-leaf", getattr(args, "min_leaf", None))
    method = getattr(args, "bvh_method", None)
    kind, rule = parse_accel(accel)
    if rule is not None:
        if method is not None and method != rule:
            raise DrptError(f"--accel {accel} and --bvh {method} disagree: give the rule once")
        method = rule
    if kind not in BVH_KINDS:
        if method is not None or min_leaf is not None:
            raise DrptError("--bvh and --min-leaf apply to the BVH only "
                            "(--accel bvh, or -SpatialTree with -input)")
        if k is not None:
            note("-SAHeuristic applies to the BVH (-SpatialTree); "
                 f"ignored with --accel {kind}")
        return {"accel": kind, "grid_resolution": resolution if kind == "grid" else None}
    if method is not None and method not in METHODS:
        raise DrptError(f"--bvh must be one of {', '.join(METHODS)}, got {method!r}")
    # With -input the seed's default BVH is its threshold rule (-SAHeuristic 2000).
    method = method or ("threshold" if (k is not None or seed_mode) else "auto")
    if min_leaf is not None and resolution is not None and min_leaf != resolution:
        raise DrptError(f"--min-leaf {min_leaf} and -resolution {resolution} disagree: "
                        "with the BVH both give the minimum leaf size, give one")
    if min_leaf is None:
        min_leaf = resolution
    if min_leaf is not None and min_leaf < 1:
        name = "--min-leaf" if getattr(args, "min_leaf", None) is not None else "-resolution"
        raise DrptError(f"{name} (minimum primitives per BVH leaf) must be >= 1, got {min_leaf}")
    return {"accel": kind, "bvh_method": method, "sah_threshold": k,
            "bvh_min_leaf": min_leaf if min_leaf is not None else 1}


def options_from_args(args: argparse.Namespace, *, seed_mode: bool = False,
                      **overrides) -> RenderOptions:
    """The validated :class:`RenderOptions` the flags of :func:`add_render_flags` give.

    Flags a command left out take :class:`RenderOptions`' defaults. With
    ``seed_mode`` (``render -input``) the seed renderer's defaults apply:
    Whitted ray tracing, the uniform grid, with ``-SpatialTree`` its BVH
    rule (SAH in nodes of at most ``2 * 2000`` primitives). ``overrides``
    replace fields afterwards (before validation). ``--backend`` selects
    the backend (:func:`drpt.backend.select`; an error after kernels were
    loaded on another one). User mistakes raise
    :class:`~drpt.errors.DrptError`.
    """
    def get(name, default=None):
        return getattr(args, name, default)

    if get("backend") is not None:
        backend.select(get("backend"))
    base = RenderOptions()
    width, height = get("size") or (base.width, base.height)
    rr_prob, rr_depth = get("rr_prob"), get("rr_depth", base.path.rr_depth)
    if get("rr_cutdown") is not None:
        rr_prob, rr_depth = get("rr_cutdown"), 1
    integrator = get("integrator") or ("path" if (get("monte_carlo") or not seed_mode)
                                       else "whitted")
    # flags that shape a BVH ask for one rather than the inline accelerator
    bvh_flags = any(get(f) is not None for f in ("bvh_method", "min_leaf", "sah_threshold",
                                                  "resolution"))
    accel = get("accel") or ("grid" if seed_mode and not get("spatial_tree")
                             else "bvh" if get("spatial_tree") else "auto")
    if accel == "auto" and bvh_flags:
        accel = "bvh"
    fields = _accel_fields(args, accel, seed_mode)
    bsdf = get("bsdf") or ("cook-torrance" if get("cook_torrance") else "phong" if seed_mode else "auto")
    opts = RenderOptions(width=width, height=height, spp=get("spp", base.spp),
                         seed=get("seed", base.seed), **fields, bsdf=bsdf,
                         integrator=integrator, mode=get("mode", base.mode),
                         wavefront_tail=get("wavefront_tail", base.wavefront_tail),
                         env_sampling=get("env_sampling", base.env_sampling),
                         env_compensation=get("env_compensation", base.env_compensation),
                         light_sampler=get("light_sampler", base.light_sampler),
                         delta_lights=get("delta_lights", base.delta_lights),
                         triangle_sampling=get("triangle_sampling", base.triangle_sampling),
                         sampler=get("sampler") or base.sampler,
                         jitter=base.jitter if get("jitter") is None else get("jitter") == "on",
                         strength=get("strength") or base.strength,
                         filter=get("filter", base.filter),
                         filter_sampling=bool(get("filter_sampling", base.filter_sampling)),
                         path=PathOptions(max_depth=get("max_depth", base.path.max_depth),
                                          rr_depth=rr_depth, rr_prob=rr_prob,
                                          rr_threshold=get("rr_threshold", base.path.rr_threshold),
                                          hide_emitters=get("hide_emitters") == "on"),
                         max_lanes=get("max_lanes"), chunk_spp=get("chunk_spp"),
                         target_error=get("target_error"), time_limit=get("time_limit"),
                         adaptive=bool(get("adaptive", False)),
                         progress=not get("quiet", False))
    if (opts.target_error is not None or opts.time_limit is not None) and "spp" not in given_flags(args):
        opts = replace(opts, spp=TARGET_SPP)
    return replace(opts, **overrides).validate()


# ------------------------------------------------------------- view flags
def add_view_flags(parser: argparse.ArgumentParser) -> None:
    """The viewer's flags (``drpt view``, ``drpt render -gui``): where it
    listens and where "save camera" writes. Paths come from the command line
    only; the page cannot name one."""
    parser.add_argument("--host", default="127.0.0.1",
                        help="address the viewer listens on (default 127.0.0.1, this machine only)")
    parser.add_argument("--port", type=int, default=8080,
                        help="the viewer's port (default 8080; the next free one if taken)")
    parser.add_argument("--camera-out", dest="camera_out", default=None,
                        help="file that the viewer's \"save camera\" writes the camera block to "
                             "(default: show it in the page and print it)")


def check_view_args(args: argparse.Namespace) -> None:
    """Refuse view flags the viewer cannot use; warn on an address beyond this machine."""
    if not 0 <= args.port <= 65535:
        raise DrptError(f"--port must be in 0..65535, got {args.port}")
    if not args.host.strip():
        raise DrptError("--host is empty: give an address such as 127.0.0.1")
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        warn(f"the viewer listens on {args.host}: other machines that reach it can watch the "
             "scene and start renders (drpt view has no login)")
    if args.camera_out is not None and not args.camera_out.strip():
        raise DrptError("--camera-out is empty: give the file to write the camera block to")
