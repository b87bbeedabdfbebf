"""Render options: what every command that renders passes to the renderer.

:class:`RenderOptions` (with :class:`PathOptions`) is what the renderer
takes, and its defaults are drpt's: ``RenderOptions()`` is what ``drpt
render SCENE`` renders with no flags (512 x 512, 64 spp, MIS path tracing,
the ``auto`` accelerator and materials). :meth:`RenderOptions.validate`
refuses values the renderer cannot use, with messages that name the
command-line flag; derived values are resolved in one place each
(:attr:`RenderOptions.lanes`: the lanes of a pass; :attr:`RenderOptions.pixel_filter`).

:func:`with_scene_settings` merges the render settings a scene file gives (a
Mitsuba XML's film, sampler and integrator) into the options, returning the
options and the scene with a new camera where the film's aspect changed; it
changes neither argument.

Accelerators are named by one vocabulary: a kind of
:data:`drpt.accel.KINDS`, optionally with a BVH rule of
:data:`drpt.accel.METHODS` joined by a dash, ``KIND-RULE`` (``bvh-sah`` is
``--accel bvh --bvh sah``); :func:`parse_accel` reads it. ``drpt bench``
takes a comma-separated list of such names.

The command-line flags that build these options, the seed renderer's
spellings among them, are :mod:`drpt.cli.args`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from .accel import KINDS, METHODS, NO_MIN_LEAF
from .accel.bvh4_nodes import LEAF_MAX_COUNT
from .aovs import check_aovs
from .backend import policy
from .errors import DrptError, Loc, SceneError
from .filters import parse_filter
from .scene.model import MAX_DEPTH, MAX_SAMPLES, MAX_SIZE, MAX_SPP, mitsuba_sample_count, vertical_fov

BSDF_MODES = ("auto", "phong", "cook-torrance", "diffuse")  # drpt.materials.interpret.MODES
INTEGRATORS = ("path", "whitted", "ptracer", "volpath", "bdpt")
#: integrators whose passes splat light paths over the whole image (their sums merge and
#: finish as light tracing's, drpt.render.renderer.finish)
LIGHT_TRACED = ("ptracer", "bdpt")
MODES = ("megakernel", "wavefront")  # how the path integrator runs (drpt.render.integrators)
ENV_SAMPLING = ("luminance", "uniform")
#: ``--env-compensation``: MIS compensation of the sky's next-event density (:attr:`RenderOptions.env_compensation`)
ENV_COMPENSATION = ("on", "off")
LIGHT_SAMPLERS = ("mixed", "power", "uniform", "bvh", "pilot")  # drpt.render.lights.selection
DELTA_LIGHTS = ("each", "select")  # drpt.render.scene.DeviceScene.delta_each
#: how next-event estimation samples an emissive triangle (drpt.render.lights.area.triangle_sampling_rule)
TRIANGLE_SAMPLING = ("auto", "area", "solid-angle")
#: --sampler names (drpt.render.sampler): independent, drpt's low-discrepancy samplers, and
#: Mitsuba's stratified, multi-jittered and orthogonal-array samplers
SAMPLERS = ("independent", "ldsampler", "zsobol", "stratified", "multijitter", "orthogonal")
#: ``--sampler`` values: a sampler of :data:`SAMPLERS`, or ``auto`` (:func:`resolve_sampler`)
SAMPLER_CHOICES = ("auto", *SAMPLERS)
#: the integrators whose ``auto`` sampler is ``ldsampler`` (:func:`resolve_sampler`)
AUTO_LD_INTEGRATORS = ("path", "volpath", "whitted", "bdpt")
BVH_KINDS = ("bvh", "bvh2", "bvh4")
GRID_MAX_RESOLUTION = 256

# Limits of the numbers the renderer and the Mitsuba export hold (RenderOptions.validate);
# those a scene file's render settings also hold (MAX_SIZE, MAX_SPP, MAX_SAMPLES, MAX_DEPTH)
# are drpt.scene.model's, which the XML reader checks:
MAX_LANES = (1 << 32) - 1  # lanes per pass: lane ids are UInt32
MAX_SEED = (1 << 64) - 1  # the seed is hashed as a 64-bit integer

#: the most samples per pixel of a --target-error or --time-limit render without --spp
TARGET_SPP = 65536
#: PathOptions.rr_threshold's default, chosen by measurement on the bundled scenes
#: (docs/performance.md, "Russian roulette below a throughput")
RR_THRESHOLD = 0.1


@dataclass
class PathOptions:
    max_depth: int = -1
    rr_depth: int = 5
    rr_prob: float | None = None  # fixed continuation probability, or adaptive
    #: before ``rr_depth``, a path whose throughput (its largest channel, times ``eta^2``) is
    #: below this plays Russian roulette too, surviving with probability throughput /
    #: ``rr_threshold`` (:func:`drpt.render.integrators.path.continue_path`); 0: only Mitsuba's
    #: roulette from ``rr_depth``. A Mitsuba XML scene's integrator is Mitsuba's, so it
    #: renders with 0 unless ``--rr-threshold`` is given (:func:`with_scene_settings`)
    rr_threshold: float = RR_THRESHOLD
    hide_emitters: bool = False  # camera rays do not see emitters or the sky (Mitsuba's hide_emitters)


@dataclass
class RenderOptions:
    width: int = 512
    height: int = 512
    spp: int = 64
    seed: int = 0
    accel: str = "auto"  # drpt.accel.build_accel kind ("auto": inline for tiny scenes, else embree or bvh)
    grid_resolution: int | None = None  # cells per axis for accel="grid" (None: automatic)
    bvh_method: str = "auto"  # BVH split rule, drpt.accel.METHODS (accel="bvh")
    sah_threshold: int | None = None  # K of bvh_method="threshold" (None: the seed's 2000)
    bvh_min_leaf: int = 1  # minimum primitives per BVH leaf (the seed's -resolution)
    bsdf: str = "auto"  # how MTL materials are read, see drpt.materials.interpret
    integrator: str = "path"  # "path" (MIS path tracing), "whitted", "ptracer" (light tracing), "bdpt", "volpath"
    mode: str = "megakernel"  # path tracing as one fused kernel, or "wavefront" (a kernel per stage)
    wavefront_tail: int = 0  # wavefront: finish in one fused loop once at most this many paths live
    env_sampling: str = "luminance"  # or "uniform" (for comparison only)
    #: the sky's next-event density with MIS compensation (``--env-compensation on|off``:
    #: :meth:`drpt.render.lights.envmap.EnvironmentLight.compensated`) where the scene file
    #: does not say (a Mitsuba ``envmap``'s ``mis_compensation`` wins); only the integrators
    #: that combine it with BSDF and phase samples by MIS use it (path, volpath)
    env_compensation: str = "on"
    #: how next-event estimation picks an area light: "power" (each emissive primitive by its
    #: power) or "uniform" (Mitsuba's: each emitter alike, then a point by area)
    light_sampler: str = "mixed"
    #: how the path tracer's next-event estimation reaches delta lights (point, spot,
    #: projector, directional) in a scene that has other emitters too: "each" (a shadow ray
    #: toward every delta light at every vertex, outside the light selection, which then
    #: picks among the other emitters) or "select" (the delta lights in the selection, one
    #: emitter per vertex), :attr:`drpt.render.scene.DeviceScene.delta_each`
    delta_lights: str = "each"
    #: how next-event estimation samples a point on an emissive triangle: "area" (uniform
    #: on it, Mitsuba's), "solid-angle" (uniform in the solid angle it subtends, where that
    #: is neither tiny nor near a hemisphere) or "auto" (solid-angle where volpath renders a
    #: scene with participating media), :func:`drpt.render.lights.area.triangle_sampling_rule`
    triangle_sampling: str = "auto"
    #: what the camera passes' random numbers are drawn from (:mod:`drpt.render.sampler`):
    #: "independent" (a PCG32 stream per lane), a low-discrepancy sampler's name, or "auto"
    #: (the scene file's where it names one, else :func:`resolve_sampler`'s choice)
    sampler: str = "auto"
    #: stratified, multijitter, orthogonal: a random offset inside each stratum (Mitsuba's
    #: ``jitter``), or its middle (``--jitter off``)
    jitter: bool = True
    #: orthogonal: the orthogonal array's strength (Mitsuba's ``strength``, ``--strength``)
    strength: int = 2
    filter: str = "box"  # pixel reconstruction filter, drpt.filters.parse_filter's spelling
    filter_sampling: bool = False  # tent/gaussian: draw samples from the filter instead of splatting
    #: stop once the estimated relMSE (drpt.metrics.estimated_rel_mse) is at most this, or
    #: once time_limit seconds have passed, at the end of a chunk; spp is then the most
    target_error: float | None = None
    time_limit: float | None = None
    path: PathOptions = field(default_factory=PathOptions)
    max_lanes: int | None = None  # samples traced at once (None: the backend's, see lanes)
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
    #: bdpt: also sum each connection strategy's contributions (``--bdpt-strategies``,
    #: :meth:`drpt.render.renderer.Renderer.strategy_images`)
    bdpt_strategies: bool = False
    #: bdpt: estimate the paths camera S+ D S+ area light (caustics seen through glass or in
    #: mirrors) by merging caustic photons (``--bdpt-merge on|off``,
    #: :attr:`drpt.render.integrators.bdpt.BDPTIntegrator.merging`); only scenes with Dirac
    #: lobes and area lights trace any of it
    bdpt_merge: bool = True
    #: ptracer, bdpt: also sum the squared splats (the variance film), from which the
    #: result's per-pixel ``variance`` is estimated; off, light-traced renders skip those
    #: float64 scatter-adds and their ``variance`` is NaN, unless a stop rule or adaptive
    #: sampling reads it (:attr:`light_variance`). Camera-sampled integrators always have it
    variance: bool = False

    def validate(self) -> RenderOptions:
        """Raise :class:`~drpt.errors.DrptError` on a value the renderer cannot
        use (messages name the command-line flag); return ``self``."""
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
        if not (math.isfinite(p.rr_threshold) and 0.0 <= p.rr_threshold <= 1.0):
            raise DrptError(f"--rr-threshold must be between 0 and 1, got {p.rr_threshold}")
        for name, value, allowed in (("--accel", self.accel, KINDS),
                                     ("--bvh", self.bvh_method, METHODS),
                                     ("--bsdf", self.bsdf, BSDF_MODES),
                                     ("--integrator", self.integrator, INTEGRATORS),
                                     ("--mode", self.mode, MODES),
                                     ("--env-sampling", self.env_sampling, ENV_SAMPLING),
                                     ("--env-compensation", self.env_compensation, ENV_COMPENSATION),
                                     ("--light-sampler", self.light_sampler, LIGHT_SAMPLERS),
                                     ("--delta-lights", self.delta_lights, DELTA_LIGHTS),
                                     ("--triangle-sampling", self.triangle_sampling, TRIANGLE_SAMPLING),
                                     ("--sampler", self.sampler, SAMPLER_CHOICES)):
            if value not in allowed:
                raise DrptError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
        if self.strength < 2:
            raise DrptError(f"--strength must be at least 2, got {self.strength}")
        if self.sampler in ("stratified", "multijitter", "orthogonal"):
            count = mitsuba_sample_count(self.sampler, self.spp)
            if count > 1 << 31:
                raise DrptError(f"--sampler {self.sampler}: --spp {self.spp} rounds up to {count}, "
                                "more than its 2^31 strata")
        if self.sampler == "orthogonal" and self.strength > 2:
            res = math.isqrt(mitsuba_sample_count("orthogonal", self.spp))
            if res ** self.strength > 1 << 31:
                raise DrptError(f"--strength {self.strength}: an orthogonal array of {res}^{self.strength} "
                                f"rows (--spp {self.spp}) is more than drpt's 2^31")
        parse_filter(self.filter)  # raises DrptError on a bad --filter
        check_aovs(self.aovs)
        if not 0 <= self.wavefront_tail <= MAX_LANES:
            raise DrptError(f"--wavefront-tail must be between 0 and {MAX_LANES}, got {self.wavefront_tail}")
        if self.mode == "wavefront" and self.integrator not in ("path", "volpath"):
            raise DrptError(f"--mode wavefront runs the path and volpath integrators, not --integrator "
                            f"{self.integrator}")
        if self.bdpt_strategies and self.integrator != "bdpt":
            raise DrptError(f"--bdpt-strategies needs --integrator bdpt, not {self.integrator}")
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
            from .render.adaptive import check  # cycle: drpt.render imports this module

            check(self)
        return self

    @property
    def light_variance(self) -> bool:
        """Whether light-traced passes (ptracer, bdpt) sum their squared splats:
        :attr:`variance`, or ``--target-error``, ``--time-limit`` or ``--adaptive``, which
        read the estimated variance."""
        return self.variance or self.target_error is not None or self.time_limit is not None or self.adaptive

    @property
    def pixel_filter(self):
        """The :class:`~drpt.filters.PixelFilter` that :attr:`filter` names."""
        return parse_filter(self.filter)

    @property
    def lanes(self) -> int:
        """The most samples a pass traces at once: :attr:`max_lanes`, or the
        selected backend's default (:func:`drpt.backend.policy`) when it is
        ``None``. Every user of the pass layout reads it here."""
        return policy().max_lanes if self.max_lanes is None else self.max_lanes


# ------------------------------------------------------------------ accelerator names
def parse_accel(spec: str) -> tuple[str, str | None]:
    """``KIND`` or ``KIND-RULE`` -> ``(kind, rule or None)``.

    ``KIND`` is one of :data:`drpt.accel.KINDS`; ``RULE``, one of
    :data:`drpt.accel.METHODS`, is allowed after a BVH kind (``bvh``,
    ``bvh2``, ``bvh4``): ``bvh-sah`` is ``--accel bvh --bvh sah``."""
    kind, dash, rule = spec.strip().partition("-")
    if kind not in KINDS or (dash and (kind not in BVH_KINDS or rule not in METHODS)):
        names = ", ".join(KINDS)
        rules = "|".join(METHODS)
        raise DrptError(f"--accel: unknown accelerator {spec!r} (use {names}, or "
                        f"bvh-RULE with RULE {rules})")
    return kind, (rule if dash else None)


def parse_accel_list(text: str) -> list[str]:
    """A comma-separated list of accelerator names (:func:`parse_accel`), checked."""
    names = [a.strip() for a in text.split(",") if a.strip()]
    if not names:
        raise DrptError(f"--accel: give at least one of {', '.join(KINDS)}")
    for name in names:
        parse_accel(name)
    return names


# ------------------------------------------------------------------ scene settings
def filter_spelling(name: str, params: dict) -> str:
    """``--filter``'s spelling of a Mitsuba rfilter: ``box``, ``tent:radius=R``,
    ``gaussian:stddev=S`` (Mitsuba's defaults when the file gives no parameter)."""
    if name == "box" or not params:
        return name
    ((key, value),) = params.items()
    return f"{name}:{key}={value!r}"


#: the names of :func:`with_scene_settings`'s ``given``: settings the caller fixed
GIVEN = ("size", "spp", "seed", "sampler", "jitter", "strength", "integrator", "max_depth", "rr_depth",
         "rr_threshold", "hide_emitters", "filter")


def with_scene_settings(opts: RenderOptions, scene,
                        given=frozenset()) -> tuple[RenderOptions, object]:
    """``(options, scene)`` with the render settings the scene file gives (a
    Mitsuba XML's film size, sample count, sampler and seed, integrator and its
    depths, ``hide_emitters``, moment and AOV integrators) where ``given`` (names
    of :data:`GIVEN`: what the command line set) does not fix them. A file with settings
    (Mitsuba XML) names Mitsuba's integrator, whose Russian roulette starts at
    ``rr_depth`` only: ``rr_threshold`` becomes 0 unless given.

    The file's reconstruction filter (Mitsuba's default: gaussian) becomes
    ``filter`` unless ``"filter"`` is given. A render of another aspect than the
    file's film gets a copy of ``scene`` whose camera has the vertical fov that
    keeps the fov along the file's ``fov_axis`` (Mitsuba's behaviour for a
    resized film); otherwise ``scene`` itself comes back. Neither argument is
    changed. A scene without settings (the seed's format) returns both as they
    are; the options are validated otherwise.
    """
    unknown = set(given) - set(GIVEN)
    if unknown:
        raise ValueError(f"unknown settings {sorted(unknown)} (expected names of {GIVEN})")
    st = getattr(scene, "settings", None)
    if st is None:
        return opts, scene
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
    if "rr_threshold" not in given:  # (the file's integrator is Mitsuba's: its roulette only)
        path["rr_threshold"] = 0.0
    if st.hide_emitters is not None and "hide_emitters" not in given:
        path["hide_emitters"] = st.hide_emitters
    if getattr(st, "moment", None) is not None:
        fields["moment"] = True
    if getattr(st, "aovs", ()):
        fields["aovs"] = tuple(st.aovs)  # Mitsuba's aov integrator (--aovs replaces them)
    if getattr(st, "sampler", None) is not None and "sampler" not in given:
        fields["sampler"] = st.sampler
    for name in ("jitter", "strength"):  # the sampler's parameters (when it is the file's)
        if getattr(st, name, None) is not None and name not in given and "sampler" not in given:
            fields[name] = getattr(st, name)
    if getattr(st, "seed", None) is not None and "seed" not in given:
        fields["seed"] = st.seed
    if st.rfilter is not None and "filter" not in given:
        fields["filter"] = filter_spelling(st.rfilter, st.rfilter_params)
    if path.get("max_depth") == 0:
        where = getattr(st, "origin", {}).get("max_depth") or Loc(scene.path)
        raise SceneError(where, "max_depth 0 renders nothing (Mitsuba gives a black image)")
    opts = replace(opts, path=replace(opts.path, **path), **fields)
    fov = getattr(st, "fov", None)
    if (fov is not None and st.width and st.height and (opts.width, opts.height) != (st.width, st.height)
            and hasattr(scene.camera, "fov") and getattr(scene.camera, "window", None) is None):
        # Mitsuba keeps the fov along fov_axis on a film of another aspect: so does drpt
        camera = replace(scene.camera, fov=vertical_fov(fov[0], fov[1], opts.width / opts.height))
        scene = replace(scene, camera=camera)
    return opts.validate(), scene


# ------------------------------------------------------------------ the sampler
def resolve_sampler(opts: RenderOptions, recorded: str | None = None) -> RenderOptions:
    """``opts`` with ``sampler="auto"`` replaced by the sampler it means; any other
    ``sampler`` (named by ``--sampler`` or by the scene file, which
    :func:`with_scene_settings` merged in before) comes back as it is.

    ``auto`` is ``recorded`` where that is given: the sampler of the checkpoint a
    ``--resume`` continues (``"independent"`` for a checkpoint that records none), so that a
    resumed render draws the samples its checkpoint's did. Otherwise it is ``ldsampler``
    for the integrators of :data:`AUTO_LD_INTEGRATORS` (path, volpath, whitted, megakernel
    and wavefront alike, and bdpt, whose camera samples and their light subpaths draw from
    their pixel's sequence), which it makes faster to converge on every scene measured
    (``docs/performance.md``, "Samplers", and for bdpt "bdpt's samplers"), and
    ``independent`` for the rest: light tracing (``ptracer``: ``ldsampler`` stratifies where
    light paths start, not where they land in the image) and ``--adaptive`` sampling,
    which draws independent samples. The renderer calls this on the options it is given,
    so every way of rendering (in process, in chunks, on workers, resumed, the preview)
    resolves ``auto`` alike; it depends on nothing but ``integrator``, ``adaptive`` and
    ``recorded``."""
    if opts.sampler != "auto":
        return opts
    if recorded is not None:
        name = recorded
    elif opts.integrator in AUTO_LD_INTEGRATORS and not opts.adaptive:
        name = "ldsampler"
    else:
        name = "independent"
    return replace(opts, sampler=name)
