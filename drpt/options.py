"""Render options: what every command that renders passes to the renderer.

:class:`RenderOptions` (with :class:`PathOptions`) is what the renderer
takes. Every command builds it the same way:

* :func:`add_render_flags` adds the shared render flags to a command's
  parser (size, spp, seed, depths and Russian roulette, the accelerator and
  its BVH rule, integrator, material mode, sky sampling, pixel filter,
  lanes, backend, quiet; for ``render`` also the seed renderer's flags);
* :func:`options_from_args` turns the parsed flags into a validated
  :class:`RenderOptions`. Bad values raise :class:`~drpt.errors.DrptError`
  (the command line prints it on one line and exits with status 2);
  :meth:`RenderOptions.validate` makes the same checks for options built
  in code.

Accelerators are named by one vocabulary: a kind of
:data:`drpt.accel.KINDS`, optionally with a BVH rule of
:data:`drpt.accel.METHODS` joined by a dash, ``KIND-RULE`` (``bvh-sah`` is
``--accel bvh --bvh sah``); :func:`parse_accel` reads it. ``drpt bench``
takes a comma-separated list of such names.

This module imports no kernel: the accelerator vocabulary is imported when a
parser is built or options are checked, after the CLI chose the backend.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field

from .errors import DrptError, note, warn

BSDF_MODES = ("auto", "phong", "cook-torrance", "diffuse")  # drpt.shading.MODES
INTEGRATORS = ("path", "whitted", "ptracer", "volpath")
MODES = ("megakernel", "wavefront")  # how the path integrator runs (drpt.render.integrators)
ENV_SAMPLING = ("luminance", "uniform")
LIGHT_SAMPLERS = ("power", "uniform", "bvh")  # drpt.render.lights.area
#: --sampler names (drpt.render.sampler): independent, drpt's low-discrepancy sampler, and
#: Mitsuba's other sampler plugins, which draw from the low-discrepancy one
SAMPLERS = ("independent", "ldsampler", "zsobol", "stratified", "multijitter", "orthogonal")
BVH_KINDS = ("bvh", "bvh2", "bvh4")
GRID_MAX_RESOLUTION = 256

# Limits of the numbers the renderer and the Mitsuba export hold (RenderOptions.validate):
MAX_SIZE = 1 << 16  # pixels per side: pixel coordinates and their jitter are float32
MAX_SPP = (1 << 32) - 1  # samples per pixel: Mitsuba's sample_count is 32-bit
MAX_SAMPLES = 1 << 60  # width * height * spp: PCG32 sequence ids (pass * lanes + lane) stay < 2^63
MAX_LANES = (1 << 32) - 1  # lanes per pass: lane ids are UInt32
MAX_DEPTH = (1 << 32) - 1  # --max-depth, --rr-depth: path depths are UInt32
MAX_SEED = (1 << 64) - 1  # the seed is hashed as a 64-bit integer

# Flag groups of add_render_flags; a command leaves out those that it sets itself.
FLAGS = ("size", "spp", "seed", "max_depth", "rr_depth", "rr_prob", "accel", "integrator", "mode",
         "bsdf", "env_sampling", "filter", "max_lanes", "backend", "quiet", "scene")


@dataclass
class PathOptions:
    max_depth: int = -1
    rr_depth: int = 5
    rr_prob: float | None = None  # fixed continuation probability, or adaptive
    hide_emitters: bool = False  # camera rays do not see emitters or the sky (Mitsuba's hide_emitters)


@dataclass
class RenderOptions:
    width: int = 256
    height: int = 256
    spp: int = 16
    seed: int = 0
    accel: str = "auto"  # drpt.accel.build_accel kind ("auto": inline for tiny scenes, else embree or bvh)
    grid_resolution: int | None = None  # cells per axis for accel="grid" (None: automatic)
    bvh_method: str = "auto"  # BVH split rule, drpt.accel.METHODS (accel="bvh")
    sah_threshold: int | None = None  # K of bvh_method="threshold" (None: the seed's 2000)
    bvh_min_leaf: int = 1  # minimum primitives per BVH leaf (the seed's -resolution)
    bsdf: str = "auto"  # how MTL materials are read, see drpt.shading
    integrator: str = "path"  # "path" (MIS path tracing), "whitted" or "ptracer" (light tracing)
    mode: str = "megakernel"  # path tracing as one fused kernel, or "wavefront" (a kernel per stage)
    wavefront_tail: int = 0  # wavefront: finish in one fused loop once at most this many paths live
    env_sampling: str = "luminance"  # or "uniform" (for comparison only)
    #: how next-event estimation picks an area light: "power" (each emissive primitive by its
    #: power) or "uniform" (Mitsuba's: each emitter alike, then a point by area)
    light_sampler: str = "power"
    #: what the camera passes' random numbers are drawn from (:mod:`drpt.render.sampler`):
    #: "independent" (a PCG32 stream per lane) or a low-discrepancy sampler's name
    sampler: str = "independent"
    filter: str = "box"  # pixel reconstruction filter, drpt.filters.parse_filter's spelling
    filter_sampling: bool = False  # tent/gaussian: draw samples from the filter instead of splatting
    #: stop once the estimated relMSE (drpt.metrics.estimated_rel_mse) is at most this, or
    #: once time_limit seconds have passed, at the end of a chunk; spp is then the most
    target_error: float | None = None
    time_limit: float | None = None
    path: PathOptions = field(default_factory=PathOptions)
    max_lanes: int | None = None  # samples traced at once (None: drpt.backend.policy().max_lanes)
    chunk_spp: int | None = None  # samples per pixel of a chunk (None: one pass step), drpt.render.chunks
    progress: bool = True
    #: also sum each sample's color products (Mitsuba's ``moment`` integrator: the result's
    #: ``moment2``, the per-sample second moment of the pixel in CIE XYZ)
    moment: bool = False
    #: AOVs traced beside the image, ``(name, type)`` pairs (:mod:`drpt.aovs`, ``--aovs``)
    aovs: tuple = ()
    #: also trace the denoiser's albedo and normal guides (``--denoise``, :mod:`drpt.denoise`)
    denoise: bool = False
    #: allocate samples per pixel from a pilot's estimated error (``--adaptive``,
    #: :mod:`drpt.render.adaptive`); ``spp`` is then the average
    adaptive: bool = False

    def validate(self) -> RenderOptions:
        """Raise :class:`~drpt.errors.DrptError` on a value the renderer cannot
        use (messages name the command-line flag); return ``self``."""
        from .accel import KINDS, METHODS, NO_MIN_LEAF
        from .accel.bvh4_nodes import LEAF_MAX_COUNT

        if min(self.width, self.height) <= 0:
            raise DrptError(f"size must be positive, got {min(self.width, self.height)}")
        if max(self.width, self.height) > MAX_SIZE:
            raise DrptError(f"size must be at most {MAX_SIZE} pixels per side, got "
                            f"{self.width} {self.height}")
        if self.spp <= 0:
            raise DrptError(f"--spp must be positive, got {self.spp}")
        if self.spp > MAX_SPP:
            raise DrptError(f"--spp must be at most {MAX_SPP}, got {self.spp}")
        if self.width * self.height * self.spp > MAX_SAMPLES:
            raise DrptError(f"width * height * spp must be at most 2^60, got "
                            f"{self.width} * {self.height} * {self.spp}")
        if self.max_lanes is not None and not 0 < self.max_lanes <= MAX_LANES:
            raise DrptError(f"--max-lanes must be between 1 and {MAX_LANES}, got {self.max_lanes}")
        if self.chunk_spp is not None and not 0 < self.chunk_spp <= MAX_SPP:
            raise DrptError(f"--chunk-spp must be between 1 and {MAX_SPP}, got {self.chunk_spp}")
        if self.target_error is not None and not (math.isfinite(self.target_error) and self.target_error > 0):
            raise DrptError(f"--target-error must be a positive number, got {self.target_error}")
        if self.time_limit is not None and not (math.isfinite(self.time_limit) and self.time_limit > 0):
            raise DrptError(f"--time-limit must be a positive number of seconds, got {self.time_limit}")
        if not 0 <= self.seed <= MAX_SEED:
            raise DrptError(f"--seed must be between 0 and 2^64 - 1, got {self.seed}")
        p = self.path
        if p.max_depth == 0 or p.max_depth < -1 or p.max_depth > MAX_DEPTH:
            raise DrptError(f"--max-depth must be -1 (unbounded) or between 1 and {MAX_DEPTH}, "
                            f"got {p.max_depth}")
        if not 0 <= p.rr_depth <= MAX_DEPTH:
            raise DrptError(f"--rr-depth must be between 0 and {MAX_DEPTH}, got {p.rr_depth}")
        if p.rr_prob is not None and not (0.0 < p.rr_prob <= 1.0):
            raise DrptError(f"Russian roulette probability must be in (0, 1], got {p.rr_prob}")
        for name, value, allowed in (("--accel", self.accel, KINDS),
                                     ("--bvh", self.bvh_method, METHODS),
                                     ("--bsdf", self.bsdf, BSDF_MODES),
                                     ("--integrator", self.integrator, INTEGRATORS),
                                     ("--mode", self.mode, MODES),
                                     ("--env-sampling", self.env_sampling, ENV_SAMPLING),
                                     ("--light-sampler", self.light_sampler, LIGHT_SAMPLERS),
                                     ("--sampler", self.sampler, SAMPLERS)):
            if value not in allowed:
                raise DrptError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
        from .filters import parse_filter

        parse_filter(self.filter)  # raises DrptError on a bad --filter
        from .aovs import check_aovs

        check_aovs(self.aovs)
        if not 0 <= self.wavefront_tail <= MAX_LANES:
            raise DrptError(f"--wavefront-tail must be between 0 and {MAX_LANES}, got {self.wavefront_tail}")
        if self.mode == "wavefront" and self.integrator != "path":
            raise DrptError(f"--mode wavefront runs the path integrator, not --integrator {self.integrator}")
        if self.accel == "grid" and self.grid_resolution is not None and \
                not 1 <= self.grid_resolution <= GRID_MAX_RESOLUTION:
            raise DrptError(f"-resolution must be between 1 and {GRID_MAX_RESOLUTION} grid cells "
                            f"per axis, got {self.grid_resolution}")
        if self.accel in ("auto", *BVH_KINDS):
            k, method = self.sah_threshold, self.bvh_method
            if k is not None and method != "threshold":
                raise DrptError(f"--sah-threshold/-SAHeuristic applies to --bvh threshold, "
                                f"not --bvh {method}")
            if k is not None and k < 0:
                raise DrptError(f"--sah-threshold/-SAHeuristic must be >= 0, got {k}")
            if self.bvh_min_leaf < 1:
                raise DrptError("--min-leaf/-resolution (minimum primitives per BVH leaf) must "
                                f"be >= 1, got {self.bvh_min_leaf}")
            if method in NO_MIN_LEAF and self.bvh_min_leaf != 1:
                raise DrptError("--min-leaf/-resolution applies to --bvh sah, median and "
                                f"threshold, not {method}")
            # leaves hold up to 2 * min_leaf - 1 primitives; a 4-wide BVH leaf at most 16
            most = (LEAF_MAX_COUNT + 1) // 2
            if self.accel != "bvh2" and self.bvh_min_leaf > most:
                raise DrptError(f"--min-leaf/-resolution (minimum primitives per BVH leaf) must "
                                f"be at most {most} with the 4-wide BVH (its leaves hold at most "
                                f"{LEAF_MAX_COUNT}), got {self.bvh_min_leaf}; --accel bvh2 "
                                "takes any")
        if self.adaptive:
            from .render.adaptive import check

            check(self)
        return self

    @property
    def pixel_filter(self):
        """The :class:`~drpt.filters.PixelFilter` that :attr:`filter` names."""
        from .filters import parse_filter

        return parse_filter(self.filter)


# ------------------------------------------------------------------ accelerator names
def parse_accel(spec: str) -> tuple[str, str | None]:
    """``KIND`` or ``KIND-RULE`` -> ``(kind, rule or None)``.

    ``KIND`` is one of :data:`drpt.accel.KINDS`; ``RULE``, one of
    :data:`drpt.accel.METHODS`, is allowed after a BVH kind (``bvh``,
    ``bvh2``, ``bvh4``): ``bvh-sah`` is ``--accel bvh --bvh sah``."""
    from .accel import KINDS, METHODS

    kind, dash, rule = spec.strip().partition("-")
    if kind not in KINDS or (dash and (kind not in BVH_KINDS or rule not in METHODS)):
        names = ", ".join(KINDS)
        rules = "|".join(METHODS)
        raise DrptError(f"--accel: unknown accelerator {spec!r} (use {names}, or "
                        f"bvh-RULE with RULE {rules})")
    return kind, (rule if dash else None)


def parse_accel_list(text: str) -> list[str]:
    """A comma-separated list of accelerator names (:func:`parse_accel`), checked."""
    from .accel import KINDS

    names = [a.strip() for a in text.split(",") if a.strip()]
    if not names:
        raise DrptError(f"--accel: give at least one of {', '.join(KINDS)}")
    for name in names:
        parse_accel(name)
    return names


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
    """The dests of the tracked render flags (size, spp, max_depth, rr_depth,
    integrator, filter) given on the command line."""
    return set(getattr(args, "_given", ()))


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
    from .accel import KINDS, METHODS

    unknown = set(omit) - set(FLAGS) | set(defaults) - set(FLAGS)
    if unknown:
        raise ValueError(f"unknown render flag groups {sorted(unknown)}")
    d = {"size": (512, 512), "spp": 64, "seed": 0, "max_depth": -1, "rr_depth": 5,
         "accel": None, "integrator": None, "bsdf": None, "env_sampling": "luminance",
         "filter": "box"}
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
        if seed_flags:
            parser.add_argument("-RR_cutdown", dest="rr_cutdown", type=float, default=None,
                                help="seed flag: fixed continuation probability p at every "
                                     "bounce")
    if want("seed"):
        parser.add_argument("--seed", type=int, default=d["seed"], action=_Given,
                            help=f"random seed (default {d['seed']})")
        parser.add_argument("--sampler", choices=SAMPLERS, default=None, action=_Given,
                            help="sample generator: independent (a random stream per sample) or "
                                 "ldsampler (a padded Owen-scrambled Sobol (0,2)-sequence per "
                                 "pixel: less noise per sample), zsobol (one such sequence over the "
                                 "image in Morton order: its error as blue noise); stratified, "
                                 "multijitter and "
                                 "orthogonal (Mitsuba's names) draw from ldsampler's sequence "
                                 f"(default {RenderOptions.sampler}, or the scene file's)")
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
                            help="path (MIS path tracing, default) or whitted")
        if seed_flags:
            parser.add_argument("-MonteCarlo", dest="monte_carlo", action="store_true",
                                help="seed flag: Monte Carlo path tracing (the seed's default "
                                     "is Whitted)")
    if want("mode"):
        parser.add_argument("--mode", choices=MODES, default="megakernel",
                            help="how the path tracer runs: megakernel (default: the whole path loop "
                                 "in one fused kernel) or wavefront (a kernel per stage and bounce: "
                                 "compacted, ray-sorted paths, per-material shading queues, batched "
                                 "shadow rays)")
        parser.add_argument("--wavefront-tail", dest="wavefront_tail", type=int, default=0, metavar="N",
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
        parser.add_argument("--light-sampler", dest="light_sampler", choices=LIGHT_SAMPLERS,
                            default=RenderOptions.light_sampler,
                            help="how next-event estimation picks an area light (emissive "
                                 "triangles and spheres): power (each primitive by its emitted "
                                 "power), uniform (Mitsuba's: every emitter alike, then a point "
                                 "by area) or bvh (a light BVH: by each emitter's importance at "
                                 f"the shading point) (default {RenderOptions.light_sampler})")
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
        from .backend import BACKENDS, ENV_VAR

        parser.add_argument("--backend", choices=BACKENDS, default=None,
                            help=f"Dr.Jit backend: llvm (CPU) or cuda (NVIDIA GPU); default "
                                 f"${ENV_VAR}, else llvm")
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
    from .scene.mitsuba import parse_defines

    return {"defines": parse_defines(getattr(args, "defines", None)),
            "ignore_unsupported": bool(getattr(args, "ignore_unsupported", False)),
            "strict": bool(getattr(args, "strict", False))}


def filter_spelling(name: str, params: dict) -> str:
    """``--filter``'s spelling of a Mitsuba rfilter: ``box``, ``tent:radius=R``,
    ``gaussian:stddev=S`` (Mitsuba's defaults when the file gives no parameter)."""
    if name == "box" or not params:
        return name
    ((key, value),) = params.items()
    return f"{name}:{key}={value!r}"


def apply_scene_settings(opts: RenderOptions, scene,
                         args: argparse.Namespace | None = None) -> RenderOptions:
    """``opts`` with the render settings the scene file gives (a Mitsuba XML's film size,
    sample count, integrator depths, ``hide_emitters``) where the command line gave none.

    The file's reconstruction filter (Mitsuba's default: gaussian) becomes
    ``filter`` unless ``--filter`` was given. An image size of another aspect
    than the file's film refits ``scene.camera``'s vertical fov so that the fov
    along the file's ``fov_axis`` stays (Mitsuba's behaviour for a resized film)."""
    from dataclasses import replace

    st = getattr(scene, "settings", None)
    if st is None:
        return opts
    given = given_flags(args) if args is not None else set()
    if args is not None and getattr(args, "rr_cutdown", None) is not None:
        given.add("rr_depth")  # the seed's -RR_cutdown sets it
    if args is not None and getattr(args, "monte_carlo", False):
        given.add("integrator")
    fields: dict = {}
    path: dict = {}
    if "size" not in given and st.width is not None and st.height is not None:
        fields["width"], fields["height"] = st.width, st.height
    if "spp" not in given and st.spp is not None and opts.target_error is None and opts.time_limit is None:
        fields["spp"] = st.spp  # (a --target-error or --time-limit render keeps its own most)
    if "integrator" not in given and st.integrator is not None:
        fields["integrator"] = st.integrator
    if "max_depth" not in given and st.max_depth is not None:
        # Mitsuba's max_depth 0 renders black; drpt's smallest depth is 1 (emitters only)
        path["max_depth"] = st.max_depth
    if "rr_depth" not in given and st.rr_depth is not None:
        path["rr_depth"] = st.rr_depth
    if st.hide_emitters is not None:
        path["hide_emitters"] = st.hide_emitters
    if getattr(st, "moment", None) is not None:
        fields["moment"] = True
    if getattr(st, "aovs", ()):
        fields["aovs"] = tuple(st.aovs)  # Mitsuba's aov integrator (--aovs replaces them)
    if getattr(st, "sampler", None) is not None and "sampler" not in given:
        fields["sampler"] = st.sampler
    if getattr(st, "seed", None) is not None and "seed" not in given:
        fields["seed"] = st.seed
    if st.rfilter is not None and "filter" not in given:
        fields["filter"] = filter_spelling(st.rfilter, st.rfilter_params)
    if path.get("max_depth") == 0:
        where = getattr(st, "origin", {}).get("max_depth", scene.path)
        raise DrptError(f"{where}: max_depth 0 renders nothing (Mitsuba gives a black image)")
    opts = replace(opts, path=replace(opts.path, **path), **fields)
    fov = getattr(st, "fov", None)
    if (fov is not None and st.width and st.height and (opts.width, opts.height) != (st.width, st.height)
            and hasattr(scene.camera, "fov") and getattr(scene.camera, "window", None) is None):
        # Mitsuba keeps the fov along fov_axis on a film of another aspect: so does drpt
        from .scene.mitsuba.reader import vertical_fov

        scene.camera = replace(scene.camera, fov=vertical_fov(fov[0], fov[1], opts.width / opts.height))
    return opts.validate()


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


#: the most samples per pixel of a --target-error or --time-limit render without --spp
TARGET_SPP = 65536


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
    from .accel import METHODS

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
    from dataclasses import replace

    from . import backend

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
    max_lanes = get("max_lanes")
    if max_lanes is None:
        max_lanes = backend.policy().max_lanes
    opts = RenderOptions(width=width, height=height, spp=get("spp", base.spp),
                         seed=get("seed", base.seed), **fields, bsdf=bsdf,
                         integrator=integrator, mode=get("mode", base.mode),
                         wavefront_tail=get("wavefront_tail", base.wavefront_tail),
                         env_sampling=get("env_sampling", base.env_sampling),
                         light_sampler=get("light_sampler", base.light_sampler),
                         sampler=get("sampler") or base.sampler,
                         filter=get("filter", base.filter),
                         filter_sampling=bool(get("filter_sampling", base.filter_sampling)),
                         path=PathOptions(max_depth=get("max_depth", base.path.max_depth),
                                          rr_depth=rr_depth, rr_prob=rr_prob),
                         max_lanes=max_lanes, chunk_spp=get("chunk_spp"),
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
