"""Turns a scene into an image: passes of samples, a pixel filter, a progress bar.

Work is cut into passes of at most ``max_lanes`` samples, so memory stays
bounded at any image size and sample count: a pass covers a band of rows with
``k`` samples per pixel (``k`` as large as the budget allows). The path
tracer runs them with *path regeneration*
(:meth:`~drpt.render.integrators.path.PathIntegrator.sample_sequence`): each
pixel gets ``m`` Dr.Jit lanes (from ``drpt.backend.policy().min_lanes``; short
unrolled paths at least ``ceil(k / 3)``, :data:`STRAIGHT_PATHS_PER_LANE`; on a tree
or grid accelerator, and where every BSDF is a mirror or glass, ``k``: a lane per sample;
see :meth:`Renderer._pass_lanes_per_pixel`), each lane traces its
share of the ``k`` samples one path after another and sums them, so a SIMD
packet no longer waits for its longest path at every bounce (its gain:
docs/performance.md, "Execution model"). The Whitted integrator runs one sample per lane. Lanes are
ordered pixel-major, so a pixel's lanes are adjacent, and one kernel reads them as
records by packet gathers and adds them in lane order, or a block sum per channel adds
them (:func:`~drpt.render.film.lane_sums`; a pixel is the mean of its own samples, added
in an order that depends on nothing else). Each
lane draws from its own PCG32 stream, selected by ``(seed, pass, lane)``
(:func:`~drpt.render.sampler.pcg_streams`: state and increment hashed from them, so
neighbouring lanes' streams are independent), so a render is deterministic for a
given seed and pass layout.

The plan (:class:`PassPlan`) is arithmetic on the pass index, not a list:
planning 10^7 spp at 4096x4096 takes no memory. Sums in the lanes and
across a pixel's lanes are float32, across passes float64; a pass whose
float32 sums overflowed (radiance near the float32 maximum: the samples
themselves are finite) is traced again, with the same random numbers, with
float64 sums (:meth:`Renderer.render_pass`), so such radiance averages correctly
and other renders pay nothing for it. A pixel mean beyond float32 (which no
image file holds) is an error.

Where a pixel's sample lies and which pixels it counts in is the pixel
filter's business (``RenderOptions.filter``, :mod:`drpt.filters`): the box
filter (the default) jitters it uniformly over the pixel square and the
pixel sums its own samples; ``tent`` and ``gaussian`` jitter it the same
way and splat it into every pixel the filter covers with the filter's
weight, as Mitsuba's film does (:meth:`Renderer._trace_splat_pass`,
:mod:`drpt.render.film`: one sample per lane); with ``filter_sampling`` they
draw it from the filter truncated to the image instead (filter importance
sampling, :mod:`drpt.render.filter_sampling`), so each pixel sums its own
samples. Light tracing (``ptracer``) splats every pass over the whole image.

Pass parameters that change between passes (row offset, seed, ``k``) are
opaque JIT values: the megakernel is compiled once per render.

Passes are grouped into chunks (:mod:`drpt.render.chunks`): fixed groups
of sample steps, each a pure function of the scene, the options and its
index (:meth:`Renderer.render_chunk`), merged in chunk order.
:meth:`Renderer.render` traces them one after another; a distributed render
(:mod:`drpt.distributed`) traces them on other processes and merges them the
same way, so both give the same image bit for bit.

The scene goes to the device once, as a
:class:`~drpt.render.scene.DeviceScene` (:attr:`Renderer.scene`), which the
integrator queries; the renderer adds the camera and the passes.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Array3f64, Bool, Float, UInt32

from .. import heap, llvm_tuning
from ..aovs import INDEX_KINDS, channel_count, traced
from ..backend import policy
from ..errors import DrptError
from ..metrics import estimated_rel_mse
from ..options import RenderOptions, resolve_sampler
from ..scene.model import Camera, Scene
from .aov import aov_values, index_arrays
from .camera import RayCamera
from .chunks import ChunkMerge, ChunkPlan, ChunkResult, plan_chunks
from .deferred import DeferredField, Later
from .film import SplatFilm, dropped_total, gather_splats, lane_sums, pass_lanes, splat_weights
from .filter_sampling import sample_position
from .frozen import FrozenPass, freezes
from .integrators.bdpt import STRATEGY_SEGMENTS, BDPTIntegrator, StrategyFilm, strategies
from .integrators.path import PathIntegrator
from .integrators.ptracer import ParticleTracer
from .integrators.volpath import VolPathIntegrator
from .integrators.volwavefront import VolWavefrontIntegrator
from .integrators.wavefront import WavefrontIntegrator
from .integrators.whitted import WhittedIntegrator, WhittedOptions
from .lanes import divmod_opaque
from .lights.rays import EmitterRays
from .sampler import (
    STRATA,
    LDSampler,
    ZSobolSampler,
    ld_stream_key,
    next_2d,
    pcg_keys,
    pcg_streams,
    strata_sampler,
    uses_ld,
)
from .scene import DeviceScene, wants_delta_each


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) float32, linear radiance
    #: (H, W, 3) float64, estimated variance of each pixel's mean (computed on first read:
    #: :mod:`drpt.render.deferred`)
    variance: np.ndarray = DeferredField()
    # (NaN for light tracing without RenderOptions.light_variance: its squares were not summed)
    # (float64: the square of radiance near the float32 maximum is beyond float32)
    seconds: float
    build_seconds: float
    samples: int
    nonfinite: int  # samples discarded because they were NaN/Inf (should be 0)
    #: with ``RenderOptions.moment``: (H, W, 3) float64, each pixel's mean of its samples'
    #: squared CIE XYZ values (Mitsuba's ``moment`` integrator's ``m2_`` channels; computed
    #: on first read)
    moment2: np.ndarray | None = DeferredField(default=None)
    #: with AOVs or denoising (``RenderOptions.aovs``, ``denoise``): (H, W, C) float32, each
    #: pixel's mean of the traced AOVs' channels (:func:`drpt.aovs.traced` gives their order)
    aov: np.ndarray | None = None

    @property
    def samples_per_second(self) -> float:
        return self.samples / max(self.seconds, 1e-9)

    @property
    def estimated_rel_mse(self) -> float:
        """The relMSE this image is expected to have (:func:`drpt.metrics.estimated_rel_mse`)."""
        return estimated_rel_mse(self.image, self.variance)

    @property
    def spp(self) -> int:
        """Samples per pixel rendered (fewer than asked when a target error or time
        limit stopped the render)."""
        return self.samples // max(self.image.shape[0] * self.image.shape[1], 1)


@dataclass
class PassSums:
    """What one pass adds to the image: sums over the image rows ``lo ..
    lo + len(sum)`` of its samples (``sum``) and of their squares (``sumsq``),
    ``(rows, W, 3)`` float64, the non-finite samples it dropped and, for a
    splatting film (:attr:`Renderer.splatting`), the filter weights' sums
    ``(rows, W, 2)``: ``sum(w)`` and ``sum(w^2)`` (``sum`` is then ``sum(w L)``
    and ``sumsq`` ``sum(w^2 L^2)``)."""

    lo: int
    sum: np.ndarray
    sumsq: np.ndarray
    nonfinite: int
    weight: np.ndarray | None = None
    #: with AOVs: the rows ``aov_lo ..`` of the AOV channels' weighted sums, then the
    #: weights' sum, ``(rows, W, C + 1)`` (:meth:`Renderer._trace_aov_pass`)
    aov: np.ndarray | None = None
    aov_lo: int = 0


#: mixed into the seed of the AOV kernel's random streams (its own, beside the beauty's)
AOV_STREAM = 0xA0F5EED
#: the seed's xor for bidirectional path tracing's pilot (:meth:`Renderer._calibrate_bdpt`)
BDPT_PILOT_STREAM = 0xB1D1C0DE
#: the seed's xor for bidirectional path tracing's caustic photons (:meth:`Renderer._bdpt_pass`)
BDPT_PHOTON_STREAM = 0x9E0F0CA5
#: the pilot's lanes (at most; whole rows of one sample per pixel)
BDPT_PILOT_LANES = 1 << 16
#: paths per lane (at most) where the path tracer traces short paths unrolled
#: (:attr:`~drpt.render.integrators.path.PathIntegrator.straight`): see :meth:`Renderer._trace_pass`
STRAIGHT_PATHS_PER_LANE = 3


def _mix_seed(seed: int, index: int) -> int:
    """A 64-bit hash (splitmix64) of (seed, index), for PCG32 initial states."""
    z = (seed * 0x9E3779B97F4A7C15 + index + 1) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return z ^ (z >> 31)


@dataclass(frozen=True)
class PassPlan:
    """The passes of a render: pass ``i`` is ``plan[i] = (first sample,
    samples per pixel, first row, rows)``, computed from ``i``.

    Sample steps of ``k`` samples per pixel are the outer order, bands of
    ``rows`` rows the inner one (the last step and band may be shorter).
    """

    width: int
    height: int
    spp: int
    k: int  # samples per pixel of a full pass
    rows: int  # rows of a full pass

    @property
    def bands(self) -> int:
        return -(-self.height // self.rows)

    @property
    def count(self) -> int:
        """The number of passes (``len(plan)``, which Python bounds by 2^63)."""
        return -(-self.spp // self.k) * self.bands

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, i: int) -> tuple[int, int, int, int]:
        if not 0 <= i < self.count:
            raise IndexError(f"pass {i} of {self.count}")
        step, band = divmod(i, self.bands)
        s0, r0 = step * self.k, band * self.rows
        return s0, min(self.k, self.spp - s0), r0, min(self.rows, self.height - r0)

    def at(self, i: int) -> tuple[int, int, int, int]:
        """``plan[i]``, also past the last pass, where further sample steps of ``k``
        samples per pixel follow in the same bands (a live view's frames go on)."""
        if i < self.count:
            return self[i]
        step, band = divmod(i, self.bands)
        r0 = band * self.rows
        return step * self.k, self.k, r0, min(self.rows, self.height - r0)

    def first_sample(self, i: int) -> int:
        """The index of pass ``i``'s first sample among the render's ``W H spp``, in pass
        order (``(s0 H + r0 k) W``; also past the last pass: a live view's frames go on)."""
        step, band = divmod(i, self.bands)
        s0 = step * self.k
        k = max(1, min(self.k, self.spp - s0))
        return (s0 * self.height + band * self.rows * k) * self.width

    def __iter__(self) -> Iterator[tuple[int, int, int, int]]:
        for i in range(self.count):
            yield self[i]


def plan_passes(width: int, height: int, spp: int, max_lanes: int) -> PassPlan:
    """Passes of at most ``max_lanes`` samples (a single row is never split):
    the whole image with as many samples per pixel as fit, else bands of
    rows with one sample per pixel."""
    pixels = width * height
    if pixels <= max_lanes:
        k = max(1, min(spp, max_lanes // pixels))
        rows = height
    else:
        k = 1
        rows = max(1, max_lanes // width)
    return PassPlan(width, height, spp, k, rows)


#: the warning of a scene with participating media rendered by another integrator than volpath
MEDIA_IGNORED = ("the scene's participating media are ignored by this integrator (as by Mitsuba's path): "
                 "--integrator volpath renders them")


class Renderer:
    def __init__(self, scene: Scene, options: RenderOptions):
        options = resolve_sampler(options)  # --sampler auto: the sampler it means
        self.opt = options
        heap.keep_freed_memory()  # the host arrays of one render reused by the next
        t0 = time.perf_counter()
        self.scene = DeviceScene(scene, options)
        self.scene_model = scene
        self.camera_model: Camera = scene.camera
        self.camera = RayCamera(scene.camera, options.width, options.height)
        self.warnings: list[str] = self.scene.warnings
        self.integrator = self._make_integrator()
        bdpt = isinstance(self.integrator, BDPTIntegrator)
        if uses_ld(options.sampler) and not self.ld_sampling:
            self.warnings.append(f"--sampler {options.sampler}: light tracing beyond 2^32 paths "
                                 "(width x height x spp) draws independent samples")
        elif options.sampler == "zsobol" and self.light_tracing and not bdpt:
            self.warnings.append("--sampler zsobol: light tracing draws from one ldsampler sequence "
                                 "of all its paths")
        elif options.sampler == "zsobol" and self._zsobol is None and (bdpt or not self.light_tracing):
            self.warnings.append("--sampler zsobol: the image's Morton codes and the sample index "
                                 "need more than 32 bits: ldsampler's sequences instead")
        if options.sampler in STRATA and self.ld_sampling:
            count = self._ld_class.count
            if count != options.spp and not self.light_tracing:
                self.warnings.append(f"--sampler {options.sampler}: its strata are laid out for "
                                     f"{count} samples per pixel (--spp {options.spp} rounded as "
                                     f"Mitsuba rounds sample_count): each pixel's samples "
                                     f"{'are' if count > options.spp else 'begin with'} "
                                     f"{min(count, options.spp)} of them")
        self._aov_ids = None
        if self.aov_kinds:
            self._aov_index_arrays()  # a scene without shape data is an error before rendering
        #: with ``bdpt_strategies``: the sums of each strategy's contributions, ``(count, H, W,
        #: 3)`` (:class:`~drpt.render.integrators.bdpt.StrategyFilm`), over the passes traced
        self.strategy_sums = None
        self._reset_frozen()
        self.build_seconds = time.perf_counter() - t0

    def _reset_frozen(self) -> None:
        """No pass traced yet, none frozen (:meth:`_frozen_pass`; a derived renderer
        starts so: its passes are its own integrator's)."""
        self._traced_args: set = set()
        self._frozen: dict = {}

    def _aov_index_arrays(self):
        """The ``(shape, prim)`` tables of the index AOVs (None when none is asked for)."""
        if self._aov_ids is None and any(k in INDEX_KINDS for k in self.aov_kinds):
            self._aov_ids = index_arrays(self.scene_model)
        return self._aov_ids

    def _make_integrator(self):
        options = self.opt
        media = getattr(self.scene_model, "media", None)
        if media and options.integrator != "volpath" and MEDIA_IGNORED not in self.warnings:
            self.warnings.append(MEDIA_IGNORED)
        # only the megakernel path tracer reaches delta lights by shadow rays of their own
        # (DeviceScene.delta_each); the other integrators find them in the light selection
        if hasattr(self.scene, "set_delta_each"):
            self.scene.set_delta_each(wants_delta_each(options, bool(media)))
        if options.integrator == "ptracer":
            if options.moment:
                raise DrptError("the moment integrator cannot wrap ptracer (light tracing has no "
                                "per-pixel samples; Mitsuba's cannot either)")
            return ParticleTracer(self.scene, EmitterRays(self.scene, self.scene_model), self.camera,
                                  options.path)
        if options.integrator == "bdpt":
            if options.moment:
                raise DrptError("the moment integrator cannot wrap bdpt (its light paths have no "
                                "per-pixel samples)")
            bdpt = BDPTIntegrator(self.scene, EmitterRays(self.scene, self.scene_model), self.camera,
                                  options.path, merge=options.bdpt_merge,
                                  low_discrepancy=uses_ld(options.sampler))
            self.warnings += [w for w in bdpt.warnings if w not in self.warnings]
            return bdpt
        if options.integrator == "whitted":
            depth = options.path.max_depth
            return WhittedIntegrator(self.scene, WhittedOptions(max_depth=depth if depth > 0 else 16))
        if options.integrator == "volpath" and media:
            if options.mode == "wavefront":
                return VolWavefrontIntegrator(self.scene, options.path, self.scene_model,
                                              tail=options.wavefront_tail)
            return VolPathIntegrator(self.scene, options.path, self.scene_model)
        if options.mode == "wavefront":
            return WavefrontIntegrator(self.scene, options.path, tail=options.wavefront_tail)
        # (volpath in a scene without media: the path integrator, the same expectation)
        return PathIntegrator(self.scene, options.path)

    def strategy_images(self, spp: int) -> dict[tuple[int, int], np.ndarray]:
        """With ``bdpt_strategies``, after a render of ``spp`` samples per pixel: each used
        strategy's image ``(s, t) -> (H, W, 3)`` float32 (the image is their sum, for paths
        of at most :data:`~drpt.render.integrators.bdpt.STRATEGY_SEGMENTS` segments)."""
        if self.strategy_sums is None:
            return {}
        segments = min(self.integrator.depth, STRATEGY_SEGMENTS)
        return {st: (self.strategy_sums[i] / max(spp, 1)).astype(np.float32)
                for i, st in enumerate(strategies(segments)) if st != (1, 1)}

    def derive(self, options: RenderOptions, camera: Camera | None = None) -> Renderer:
        """A renderer of the same device scene (nothing is built again) with
        other per-render ``options`` (size, spp, seed, integrator, path
        depths, lanes) and ``camera`` (default: this renderer's). The options
        that shape the device scene (accelerator, material mode, sky
        sampling, light sampler) stay this renderer's. Renders equal those of a new
        :class:`Renderer` of the scene with these options and camera."""
        new = copy.copy(self)
        new.opt = options = resolve_sampler(options.validate())
        new.camera_model = self.camera_model if camera is None else camera
        new.camera = RayCamera(new.camera_model, options.width, options.height)
        new.integrator = new._make_integrator()
        new.strategy_sums = None
        new._reset_frozen()
        return new

    @property
    def max_lanes(self) -> int:
        """Samples traced at once (:attr:`RenderOptions.lanes`)."""
        return self.opt.lanes

    @property
    def plan(self) -> PassPlan:
        """The render's passes (:func:`plan_passes` of its size, spp and :attr:`max_lanes`)."""
        return self.chunks.passes

    def render_pass(self, pass_index: int) -> PassSums:
        """Pass ``pass_index`` of :attr:`plan`: the :class:`PassSums` of its ``k`` samples
        of each pixel of its rows, a pure function of the scene, the options and
        ``pass_index`` (its random numbers are selected by the seed and the index).
        Past the plan's last pass, sample steps of the plan's ``k`` samples per pixel
        go on in its bands of rows, so a live view (:mod:`drpt.render.progressive`)
        renders frame after frame with the render's own passes. :meth:`render` is the
        passes of the plan in order, summed.

        Without splatting the sums cover the pass's own rows (``lo = r0``); a
        splatting pass (:attr:`splatting`) also reaches the rows its filter covers,
        a light-tracing pass the whole image (``lo = 0``).

        The device's sums are float32; where one overflowed, the pass is traced again
        with float64 sums (a second kernel, compiled only then), since float64
        sums in every pass cost time (docs/performance.md, "Execution model")."""
        _s0, k, r0, rows = self.plan.at(pass_index)
        if self.light_tracing:
            sums = PassSums(0, *self._trace_light_pass(pass_index, k * rows * self.opt.width, k, r0, rows))
        elif self.splatting:
            sums = self._trace_splat_pass(pass_index, k, r0, rows)
        else:
            img, sq, nbad = self._trace_pass(pass_index, k, r0, rows, wide=False)
            if not all_finite(img, sq):
                img, sq, nbad = self._trace_pass(pass_index, k, r0, rows, wide=True)
            sums = PassSums(r0, img, sq, nbad)
        if self.aov_kinds:
            sums.aov_lo, sums.aov = self._trace_aov_pass(pass_index, k, r0, rows)
        return sums

    @property
    def aov_kinds(self) -> list[str]:
        """The AOV kinds this render traces (:func:`drpt.aovs.traced`; empty: no AOV kernel)."""
        return [k for _, k in traced(self.opt.aovs, self.opt.denoise)]

    def _trace_aov_pass(self, pass_index: int, k: int, r0: int, rows: int) -> tuple[int, np.ndarray]:
        """The AOV kernel (:mod:`drpt.render.aov`) for the ``k`` samples of each pixel of
        rows ``r0..r0+rows``: camera rays through each pixel as the beauty's samples lie
        (uniform in the pixel, or drawn from the filter with ``filter_sampling``), from
        random streams of their own. With a tent or Gaussian filter the values are splatted
        as the beauty's (:func:`~drpt.render.film.gather_splats`), also for light tracing,
        whose image is splatted. Returns the first row and the ``(rows, W, C + 1)`` sums:
        the channels' weighted sums, then the weights' sum."""
        W, H = self.opt.width, self.opt.height
        n, lane, x, y = self._pass_lanes(k, r0, rows)
        rng = pcg_streams(n, _mix_seed(self.opt.seed ^ AOV_STREAM, pass_index))
        flt = self.opt.pixel_filter
        splat = not flt.is_box and (self.light_tracing or not self.opt.filter_sampling)
        if splat:
            px = Float(x) + rng.next_float32()
            py = Float(y) + rng.next_float32()
            lens = Array2f(rng.next_float32(), rng.next_float32()) if self.camera.thin_lens else None
            o, d = self.camera.ray(px, py, lens)
            weight = None
        else:
            o, d, weight = self._camera_ray(x, y)(rng)
        cam = self.camera_model
        near = None
        if getattr(cam, "near_clip", 0.0) > 0.0 and hasattr(cam, "fov"):
            fwd = np.asarray(cam.direction, np.float64)
            near = (float(cam.near_clip), tuple(float(c) for c in fwd / np.linalg.norm(fwd)))
        values = aov_values(self.scene, rng, o, d, self.aov_kinds, self._aov_index_arrays(), near)
        if weight is not None:
            values = [v * weight for v in values]
        values = [dr.select(dr.isfinite(v), v, 0.0) for v in values]  # as the image drops NaN/Inf
        with llvm_tuning.blocks_for(n):
            dr.eval(values)
        if splat:
            ok = dr.full(Bool, True, n)
            blocks = []
            y0 = r0
            for c in range(0, len(values), 3):
                group = values[c:c + 3] + [Float(0.0)] * (3 - len(values[c:c + 3]))
                y0, s, _sq, wts = gather_splats(flt, W, H, r0, rows, k, px, py, Array3f(*group), ok)
                blocks.append(s[..., :min(3, len(values) - c)])
            return y0, np.concatenate(blocks + [wts[..., :1]], axis=-1)
        sums = [dr.block_sum(v, k) for v in values]
        wsum = None if weight is None else dr.block_sum(Float(weight), k)
        dr.eval(sums, wsum)
        cols = [c.numpy() for c in sums]
        cols.append(np.full(rows * W, float(k)) if wsum is None else wsum.numpy())
        return r0, np.stack(cols, axis=-1).astype(np.float64).reshape(rows, W, len(cols))

    def _trace_pass(self, pass_index: int, k: int, r0: int, rows: int, wide: bool
                    ) -> tuple[np.ndarray, np.ndarray, int]:
        """:meth:`render_pass`'s sums (the device's float64 with ``wide``, else float32; read
        back by :func:`_read_sums`, as float64 where the pass covers the whole image): the
        kernels of :meth:`_pass_arrays`, traced, or replayed where this pass geometry was
        traced before (:mod:`drpt.render.frozen`)."""
        W = self.opt.width
        sums, sqsums, nbad = self._pass_outputs("pass", self._pass_arrays, self._pass_keys(pass_index, r0),
                                                (k, rows, wide))
        dr.eval(sums, sqsums, nbad)
        whole = rows == self.opt.height  # (a merge takes a whole image's float64 sums as its own)
        return _read_sums(sums, rows, W, whole), _read_sums(sqsums, rows, W, whole), int(nbad.numpy()[0])

    def _pass_lanes_per_pixel(self, k: int, pixels: int) -> int:
        """A camera pass's lanes per pixel ``m`` for its ``k`` samples of ``pixels``
        pixels."""
        # Lanes per pixel: with path regeneration m = ceil(min_lanes / pixels)
        # (at most k), each running about k / m samples, else one lane per
        # sample. Fewer, longer lanes balance better (docs/performance.md,
        # "Execution model"), but too few lanes leave the device idle. Where a
        # pixel's paths follow the same mirrors (PathIntegrator.pixel_coherent)
        # a lane per sample keeps each packet on one pixel's paths: m = k.
        # Unrolled short paths (PathIntegrator.straight) all take the same work, so
        # path regeneration's balancing has nothing to gain from long lanes, and a pixel's
        # paths share their hits and misses: m = ceil(k / STRAIGHT_PATHS_PER_LANE) lanes
        # keep a 16-lane packet on one or two pixels' paths (whole packets skip what their
        # escaped paths need not trace) at few lanes' overhead (docs/performance.md).
        # Other paths through a tree or grid (the accelerator's coherent_gain, on a
        # backend whose policy says sample_lanes): a lane per sample too, so that a
        # packet's first rays are one or two pixels' camera rays, which a traversal
        # serves in far less time than scattered ones; that outweighs the lanes that
        # idle in a packet until its longest path ends ("Lanes per pixel on a tree").
        sequential = hasattr(self.integrator, "sample_sequence")
        pol = policy()
        m = min(k, -(-pol.min_lanes // pixels)) if sequential else k
        if sequential and getattr(self.integrator, "pixel_coherent", False):
            m = k
        elif sequential and getattr(self.integrator, "straight", False):
            m = max(m, -(-k // STRAIGHT_PATHS_PER_LANE))
        elif sequential and pol.sample_lanes and self.scene.accel.coherent_gain:
            m = k
        return m

    def _pass_keys(self, pass_index: int, r0: int | None = None, seed: int | None = None) -> dict:
        """What differs between a render's passes of one pass geometry, and between
        renders, as opaque arrays (a frozen pass's inputs): the pass's first row ``r0``
        (where given) and its random-number keys of ``seed`` (the render's unless given),
        the PCG32 streams' key of ``(seed, pass)``, or the low-discrepancy sequences' key
        and the pass's first sample."""
        seed = self.opt.seed if seed is None else seed
        keys = {} if r0 is None else {"r0": dr.opaque(UInt32, r0)}
        if not self.ld_sampling:
            return keys | {"pcg": pcg_keys(_mix_seed(seed, pass_index))}
        plan = self.chunks.passes
        s0 = pass_index // plan.bands * plan.k  # plan[pass_index]'s first sample (also past spp:
        # a live view's frames go on)
        return keys | {"ld": ld_stream_key(seed), "s0": dr.opaque(UInt32, s0)}

    def _pass_arrays(self, keys: dict, k: int, rows: int, wide: bool):
        """The camera pass of ``k`` samples of each pixel of ``rows`` rows from ``keys["r0"]``:
        its device arrays: the pixels' sums and squares (and products), an array a channel
        (:func:`~drpt.render.film.lane_sums`), then the pass's count of dropped non-finite
        samples (:func:`~drpt.render.film.dropped_total`, one element). A pure
        function of ``keys``, its ``int`` arguments and the renderer's device state (the
        contract of :mod:`drpt.render.frozen`)."""
        W = self.opt.width
        pixels = rows * W
        sequential = hasattr(self.integrator, "sample_sequence")
        m = self._pass_lanes_per_pixel(k, pixels)
        n = pass_lanes(pixels, m)
        lane = dr.arange(UInt32, n)
        # (the lane's pixel and its place among the pixel's m lanes without an opaque integer
        # division, drpt.render.lanes; the pass's k // m and k % m are the host's)
        pixel, j = divmod_opaque(lane, m)
        # lanes past the pixels' (film.pass_lanes rounds up to whole records) are pixel 0's
        # lanes with no sample
        real = None if n == pixels * m else lane < dr.opaque(UInt32, pixels * m)
        if real is not None:
            pixel = dr.select(real, pixel, 0)
        x = pixel % W
        y = pixel // W + keys["r0"]
        # with path regeneration lane j of a pixel's m traces its samples j, j + m, ...
        rng = self._sampler(None, n, x, y, j, dr.opaque(UInt32, m) if sequential else 1, keys=keys)

        camera_ray = self._camera_ray(x, y)
        if sequential:
            count = dr.opaque(UInt32, k // m) + dr.select(j < dr.opaque(UInt32, k % m), 1, 0)
            if real is not None:
                count = dr.select(real, count, 0)
            extra = {"moment": True} if self.opt.moment else {}
            acc, acc2, bad, *cross = self.integrator.sample_sequence(rng, camera_ray, count, wide=wide,
                                                                     single=m == k, **extra)
            nbad = dropped_total(bad)  # (the pass's total, added in the path kernel)
            # evaluate the path loop once (the reductions below would each
            # re-run it), in blocks that keep every
            # thread busy to the end (drpt.llvm_tuning.blocks_for)
            with llvm_tuning.blocks_for(n):
                dr.eval(acc, acc2, nbad, cross)
        else:
            o, d, weight = camera_ray(rng)
            L = self.integrator.sample(rng, o, d, Bool(True) if real is None else real)
            if weight is not None:
                L = L * weight
            with llvm_tuning.blocks_for(n):
                dr.eval(L)
            bad = ~(dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z))
            if real is not None:
                bad &= real
            acc = (Array3f64 if wide else Array3f)(dr.select(bad, 0.0, L))
            acc2 = acc * acc
            cross = [type(acc)(acc.x * acc.y, acc.x * acc.z, acc.y * acc.z)] if self.opt.moment else []
            nbad = dropped_total(UInt32(bad))
        # a pixel's lanes summed (film.lane_sums; with one lane a pixel, the lanes' own
        # values): the sums, and as a group of their own (contiguous for the merge's
        # additions) the squares, then with RenderOptions.moment (a Mitsuba moment
        # integrator) the products rg, rb, gb
        squares = [c for a in (acc2, *cross) for c in (a.x, a.y, a.z)]
        sums, sqsums = lane_sums([[acc.x, acc.y, acc.z], squares], m, pixels)
        return sums, sqsums, nbad

    def _pass_outputs(self, name: str, body: Callable, keys: dict, args: tuple):
        """``body(keys, *args)``'s outputs: replayed where this renderer froze the pass
        (:meth:`_frozen_pass`), else traced (the first time, or where recording failed)."""
        frozen = self._frozen_pass(name, body, args)
        out = frozen(keys, self._frozen_signature(), *args) if frozen else None
        return body(keys, *args) if out is None else out

    def _frozen_pass(self, name: str, body: Callable, args: tuple):
        """The :class:`~drpt.render.frozen.FrozenPass` of ``body`` (``name``: which) where
        this pass geometry ``args`` was traced before by this renderer (a render of one
        pass traces it as before: recording costs more than tracing), else None; None also
        where passes are not frozen (:func:`~drpt.render.frozen.freezes`) and while an
        :class:`~drpt.render.instrument.Instrument` is attached (it observes each trace: a
        replay would not call it)."""
        if not freezes(self.integrator) or self.scene.instrument is not None:
            return None
        if (name, args) not in self._traced_args:
            self._traced_args.add((name, args))
            return None
        if name not in self._frozen:
            self._frozen[name] = FrozenPass(body, self._frozen_roots)
        fp = self._frozen[name]
        return None if fp.failed else fp

    def _frozen_roots(self) -> tuple:
        """Where a frozen pass's device inputs are found (:func:`~drpt.render.frozen.device_arrays`):
        the device scene, the integrator, the camera and the sampler class's tables."""
        zsobol = self._zsobol
        return self.scene, self.integrator, self.camera, (zsobol.perms if zsobol is not None else None)

    def _frozen_signature(self) -> tuple:
        """What of the renderer's Python state its pass kernels depend on, for the frozen
        pass's key: the options but the seed (which enters as keys), and the identities
        of the device scene's, the integrator's and the camera's attributes (one replaced,
        as a light selection is, records the pass again)."""
        # the options as their repr: Dr.Jit 1.5's freeze left the arguments after a dataclass
        # argument out of its key (a pass of 2 rows replayed one of 3: tests/render/test_frozen.py)
        return (repr(replace(self.opt, seed=0)),
                tuple(id(v) for r in (self.scene, self.integrator, self.camera) for v in vars(r).values()))

    @property
    def ld_sampling(self) -> bool:
        """Whether passes draw from a low-discrepancy sampler
        (:mod:`drpt.render.sampler`): ``--sampler`` other than ``independent``
        (light tracing: one sequence of all its paths, while they are at most 2^32;
        bidirectional path tracing: its camera samples' sequences, as a camera pass's)."""
        o = self.opt
        if isinstance(self.integrator, BDPTIntegrator):
            return uses_ld(o.sampler)
        return uses_ld(o.sampler) and (not self.light_tracing or o.width * o.height * o.spp <= 1 << 32)

    def _sampler(self, pass_index: int | None, n: int, x: UInt32, y: UInt32, j: UInt32, step,
                 seed: int | None = None, keys: dict | None = None):
        """The random numbers of a camera pass's ``n`` lanes: the lane's PCG32 stream
        of ``(seed, pass, lane)``, or with :attr:`ld_sampling` an
        :class:`~drpt.render.sampler.LDSampler` of pixel ``(x, y)`` whose first sample
        is the pass's first sample plus ``j``, its next ``step`` further on (``seed``:
        the render's unless given; ``keys``: :meth:`_pass_keys` of the pass, in place of
        ``pass_index`` and ``seed``)."""
        if keys is None:
            keys = self._pass_keys(pass_index, seed=seed)
        if not self.ld_sampling:
            return pcg_streams(n, keys["pcg"])
        seed = keys["ld"]
        index = j + keys["s0"]
        zsobol = self._zsobol
        if zsobol is not None:
            return zsobol.for_pixels_xy(seed, x, y, index, step)
        pixel = y * dr.opaque(UInt32, self.opt.width) + x
        return self._ld_class.for_pixels(seed, pixel, index, step)

    @property
    def _ld_class(self) -> type:
        """The low-discrepancy sampler's class of the camera and light passes: ``LDSampler``,
        or for Mitsuba's ``stratified``, ``multijitter`` and ``orthogonal`` the class of this
        spp, jitter and strength (:func:`~drpt.render.sampler.strata_sampler`)."""
        o = self.opt
        if o.sampler in STRATA:
            return strata_sampler(o.sampler, o.spp, o.jitter, o.strength)
        return LDSampler

    @property
    def _zsobol(self):
        """With ``--sampler zsobol``: the :class:`~drpt.render.sampler.ZSobolSampler` class of
        this image size and spp (None otherwise, or where its index does not fit 32 bits:
        then ``ldsampler``'s sequences, with a warning); made once per size and spp."""
        o = self.opt
        if o.sampler != "zsobol":
            return None
        key = (o.width, o.height, o.spp)
        cached = self.__dict__.get("_zsobol_class")
        if cached is None or cached[0] != key:
            cached = self._zsobol_class = (key, ZSobolSampler.for_image(*key))
        return cached[1]

    def _trace_light_pass(self, pass_index: int, n: int, k: int = 0, r0: int = 0, rows: int = 0
                          ) -> tuple[np.ndarray, np.ndarray, int]:
        """``n`` light paths (:class:`~drpt.render.integrators.ptracer.ParticleTracer`)
        splatted into a film of the whole image: its sums and sums of squares ``(H, W,
        3)`` and the non-finite contributions dropped. Their random numbers come from
        the same ``(seed, pass, lane)`` streams as a camera pass's. Bidirectional path
        tracing (:class:`~drpt.render.integrators.bdpt.BDPTIntegrator`) also gives each
        lane a camera sample: the ``k`` samples of each pixel of rows ``r0..r0+rows``,
        pixel-major, uniform in their pixel."""
        if isinstance(self.integrator, BDPTIntegrator):
            if self.integrator.threshold is None:
                self._calibrate_bdpt()
            strategies = None
            if self.opt.bdpt_strategies:
                strategies = StrategyFilm(self.opt.width, self.opt.height,
                                          min(self.integrator.depth, STRATEGY_SEGMENTS))
            film, camera, bad = self._bdpt_pass(self.opt.seed, pass_index, k, r0, rows, strategies)
            if strategies is not None:
                sums = strategies.arrays()
                self.strategy_sums = sums if self.strategy_sums is None else self.strategy_sums + sums
            img, sq, _ = film.arrays()
            cimg, csq, _ = camera.arrays()
            # squares of the light splats, then of the camera samples, then the camera samples'
            # sums: finish estimates the two parts' variances apart (_finish_image)
            return img + cimg, np.concatenate([sq, csq, cimg], axis=-1), int(dr.sum(bad)[0])
        if self.ld_sampling:
                # one sequence of all the render's light paths: lane j of a pass is path
            # first_sample + j (W H spp <= 2^32: ld_sampling)
            first = self.chunks.passes.first_sample(pass_index) & 0xFFFFFFFF  # (a live view: wraps)
            rng = self._ld_class.for_pixels(self.opt.seed, UInt32(0),
                                            dr.arange(UInt32, n) + dr.opaque(UInt32, first))
        else:
            rng = pcg_streams(n, _mix_seed(self.opt.seed, pass_index))
        film = SplatFilm(self.opt.width, self.opt.height, self.opt.pixel_filter, squares=self.opt.light_variance)
        bad = self.integrator.trace(rng, film, dr.full(Bool, True, n))
        with llvm_tuning.blocks_for(n):
            dr.eval(film.sum, film.sq, bad)
        img, sq, _ = film.arrays()
        return img, sq, int(dr.sum(bad)[0])

    def _bdpt_pass(self, seed: int, pass_index: int, k: int, r0: int, rows: int,
                   strategies: StrategyFilm | None = None):
        """Bidirectional path tracing's lanes of a pass, evaluated: ``(light film, camera
        film, dropped)``; their random numbers as a camera pass's (:meth:`_sampler`)."""
        n, lane, x, y = self._pass_lanes(k, r0, rows)
        photons = None
        if self.integrator.merging and strategies is None:
            # caustic photons of the first m lanes' light subpaths, from a stream of their own
            # (BDPTIntegrator.photons); the radius from the pass's samples per pixel (its
            # first and its k), the same in every band of rows and whatever the lanes per pass
            plan = self.chunks.passes
            m = self.integrator.photon_paths(n)
            first = dr.arange(UInt32, m)
            rng = self._sampler(pass_index, m, dr.gather(UInt32, x, first), dr.gather(UInt32, y, first),
                                first % dr.opaque(UInt32, k), 1, seed ^ BDPT_PHOTON_STREAM)
            photons = self.integrator.photons(rng, m, pass_index // plan.bands * plan.k, k)
        rng = self._sampler(pass_index, n, x, y, lane % dr.opaque(UInt32, k), 1, seed)
        u = next_2d(rng)
        squares = self.opt.light_variance
        film = SplatFilm(self.opt.width, self.opt.height, self.opt.pixel_filter, squares=squares)
        camera = SplatFilm(self.opt.width, self.opt.height, self.opt.pixel_filter, squares=squares)
        bad = self.integrator.trace(rng, film, camera, Float(x) + u.x, Float(y) + u.y,
                                    dr.full(Bool, True, n), strategies, photons)
        with llvm_tuning.blocks_for(n):
            dr.eval(film.sum, film.sq, camera.sum, camera.sq, bad, strategies.sum if strategies else [])
        return film, camera, bad

    def _calibrate_bdpt(self) -> None:
        """Bidirectional path tracing's pilot: the path tracer's 1 sample per pixel of at most
        :data:`BDPT_PILOT_LANES` pixels (a band of rows in the middle of the image), from a
        stream of its own, estimates the image's mean pixel value, from which
        :meth:`~drpt.render.integrators.bdpt.BDPTIntegrator.calibrate` sets the roulette's
        threshold. The path tracer has bdpt's expectation, and its kernel costs a fraction of
        bdpt's to trace and to run (docs/performance.md measures a pilot of bdpt's own kernel
        against it)."""
        W, H = self.opt.width, self.opt.height
        rows = max(1, min(H, BDPT_PILOT_LANES // W))
        pilot = self.derive(replace(self.opt, integrator="path", spp=1, bdpt_strategies=False,
                                    seed=self.opt.seed ^ BDPT_PILOT_STREAM))
        img, _, _ = pilot._trace_pass(0, 1, (H - rows) // 2, rows, False)
        rgb = img.reshape(-1, 3).astype(np.float64).mean(0)
        self.integrator.calibrate(float(0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]))

    def _pass_lanes(self, k: int, r0: int, rows: int) -> tuple[int, UInt32, UInt32, UInt32]:
        """``(n, lane, x, y)``: one lane per sample of a pass of ``k`` samples per pixel
        of rows ``r0..r0+rows``, pixel-major (a pixel's ``k`` lanes are adjacent), and
        each lane's pixel column and row."""
        W = self.opt.width
        n = rows * W * k
        lane = dr.arange(UInt32, n)
        pixel = lane // dr.opaque(UInt32, k)
        return n, lane, pixel % W, pixel // W + dr.opaque(UInt32, r0)

    def _trace_splat_pass(self, pass_index: int, k: int, r0: int, rows: int) -> PassSums:
        """:meth:`render_pass` for a tent or Gaussian filter: each of the ``k`` samples of a
        pixel of rows ``r0..r0+rows`` lies uniformly in its pixel, and its radiance
        is splatted into the pixels its filter covers with the filter's weights
        (:class:`~drpt.render.film.SplatFilm`), as Mitsuba's film does. One sample
        per lane. The samples' kernel is :meth:`_splat_samples`' (traced, or replayed as
        :meth:`_trace_pass`'s), the film's gather is traced each pass (it decides on the
        host, from the sums, whether to gather again in float64)."""
        W, H = self.opt.width, self.opt.height
        (px, py), L, bad, weights = self._pass_outputs("splat", self._splat_samples,
                                                       self._pass_keys(pass_index, r0), (k, rows))
        y0, img, sq, wts = gather_splats(self.opt.pixel_filter, W, H, r0, rows, k, px, py, L, ~bad,
                                         self.opt.moment, weights)
        return PassSums(y0, img, sq, int(dr.sum(UInt32(bad))[0]), wts)

    def _splat_samples(self, keys: dict, k: int, rows: int):
        """A splatting pass's samples (``k`` per pixel of ``rows`` rows from ``keys["r0"]``),
        evaluated: positions ``(px, py)`` (``(None, None)`` where the film has weights), radiance ``L``
        (zero where not finite), ``bad`` and the film's per-sample filter weights (or
        None); a pure function as :meth:`_pass_arrays` is."""
        W = self.opt.width
        n = rows * W * k
        # (each lane's pixel and sample without an opaque integer division, drpt.render.lanes)
        pixel, j = divmod_opaque(dr.arange(UInt32, n), k)
        x = pixel % W
        y = pixel // W + keys["r0"]
        rng = self._sampler(None, n, x, y, j, 1, keys=keys)
        u = next_2d(rng)
        px = Float(x) + u.x
        py = Float(y) + u.y
        lens = next_2d(rng) if self.camera.thin_lens else None
        o, d = self.camera.ray(px, py, lens)
        L = self.integrator.sample(rng, o, d, Bool(True))
        bad = ~(dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z))
        L = dr.select(bad, 0.0, L)
        # the film's per-sample filter weights, where it reads them, in this kernel
        weights = splat_weights(self.opt.pixel_filter, W, rows, k, self.opt.moment, x, y, px, py, ~bad)
        with llvm_tuning.blocks_for(n):
            dr.eval(L, bad, weights if weights is not None else (px, py))
        # (the film reads the positions only where it has no weights)
        return (px, py) if weights is None else (None, None), L, bad, weights

    @property
    def light_tracing(self) -> bool:
        """Whether passes splat light paths over the whole image (``ptracer``, ``bdpt``)."""
        return isinstance(self.integrator, (ParticleTracer, BDPTIntegrator))

    @property
    def splatting(self) -> bool:
        """Whether camera samples are splatted through a tent or Gaussian filter
        (the default for those filters; ``filter_sampling`` draws each pixel's
        samples from its filter instead)."""
        return not self.light_tracing and not self.opt.pixel_filter.is_box and not self.opt.filter_sampling

    def _camera_ray(self, x: UInt32, y: UInt32) -> Callable:
        """``camera_ray(rng) -> (o, d, weight)`` for pixel column ``x`` and row
        ``y``: a sample's position in the pixel (uniform in its square for the
        box filter, else drawn from the pixel filter truncated to the image,
        :mod:`~drpt.render.filter_sampling`), then for a thin lens its lens
        point, then the camera ray. ``weight`` is the filter sample's weight,
        ``None`` for 1 (the box and tent filters)."""
        flt = self.opt.pixel_filter
        W, H = self.opt.width, self.opt.height
        camera = self.camera

        def camera_ray(rng):
            u = next_2d(rng)
            if flt.is_box:
                px = Float(x) + u.x
                py = Float(y) + u.y
                weight = None
            else:
                px, py, weight = sample_position(flt, Float(x), Float(y), u.x, u.y, W, H)
            lens = None
            if camera.thin_lens:
                lens = next_2d(rng)
            o, d = camera.ray(px, py, lens)
            return o, d, weight

        return camera_ray

    @property
    def chunks(self) -> ChunkPlan:
        """The render's chunks (:func:`~drpt.render.chunks.plan_chunks`)."""
        o = self.opt
        return plan_chunks(o.width, o.height, o.spp, self.max_lanes, o.chunk_spp)

    def render_chunk(self, index: int, on_pass: Callable[[int], None] | None = None,
                     into: ChunkMerge | None = None) -> ChunkResult:
        """Sums of chunk ``index``'s samples and of their squares, per pixel
        (float64): a pure function of the scene, the options and ``index``.
        ``on_pass(samples)``, if given, is called after each pass with the
        samples of the chunk traced so far.

        ``into``, a merge whose next chunk is ``index``: where each pass of the
        chunk adds to its own rows only, once (one sample step per chunk and no
        splatting film, or a splatting chunk of one pass; no light tracing or AOVs),
        the passes' sums are added straight into the merge's sums, the very float64
        additions that adding the chunk's sums would make (each pixel's chunk sum is
        one pass's), without the chunk's own full-image arrays; a merge that holds no
        sums yet takes a whole-image pass's float64 arrays as they are (a splatting pass's,
        a box pass's: :func:`_takes`, the same bits as their additions into its zeros). The
        result is then
        :attr:`ChunkResult.direct`. Until it is pushed, ``into.dirty`` is set."""
        t0 = time.perf_counter()
        chunks = self.chunks
        plan = chunks.passes
        W, H = self.opt.width, self.opt.height
        own_rows = len(chunks.passes_of(index)) == 1 if self.splatting else chunks.steps == 1
        if into is not None and into.next == index and own_rows and not self.light_tracing and not self.aov_kinds:
            return self._render_chunk_into(index, on_pass, into, t0)
        acc = np.zeros((H, W, 3), np.float64)
        # squares; with moment (Mitsuba's moment integrator) also the channel products
        # (rg, rb, gb) or, splatted, the weighted r^2 .. gb (SplatFilm)
        channels = (9 if self.splatting else 6) if self.opt.moment else 3
        if isinstance(self.integrator, BDPTIntegrator):
            channels = 9  # light splats' squares, camera samples' squares and sums
        acc2 = np.zeros((H, W, channels), np.float64)
        weight = np.zeros((H, W, 2), np.float64) if self.splatting else None
        aov = None
        if self.aov_kinds:
            aov = np.zeros((H, W, channel_count(self.aov_kinds) + 1), np.float64)
        nonfinite = 0
        for i in chunks.passes_of(index):
            _s0, k, r0, rows = plan[i]
            p = self.render_pass(i)
            hi = p.lo + p.sum.shape[0]
            acc[p.lo:hi] += p.sum
            acc2[p.lo:hi] += p.sumsq
            if weight is not None:
                weight[p.lo:hi] += p.weight
            if aov is not None:
                aov[p.aov_lo:p.aov_lo + p.aov.shape[0]] += p.aov
            nonfinite += p.nonfinite
            if on_pass is not None:
                on_pass((_s0 - chunks.spp_before(index)) * H * W + (r0 + rows) * W * k)
        return ChunkResult(index, chunks.spp_of(index), acc, acc2, nonfinite,
                           time.perf_counter() - t0, weight=weight, aov=aov)

    def _render_chunk_into(self, index: int, on_pass, into: ChunkMerge, t0: float) -> ChunkResult:
        chunks = self.chunks
        plan = chunks.passes
        W, H = self.opt.width, self.opt.height
        # squares; with moment also the channel products (rg, rb, gb) or, splatted, the
        # weighted r^2 .. gb (as render_chunk's own arrays); a merge of no chunk yet has no sums
        # to keep (its zeros are made only where read: ChunkMerge.zeros)
        channels = (9 if self.splatting else 6) if self.opt.moment else 3
        if into.shape_of("sumsq")[-1] != channels and (into.next == 0 or not into.sumsq.any()):
            into.zeros("sumsq", (H, W, channels))
        if self.splatting and into.weight is None:
            into.weight = np.zeros((H, W, 2), np.float64)
        nonfinite = 0
        for i in chunks.passes_of(index):
            _s0, k, r0, rows = plan[i]
            p = self.render_pass(i)
            hi = p.lo + p.sum.shape[0]
            empty = into.next == 0 and not into.dirty  # (the merge's sums are still zeros)
            into.dirty = True
            if empty and _takes(into, p):
                # a pass's float64 sums are each 0.0 + itself bit for bit (a splatting pass's
                # gathered sums start from +0.0, a box pass's of the whole image are read back
                # so, _read_sums): the values of additions into the zeros, taken as the
                # merge's arrays (no image-sized additions into fresh pages)
                into.sum, into.sumsq, into.weight = p.sum, p.sumsq, p.weight
            else:
                into.sum[p.lo:hi] += p.sum
                into.sumsq[p.lo:hi] += p.sumsq
                if p.weight is not None:
                    into.weight[p.lo:hi] += p.weight
            nonfinite += p.nonfinite
            if on_pass is not None:
                on_pass((_s0 - chunks.spp_before(index)) * H * W + (r0 + rows) * W * k)
        return ChunkResult(index, chunks.spp_of(index), None, None, nonfinite, time.perf_counter() - t0,
                           direct=True)

    def render(self, on_pass: Callable[[int, int], None] | None = None) -> RenderResult:
        """The image at the options' size and spp: every chunk in order
        (:meth:`render_chunk`), merged as a distributed render merges them
        (:class:`~drpt.render.chunks.ChunkMerge`). ``on_pass(done, total)``,
        if given, is called after each pass with the samples traced so far."""
        from tqdm import tqdm

        if self.opt.adaptive:
            from .adaptive import render_adaptive  # cycle: adaptive builds on this module

            return render_adaptive(self)
        W, H, spp = self.opt.width, self.opt.height, self.opt.spp
        chunks = self.chunks
        merged = ChunkMerge(chunks)
        t0 = time.perf_counter()
        with tqdm(total=W * H * spp, unit="spl", unit_scale=True, disable=not self.opt.progress,
                  desc="render", leave=False) as bar:
            for c in range(chunks.count):
                before = W * H * chunks.spp_before(c)

                def progress(done: int, before: int = before) -> None:
                    bar.update(before + done - bar.n)
                    if on_pass is not None:
                        on_pass(before + done, W * H * spp)

                merged.push(self.render_chunk(c, progress, into=merged))
                estimate = stop_estimate(merged, self.opt, time.perf_counter() - t0, self.light_tracing)
                if estimate is not None:
                    bar.set_postfix_str(f"relMSE ~{estimate:.3g}")
                    if stops(estimate, merged, self.opt, time.perf_counter() - t0):
                        break
        return finish(merged, time.perf_counter() - t0, self.build_seconds, self.light_tracing, consume=True,
                      variance=self.opt.light_variance)


def _read_sums(columns: list, rows: int, W: int, whole: bool) -> np.ndarray:
    """A pass's per-pixel sums, a Dr.Jit array a channel, read back a channel at a time into one
    ``(rows, W, C)`` array: with ``whole`` (the pass covers the image) float64 values of ``0.0 +
    sum``, the values that a merge's additions into its zeros give (-0.0 becomes +0.0), which
    an empty merge takes as its own sums (a float32 stack and a float64 copy of it cost more:
    docs/performance.md); else in the device's precision, which the merge adds into its float64
    sums (a band of the image: float64 there would hold twice the memory beside the merge's)."""
    out = np.empty((rows * W, len(columns)), np.float64 if whole else columns[0].numpy().dtype)
    for i, c in enumerate(columns):
        out[:, i] = c.numpy()
    if whole:
        out += 0.0  # (in place, contiguous: faster than adding into the strided columns)
    return out.reshape(rows, W, len(columns))


def _takes(into: ChunkMerge, p: PassSums) -> bool:
    """Whether the merge ``into`` can take the pass's arrays as its own sums: they cover the
    whole image in the merge's shapes, float64 and writable (:func:`finish` divides in them)."""
    pairs = ((into.shape_of("sum"), p.sum), (into.shape_of("sumsq"), p.sumsq),
             (None if into.weight is None else into.weight.shape, p.weight))
    return p.lo == 0 and all(
        (a is None) == (b is None) and (a is None or (a == b.shape and b.dtype == np.float64
                                                       and b.flags.writeable))
        for a, b in pairs)


def finish(merged: ChunkMerge, seconds: float, build_seconds: float,
           light_tracing: bool = False, consume: bool = False, variance: bool = True) -> RenderResult:
    """The image and variance of a finished merge (:func:`_finish_image`), with the
    AOVs' means where the merge has AOV sums (each pixel's weighted sums over its
    weights' sum). With ``consume`` (the render's last word on the merge) a camera
    render's mean and variance are computed in the merge's own sums, which are then
    no longer sums: no image-sized temporaries beyond the float32 image and one
    channel. A light-traced merge without ``variance`` (its squares were not summed,
    :attr:`~drpt.options.RenderOptions.light_variance`) has a NaN variance."""
    result = _finish_image(merged, seconds, build_seconds, light_tracing, consume)
    if light_tracing and not variance:
        result.variance = np.full(result.image.shape, np.nan)
    if merged.aov is not None:
        ws = merged.aov[..., -1:]
        ok = ws > 0.0
        result.aov = np.where(ok, merged.aov[..., :-1] / np.where(ok, ws, 1.0), 0.0).astype(np.float32)
    return result


#: films of at most this many pixels get their variance and moments computed when first read
#: (:mod:`drpt.render.deferred`): there the finish is a visible share of a render, and the
#: float64 mean that the result keeps until then (24 bytes a pixel) is at most 6 MB; a larger
#: render computes them at once, so its peak memory is not raised by the mean kept beside
#: what follows the render (writing the image)
DEFER_MAX_PIXELS = 1 << 18


def _finish_image(merged: ChunkMerge, seconds: float, build_seconds: float,
                  light_tracing: bool = False, consume: bool = False) -> RenderResult:
    """The image and variance of a finished merge.

    * Camera samples of their own pixel: the mean of the pixel's samples, and the
      variance of that mean from their squares.
    * Splatted camera samples (``merged.weight`` holds ``sum(w)``, ``sum(w^2)``):
      ``sum(w L) / sum(w)`` (Mitsuba's film), and the variance of that weighted mean,
      ``(sum(w^2 L^2) / sum(w^2) - mean^2) sum(w^2) / sum(w)^2``, corrected for the
      effective sample count ``sum(w)^2 / sum(w^2)``. With a moment render the
      second moment is ``sum(w L_a L_b) / sum(w)``, as Mitsuba's film develops its
      ``m2_`` channels.
    * ``light_tracing``: splats of ``W H spp`` light paths
      (:mod:`~drpt.render.integrators.ptracer`): a pixel's value is its sum over
      ``spp``, and the variance of that mean is estimated from the sum of squared
      splats, each path counting as a sample of ``W H`` times its splat."""
    spp = merged.spp
    H, W, _ = merged.sum.shape
    if merged.weight is not None:
        return _finish_weighted(merged, seconds, build_seconds, consume)
    if consume and not light_tracing:
        mean = merged.sum
        mean /= spp  # the same division as merged.sum / spp, in the merge's array
    else:
        mean = merged.sum / spp
    _check_range(mean)
    if light_tracing:
        paths = W * H * spp
        if merged.sumsq.shape[-1] == 9:
            # bdpt: the camera samples' part (squares and sums after the splats' squares) is
            # a mean of spp samples per pixel, the rest a light-traced image
            cam = merged.sumsq[..., 6:] / spp
            var_c = np.maximum(merged.sumsq[..., 3:6] / spp - cam * cam, 0.0) / max(spp - 1, 1)
            light = mean - cam
            second = merged.sumsq[..., :3] * (W * H) / spp
            var = var_c + np.maximum(second - light * light, 0.0) / max(paths - 1, 1)
            return RenderResult(mean.astype(np.float32), var, seconds, build_seconds, paths,
                                merged.nonfinite)
        second = merged.sumsq * (W * H) / spp  # mean over paths of (W H splat)^2
        var = np.maximum(second - mean * mean, 0.0) / max(paths - 1, 1)
        return RenderResult(mean.astype(np.float32), var, seconds, build_seconds, paths,
                            merged.nonfinite)
    image = mean.astype(np.float32)
    if not consume or H * W > DEFER_MAX_PIXELS:
        var, moment2 = _variance_and_moment(merged.sumsq, mean, spp, consume)
        return RenderResult(image, var, seconds, build_seconds, W * H * spp, merged.nonfinite, moment2)
    # a small render's own result: its variance and moments computed when first read, from
    # the merge's mean and squares (the closure keeps those two arrays until then, not the merge)
    sumsq = merged.sumsq
    both = Later(lambda: _variance_and_moment(sumsq, mean, spp, True))
    moment2 = Later(lambda: both.value()[1]) if sumsq.shape[-1] == 6 else None
    return RenderResult(image, Later(lambda: both.value()[0]), seconds, build_seconds, W * H * spp,
                        merged.nonfinite, moment2)


def _variance_and_moment(sumsq: np.ndarray, mean: np.ndarray, spp: int,
                         consume: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """The variance of each pixel's mean of ``spp`` samples, from the sums of their squares
    (``sumsq``: the squares, then with a ``moment`` render the channel products) and the
    means; and the second moments of a ``moment`` render (else None). With ``consume`` in
    ``sumsq``'s own array."""
    # Unbiased sample variance of one sample, divided by spp: variance of the mean,
    # max(sumsq / spp - mean^2, 0) * spp / max(spp - 1, 1) / spp = max(...) / max(spp - 1, 1),
    # in place (consume: the squares' means in the merge's own array, the same division as
    # sumsq / spp)
    second = np.divide(sumsq, spp, out=sumsq if consume else None)
    moment2 = xyz_second_moment(second) if second.shape[-1] == 6 else None
    # (with the channel products after the squares, var is a fresh array: each channel's
    # difference written into it, with no copy of the squares first)
    var = second if second.shape[-1] == 3 else np.empty(mean.shape)
    square = np.empty(mean.shape[:-1])  # one channel's temporary, for each channel in turn
    for c in range(3):
        np.subtract(second[..., c], np.square(mean[..., c], out=square), out=var[..., c])
    np.maximum(var, 0.0, out=var)
    var /= max(spp - 1, 1)
    return var, moment2


def _finish_weighted(merged: ChunkMerge, seconds: float, build_seconds: float,
                     consume: bool) -> RenderResult:
    """:func:`_finish_image` of splatted camera samples (``merged.weight``): with
    ``consume``, in the merge's own arrays, without image-sized temporaries (each a fresh
    allocation, paid in page faults). A pixel without weight (no sample reached it) divides
    by 1 and reads 0: image, variance and moments."""
    spp = merged.spp
    H, W, _ = merged.sum.shape
    ok = merged.weight[..., :1] > 0.0
    every = bool(ok.all())
    if every:
        ws = np.ascontiguousarray(merged.weight[..., :1])
        ws2 = np.ascontiguousarray(merged.weight[..., 1:])
    else:
        ws, ws2 = np.where(ok, merged.weight[..., :1], 1.0), np.where(ok, merged.weight[..., 1:], 1.0)
    none = None if every else np.broadcast_to(~ok, merged.sum.shape)
    mean = _per_pixel_divide(merged.sum, ws, merged.sum if consume else None)
    if none is not None:
        mean[none] = 0.0
    _check_range(mean)
    n_eff = ws * ws / ws2  # (1 where no weight)
    sq = merged.sumsq
    var = _per_pixel_divide(sq[..., :3], ws2)
    if none is not None:
        var[none] = 0.0
    var -= mean * mean
    np.maximum(var, 0.0, out=var)
    n_eff -= 1.0
    var /= np.maximum(n_eff, 1.0, out=n_eff)
    moment2 = None
    if sq.shape[-1] == 9:  # the weighted r^2 .. gb, as Mitsuba's film develops its m2_
        second = _per_pixel_divide(sq[..., 3:], ws, sq[..., 3:] if consume else None)
        if none is not None:
            second[np.broadcast_to(~ok, second.shape)] = 0.0
        moment2 = xyz_second_moment(second)
    return RenderResult(mean.astype(np.float32), var, seconds, build_seconds, W * H * spp,
                        merged.nonfinite, moment2)


def _per_pixel_divide(a: np.ndarray, w: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``a / w`` for ``(H, W, C)`` values and ``(H, W, 1)`` per-pixel divisors, into ``out``
    (a fresh array if None): numpy's broadcast division's very quotients, a channel at a time,
    whose loops run over the pixels where the broadcast's inner loops run over ``C`` values
    (half the time for ``C`` of 3 to 6: docs/performance.md)."""
    out = np.empty(a.shape) if out is None else out
    d = w[..., 0]
    for c in range(a.shape[-1]):
        np.divide(a[..., c], d, out=out[..., c])
    return out


def stop_estimate(merged: ChunkMerge, opts: RenderOptions, seconds: float,
                  light_tracing: bool) -> float | None:
    """With a target error or a time limit: the estimated relMSE of the merged image
    so far (None before 2 samples per pixel, or without either option)."""
    if opts.target_error is None and opts.time_limit is None:
        return None
    if merged.spp < 2 or merged.done:
        return None
    r = finish(merged, seconds, 0.0, light_tracing)
    return r.estimated_rel_mse


def stops(estimate: float | None, merged: ChunkMerge, opts: RenderOptions, seconds: float) -> bool:
    """Whether a render stops after the merged chunks: its estimate (of
    :func:`stop_estimate`) at most the target error, or the time limit passed. Only
    the merged prefix of chunks decides, so a render stopped by its estimate is the
    same for a seed whatever ran it (in process, on workers, resumed)."""
    if merged.done or merged.spp < 2:
        return False
    if opts.target_error is not None and estimate is not None and estimate <= opts.target_error:
        return True
    return opts.time_limit is not None and seconds >= opts.time_limit


def all_finite(*arrays: np.ndarray) -> bool:
    """Whether every value of the arrays is finite: a pass's float32 sums (read back as
    float64 where the pass covers the image: an overflow stays infinite) did not overflow
    (:meth:`Renderer.render_pass`).
    Each array's largest and smallest value (a NaN propagates through both): vectorized
    passes in the arrays' own precision, no temporary per element, and no false alarm where
    the finite values' sum would pass the float32 maximum."""
    return all(np.isfinite(a.max()) and np.isfinite(a.min()) for a in arrays)


def _check_range(mean: np.ndarray) -> None:
    """A pixel mean beyond float32, which no image file holds, is an error."""
    if mean.max() > np.finfo(np.float32).max:
        y, x, _ = np.unravel_index(np.argmax(mean), mean.shape)
        raise DrptError(f"pixel ({x}, {y}) averages {mean.max():.3g}, beyond the float32 "
                        "maximum (3.4e38) of the image: scale the scene's emission down")


#: linear sRGB -> CIE XYZ, Mitsuba's ``srgb_to_xyz``
SRGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423],
                        [0.212671, 0.715160, 0.072169],
                        [0.019334, 0.119193, 0.950227]])


def xyz_second_moment(m: np.ndarray) -> np.ndarray:
    """Per pixel, the mean of ``X^2, Y^2, Z^2`` over the samples, from the means ``m`` of
    ``r^2, g^2, b^2, rg, rb, gb`` (``X = a . rgb`` gives ``X^2 = a^T (rgb rgb^T) a``): one
    matrix product with :data:`_XYZ_SQUARES`."""
    return m[..., :6] @ _XYZ_SQUARES


def _xyz_squares() -> np.ndarray:
    """The ``6 x 3`` matrix taking ``(r^2, g^2, b^2, rg, rb, gb)`` to ``(X^2, Y^2, Z^2)``."""
    a = np.asarray(SRGB_TO_XYZ, np.float64)
    return np.stack([a[:, 0] ** 2, a[:, 1] ** 2, a[:, 2] ** 2,
                     2 * a[:, 0] * a[:, 1], 2 * a[:, 0] * a[:, 2], 2 * a[:, 1] * a[:, 2]])


_XYZ_SQUARES = _xyz_squares()
