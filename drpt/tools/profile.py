"""``python -m drpt profile SCENE``: where a render spends its time, megakernel against wavefront.

The same render (same options, same seed) is run in both execution modes of
the path tracer (``--mode both``, the default, or one of them):

* **megakernel** (drpt's default): camera, the whole path loop, traversal and
  shading fused into one kernel per pass (symbolic loops, path regeneration);
* **wavefront** (:mod:`drpt.render.integrators.wavefront`): per bounce, the
  live paths compacted and sorted for coherence, a closest-hit kernel,
  emission, per-material shading queues, one batch of shadow rays; the path
  state in memory between kernels.

Each mode first renders once as a warm-up, so compilation (LLVM backend time)
lands there and is reported apart; ``--repeat`` timed renders follow with
``dr.JitFlag.KernelHistory`` on (the fastest counts) and every entry of
``dr.kernel_history()`` is kept. Peak memory comes from
``dr.detail.malloc_watermark`` on drpt's backend.

Stages, rays, lanes, occupancy
------------------------------
*Wavefront*: an instrumented render (:class:`~drpt.render.integrators.wavefront.WaveStats`)
synchronises at every stage boundary and reads the kernel history there, so
each kernel is attributed to the stage that launched it (Dr.Jit 1.5 records
no labels); rays are the paths entering the closest-hit kernel and the
shadow rays of the batches, exactly. Its kernels run only live paths
(compaction: occupancy 1 by construction); what it saves is shown by the
live paths per bounce against the pass width. A second timed render without
the coherence sort gives the sort's effect (A/B in one process).

*Megakernel*: the fused kernel cannot be split; its history is split by
kernel (the path kernel and the accumulation kernels around it). An
instrumented render counts, per lane, the loop iterations it ran and the
shadow rays it traced (an :class:`~drpt.render.instrument.Instrument` on the
scene: a scatter-add in the loop; not timed): rays are
exact, and the SIMD occupancy is the useful lane-iterations over those the
packets executed (a packet of ``W`` consecutive lanes runs until its
longest lane is done; ``W`` = 16 with AVX-512, 8 with AVX2, read from the
CPU flags: an assumption about Dr.Jit's LLVM vector width).

The verdict says which mode is faster and why, from these numbers: kernel
time against time outside kernels (launches, synchronisation, Python), the
megakernel's occupancy, memory.

Light tracing (``--integrator ptracer|bdpt``)
---------------------------------------------
The renderer traces a light-tracing pass as one fused kernel (light subpath,
for bdpt the camera subpath and every connection, the splats): there is no
wavefront mode, so no coherence sort, fused tail or per-stage kernels, and
the subpaths' times cannot be separated. What applies is measured as for the
megakernel: warm-up, timed renders, kernel history split by kernel (the pass
kernel against accumulation and readback), peak memory, samples/s (a sample
is one light path, for bdpt one light subpath and one camera sample). An
instrumented render (not timed) counts every query by its purpose through
:meth:`Instrument.count <drpt.render.instrument.Instrument.count>`: closest
hits of the light and camera subpaths, shadow rays (light vertex to camera
``t = 1``, next-event ``s = 1``, connections ``s, t >= 2``, emitters seen by
the camera) and splats; the scene's ``occluded`` hook counts the shadow rays
once more, as a check. Per-lane counts give each subpath loop's SIMD
occupancy as for the megakernel. With ``--mode both`` (the default) the path
tracer's megakernel renders the same image size and spp for the trade
(samples/s, rays per sample); ``--mode megakernel`` profiles the light tracer
alone. Error per sample is not measured here (``drpt converge`` measures error
against time).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..backend import ensure, jit_backend
from ..cli.args import add_render_flags, options_from_args
from ..errors import DrptError
from ..options import RenderOptions
from ..render.instrument import HIT_CAMERA, HIT_LIGHT, SPLAT, Instrument
from ..render.integrators.wavefront import OUTSIDE, WaveStats
from ..render.renderer import Renderer, plan_passes
from ..scene import load_scene
from ..scene.files import check_input

MODES = ("megakernel", "wavefront")
LIGHT_TRACERS = ("ptracer", "bdpt")
#: the name of the fused pass kernel of each light-tracing integrator
LIGHT_FUSED = {"ptracer": "fused light-tracing kernel (light paths + splats)",
               "bdpt": "fused bdpt kernel (both subpaths + connections)"}
#: what ``profile`` does not measure for a light-tracing integrator, and why
LIGHT_NOT_APPLICABLE = [
    "per-stage times: one fused kernel per pass (subpaths, connections and splats are not separate kernels)",
    "wavefront mode, coherence sort and fused tail: light tracing has no wavefront integrator",
    "error per sample: use drpt converge for error against time",
]


# --------------------------------------------------------------------------- history helpers

def _entry(h: dict) -> dict:
    """A JSON-friendly copy of one ``dr.kernel_history()`` entry (IR dropped)."""
    return {
        "type": str(h["type"]).split(".")[-1],
        "hash": h.get("hash", ""),
        "size": int(h.get("size", 0)),
        "operation_count": int(h.get("operation_count", 0)),
        "execution_ms": float(h.get("execution_time", 0.0)),
        "codegen_ms": float(h.get("codegen_time", 0.0)),
        "backend_ms": float(h.get("backend_time", 0.0)),
        "cache_hit": bool(h.get("cache_hit", 0)),
        "cache_disk": bool(h.get("cache_disk", 0)),
    }


def _history() -> list[dict]:
    import drjit as dr

    return [_entry(h) for h in dr.kernel_history()]


@dataclass
class Stage:
    name: str
    kernel_ms: float = 0.0
    wall_ms: float = 0.0
    launches: int = 0  # all history entries (JIT kernels, reductions, copies, memsets)
    jit_kernels: int = 0
    lanes: int = 0  # sum of kernel sizes
    rays: int = 0  # active rays traced (accelerator stages, camera), else 0
    codegen_ms: float = 0.0

    def add(self, entries: list[dict]) -> None:
        for e in entries:
            self.kernel_ms += e["execution_ms"]
            self.codegen_ms += e["codegen_ms"]
            self.launches += 1
            self.jit_kernels += e["type"] == "JIT"
            self.lanes += e["size"]

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class ModeResult:
    mode: str
    warmup_s: float
    warmup_backend_ms: float
    seconds: float  # wall time of the timed render
    samples: int
    peak_bytes: int
    entries: list[dict]
    stages: list[Stage] = field(default_factory=list)
    staged_seconds: float | None = None  # wall time of the instrumented run
    occupancy: dict = field(default_factory=dict)
    unsorted_seconds: float | None = None  # wavefront without the coherence sort (A/B)
    unsorted_stages: list[Stage] = field(default_factory=list)
    tail_ab: dict = field(default_factory=dict)  # wavefront with the other fused-tail setting (A/B)
    passes: int | None = None
    integrator: str = "path"
    not_applicable: list[str] = field(default_factory=list)  # what is not measured for it, and why

    @property
    def kernel_ms(self) -> float:
        return sum(e["execution_ms"] for e in self.entries)

    @property
    def launches(self) -> int:
        return len(self.entries)

    @property
    def jit_kernels(self) -> int:
        return sum(e["type"] == "JIT" for e in self.entries)

    @property
    def codegen_ms(self) -> float:
        return sum(e["codegen_ms"] for e in self.entries)

    @property
    def backend_ms(self) -> float:
        return sum(e["backend_ms"] for e in self.entries)

    @property
    def samples_per_second(self) -> float:
        return self.samples / max(self.seconds, 1e-12)

    def as_dict(self) -> dict:
        return {
            "mode": self.mode,
            "integrator": self.integrator,
            "not_applicable": self.not_applicable,
            "warmup_seconds": self.warmup_s,
            "warmup_backend_ms": self.warmup_backend_ms,
            "seconds": self.seconds,
            "staged_seconds": self.staged_seconds,
            "samples": self.samples,
            "samples_per_second": self.samples_per_second,
            "kernel_ms": self.kernel_ms,
            "launches": self.launches,
            "jit_kernels": self.jit_kernels,
            "codegen_ms": self.codegen_ms,
            "backend_ms": self.backend_ms,
            "peak_bytes": self.peak_bytes,
            "passes": self.passes,
            "occupancy": self.occupancy,
            "unsorted_seconds": self.unsorted_seconds,
            "unsorted_stages": [s.as_dict() for s in self.unsorted_stages],
            "tail_ab": self.tail_ab,
            "stages": [s.as_dict() for s in self.stages],
            "kernels": self.entries,
        }


# --------------------------------------------------------------------------- running

@dataclass
class ProfileOptions:
    """What ``profile`` renders (``render``, a :class:`~drpt.options.RenderOptions`;
    its progress bar is off) and how many timed renders per mode (``repeat``)."""

    render: RenderOptions = field(default_factory=lambda: RenderOptions(width=128, height=128, spp=16))
    repeat: int = 1  # timed renders per mode; the fastest is kept

    @property
    def width(self) -> int:
        return self.render.width

    @property
    def height(self) -> int:
        return self.render.height

    @property
    def spp(self) -> int:
        return self.render.spp

    @property
    def max_lanes(self) -> int:
        return self.render.lanes

    def as_dict(self) -> dict:
        return {**asdict(self.render), "repeat": self.repeat}


def _renderer(scene, popt: ProfileOptions):
    from dataclasses import replace

    return Renderer(scene, replace(popt.render, progress=False))


FUSED = "fused megakernel (camera + whole path loop)"


def _megakernel_stages(entries: list[dict], rays: int, fused: str = FUSED) -> list[Stage]:
    """Megakernel history split by kernel (stages are fused and cannot be separated).

    The path kernels are the JIT kernels with at least half the operation
    count of the largest one; the rest are accumulation kernels.
    """
    jit = [e for e in entries if e["type"] == "JIT"]
    big = max((e["operation_count"] for e in jit), default=-1)
    groups: dict[str, list[dict]] = defaultdict(list)
    for e in entries:
        if e["type"] == "JIT" and e["operation_count"] * 2 >= big:
            groups[fused].append(e)
        elif e["type"] == "JIT":
            groups["other JIT kernels (accumulation)"].append(e)
        else:
            groups[f"{e['type']} (accumulation + readback)"].append(e)
    out = []
    for name, es in groups.items():
        st = Stage(name)
        st.add(es)
        if name == fused:
            st.rays = rays
        out.append(st)
    return out


def _simd_width() -> int:
    """Float32 lanes of a CPU vector: 16 with AVX-512, 8 with AVX2 (Linux CPU flags), else 4."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return 8
    return 16 if "avx512f" in flags else 8 if "avx2" in flags else 4


def _time_once(renderer) -> tuple[float, list[dict]]:
    """One render's wall time and kernel history."""
    import drjit as dr

    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.sync_thread()
        dr.kernel_history_clear()
        t0 = time.perf_counter()
        renderer.render()
        dr.sync_thread()
        t = time.perf_counter() - t0
        return t, _history()


def _timed(renderer, repeat: int) -> tuple[float, list[dict]]:
    """The fastest of ``repeat`` renders (the machine may be shared) and its history."""
    best = (float("inf"), [])
    for _ in range(max(1, repeat)):
        run = _time_once(renderer)
        if run[0] < best[0]:
            best = run
    return best


class _LaneCounts(Instrument):
    """An instrument (:mod:`drpt.render.instrument`) counting, per lane of each pass,
    the path vertices it traces and the shadow rays it asks for (scatter-adds that
    land in the path kernel)."""

    def __init__(self):
        self.iters: list = []  # per pass: UInt32 per lane
        self.shadows: list = []

    def paths(self, lanes: int, kinds: tuple[str, ...] = ()) -> None:
        import drjit as dr
        from drjit.auto import UInt32

        self.n = lanes
        self.iters.append(dr.zeros(UInt32, lanes))
        self.shadows.append(dr.zeros(UInt32, lanes))
        dr.eval(self.iters[-1], self.shadows[-1])

    def _count(self, into, active) -> None:
        import drjit as dr
        from drjit.auto import Bool, UInt32

        dr.scatter_add(into, UInt32(1), dr.arange(UInt32, self.n), active | dr.zeros(Bool, self.n))

    def bounce(self, state) -> None:
        self._count(self.iters[-1], state.active)

    def occluded(self, o, d, tmax, active) -> None:
        self._count(self.shadows[-1], active)


def _counted_render(renderer, counts):
    """Render once with ``counts`` as the scene's instrument (detached afterwards, also on
    an error); return ``counts``."""
    scene = renderer.scene
    scene.instrument = counts
    try:
        renderer.render()
    finally:
        scene.instrument = None
    return counts


def _megakernel_counts(renderer) -> dict:
    """Per-lane loop iterations and shadow rays of one megakernel render,
    counted by an instrument on the scene (:class:`_LaneCounts`; not timed)."""
    import numpy as np

    counts = _counted_render(renderer, _LaneCounts())
    iters = [c.numpy() for c in counts.iters]
    shadows = [c.numpy() for c in counts.shadows]
    w = _simd_width()
    useful = executed = 0
    for c in iters:
        c = c.astype(np.int64)
        pad = (-len(c)) % w
        packets = np.concatenate([c, np.zeros(pad, np.int64)]).reshape(-1, w)
        useful += int(c.sum())
        executed += int(packets.max(1).sum()) * w
    lanes = sum(len(c) for c in iters)
    return {"simd_width_assumed": w, "lanes": lanes, "lane_iterations": useful,
            "executed_lane_iterations": executed, "occupancy": useful / max(executed, 1),
            "max_iterations_per_lane": int(max((c.max() for c in iters), default=0)),
            "mean_iterations_per_lane": useful / max(lanes, 1),
            "closest_hit_rays": useful, "shadow_rays": int(sum(int(x.sum()) for x in shadows))}


OCCLUDED = "shadow rays seen by the scene"


class _KindCounts(_LaneCounts):
    """An instrument counting, per lane of each pass, the light-tracing integrators'
    queries by kind (:meth:`Instrument.count`) and the scene's shadow rays."""

    def __init__(self):
        self.passes: list[dict] = []  # per pass: kind -> UInt32 per lane

    def paths(self, lanes: int, kinds: tuple[str, ...] = ()) -> None:
        import drjit as dr
        from drjit.auto import UInt32

        self.n = lanes
        counters = {k: dr.zeros(UInt32, lanes) for k in (*kinds, OCCLUDED)}
        dr.eval(*counters.values())  # in memory before the kernel's loops
        self.passes.append(counters)

    def bounce(self, state) -> None:  # the path tracer's hook: not called by light tracing
        pass

    def occluded(self, o, d, tmax, active) -> None:
        self._count(self.passes[-1][OCCLUDED], active)

    def count(self, kind: str, active) -> None:
        self._count(self.passes[-1][kind], active)


def _loop_occupancy(per_lane: list, w: int) -> dict:
    """SIMD occupancy of a loop from each lane's iterations (packets of ``w`` lanes
    run until their longest lane is done)."""
    import numpy as np

    useful = executed = top = 0
    for c in per_lane:
        c = c.astype(np.int64)
        packets = np.concatenate([c, np.zeros((-len(c)) % w, np.int64)]).reshape(-1, w)
        useful += int(c.sum())
        executed += int(packets.max(1).sum()) * w
        top = max(top, int(c.max(initial=0)))
    lanes = sum(len(c) for c in per_lane)
    return {"occupancy": useful / max(executed, 1), "lane_iterations": useful,
            "executed_lane_iterations": executed, "mean_iterations_per_lane": useful / max(lanes, 1),
            "max_iterations_per_lane": top}


def _light_counts(renderer) -> dict:
    """Queries by kind of one light-tracing render, counted by an instrument on the
    scene (:class:`_KindCounts`; not timed), and its subpath loops' SIMD occupancy."""
    counts = _counted_render(renderer, _KindCounts())
    per_kind: dict[str, list] = defaultdict(list)
    for p in counts.passes:
        for k, c in p.items():
            per_kind[k].append(c.numpy())
    totals = {k: int(sum(int(c.sum()) for c in cs)) for k, cs in per_kind.items()}
    w = _simd_width()
    loops = {k: _loop_occupancy(per_kind[k], w) for k in (HIT_LIGHT, HIT_CAMERA) if k in per_kind}
    kinds = {k: v for k, v in totals.items() if k != OCCLUDED}
    return {"simd_width_assumed": w, "lanes": sum(len(c) for c in per_kind[OCCLUDED]),
            "rays_by_kind": kinds,
            "closest_hit_rays": sum(v for k, v in kinds.items() if k.startswith("closest hit")),
            "shadow_rays": sum(v for k, v in kinds.items() if k.startswith("shadow")),
            "shadow_rays_seen_by_scene": totals[OCCLUDED],
            "splats": kinds.get(SPLAT, 0), "loops": loops}


def _measure(renderer, repeat: int) -> tuple[float, float, float, list[dict], int]:
    """A warm-up render (it compiles every kernel, or loads it from Dr.Jit's caches): its
    wall seconds and backend milliseconds; then the fastest of ``repeat`` timed renders
    (:func:`_timed`: its seconds and kernel history) and the peak memory in bytes."""
    import drjit as dr

    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        t0 = time.perf_counter()
        renderer.render()
        dr.sync_thread()
        warmup = time.perf_counter() - t0
        warm_backend = sum(e["backend_ms"] for e in _history())
    dr.flush_malloc_cache()
    dr.detail.malloc_clear_statistics()
    seconds, entries = _timed(renderer, repeat)
    peak = int(dr.detail.malloc_watermark(jit_backend()))
    return warmup, warm_backend, seconds, entries, peak


def profile_light(scene, popt: ProfileOptions, base=None) -> ModeResult:
    """Profile a light-tracing integrator (``popt.render.integrator``, one of
    :data:`LIGHT_TRACERS`): its fused pass kernel timed as the megakernel is, its
    queries counted by kind; the renderer stays on the result (``result.renderer``)."""

    name = popt.render.integrator
    renderer = _renderer(scene, popt) if base is None else base
    warmup, warm_backend, seconds, entries, peak = _measure(renderer, popt.repeat)
    result = ModeResult(name, warmup, warm_backend, seconds, popt.width * popt.height * popt.spp, peak,
                        entries, integrator=name, not_applicable=list(LIGHT_NOT_APPLICABLE))
    result.renderer = renderer
    result.occupancy = _light_counts(renderer)
    return result


def _wavefront_stages(renderer, sort: bool) -> tuple[list[Stage], float, list[list[int]]]:
    """Stages of one instrumented wavefront render, its wall time and the live
    paths per bounce of each pass."""
    import drjit as dr

    integ = renderer.integrator
    integ.sort = sort
    integ.stats = WaveStats(history=True)
    try:
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.sync_thread()
            dr.kernel_history_clear()
            t0 = time.perf_counter()
            renderer.render()
            dr.sync_thread()
            staged = time.perf_counter() - t0
            rest = _history()  # accumulation and readback after each pass
        stats = integ.stats
    finally:
        integ.stats, integ.sort = None, True
    stages = {}
    for ws in stats.stages.values():
        stages[ws.name] = Stage(ws.name, kernel_ms=ws.kernel_ms, wall_ms=ws.wall_ms, launches=ws.launches,
                                jit_kernels=ws.jit_kernels, lanes=ws.lanes, rays=ws.rays,
                                codegen_ms=ws.codegen_ms)
    acc = stages.setdefault(OUTSIDE, Stage(OUTSIDE))
    acc.add(rest)  # accumulation and readback after the last pass
    # its wall time: what the stages inside sample() did not account for
    acc.wall_ms = max(0.0, staged * 1e3 - sum(s.wall_ms for s in stages.values() if s is not acc))
    return list(stages.values()), staged, stats.live


def profile_mode(scene, popt: ProfileOptions, mode: str, base=None) -> ModeResult:
    """Profile ``mode`` (a renderer of its own, or derived from ``base``'s device
    scene); the renderer stays on the result (``result.renderer``)."""
    from dataclasses import replace


    popt = replace(popt, render=replace(popt.render, mode=mode))
    samples = popt.width * popt.height * popt.spp
    renderer = _renderer(scene, popt) if base is None else base.derive(replace(popt.render, progress=False))
    result_integrator = popt.render.integrator
    warmup, warm_backend, seconds, entries, peak = _measure(renderer, popt.repeat)
    result = ModeResult(mode, warmup, warm_backend, seconds, samples, peak, entries, integrator=result_integrator)
    result.renderer = renderer
    if mode == "megakernel":
        result.occupancy = _megakernel_counts(renderer)
        return result  # its stages: from the fastest run's history (run_profile)
    # the instrumented renders, sorted and unsorted interleaved; the fastest of each
    staged = {True: None, False: None}
    for _ in range(max(1, popt.repeat)):
        for srt in (True, False):
            run = _wavefront_stages(renderer, sort=srt)
            if staged[srt] is None or run[1] < staged[srt][1]:
                staged[srt] = run
    result.stages, result.staged_seconds, live = staged[True]
    result.unsorted_stages = staged[False][0]
    rays = {s.name: s.rays for s in result.stages}
    lane_bounces = sum(sum(v) for v in live)
    full = sum(len(v) * v[0] for v in live if v)
    result.occupancy = {"occupancy": 1.0, "bounces_per_pass": [len(v) for v in live],
                        "live_per_bounce": live[0] if live else [], "lane_bounces": lane_bounces,
                        "full_width_lane_bounces": full, "live_fraction": lane_bounces / max(full, 1),
                        "closest_hit_rays": rays.get("closest hit", 0), "shadow_rays": rays.get("shadow rays", 0)}
    # A/B in one process, interleaved (the machine may be shared): the same renderer
    # without the coherence sort (the same image, bit for bit) and with the other
    # fused-tail setting; the best of ``repeat`` renders of each, the sorted render's
    # runs included.
    integ = renderer.integrator
    base_tail = integ.tail
    other_tail = TAIL_AB if base_tail == 0 else 0
    variants = {"sorted": (True, base_tail), "unsorted": (False, base_tail), "tail": (True, other_tail)}
    best = {"sorted": seconds, "unsorted": float("inf"), "tail": float("inf")}
    entries_of = {"sorted": entries}
    try:
        for name in ("unsorted", "tail"):  # warm-up: their few other kernels
            integ.sort, integ.tail = variants[name]
            renderer.render()
        for _ in range(max(1, popt.repeat)):
            for name, (srt, tl) in variants.items():
                integ.sort, integ.tail = srt, tl
                t, run_entries = _time_once(renderer)
                if t < best[name]:
                    best[name], entries_of[name] = t, run_entries
    finally:
        integ.sort, integ.tail = True, base_tail
    result.seconds, result.entries = best["sorted"], entries_of["sorted"]
    result.unsorted_seconds = best["unsorted"]
    result.tail_ab = {"tail": other_tail, "seconds": best["tail"], "render_tail": base_tail}
    return result


TAIL_AB = 16384  # the fused tail the A/B tries (paths left in a pass)


def run_profile(scene_path: str | Path, popt: ProfileOptions, modes=MODES) -> list[ModeResult]:
    """Profile ``modes`` of the path tracer, or with a light-tracing
    ``popt.render.integrator`` that integrator and, where ``modes`` has both,
    the path tracer's megakernel beside it."""
    from dataclasses import replace

    scene_path = Path(scene_path)
    check_input(scene_path, what="scene file")  # (missing, a folder, ...: one line)
    integrator = popt.render.integrator
    light = integrator in LIGHT_TRACERS
    if integrator != "path" and not light:
        raise DrptError(f"profile measures --integrator path, ptracer or bdpt, not --integrator {integrator}")
    if light and tuple(modes) == ("wavefront",):
        raise DrptError(f"--integrator {integrator} has no wavefront mode (one fused kernel per pass): "
                        "use --mode both or megakernel")
    scene = load_scene(scene_path)
    ensure()
    out = []
    if light:
        out.append(profile_light(scene, popt))
        # the path tracer beside it (same device scene, size, spp and seed)
        modes = ("megakernel",) if len(modes) > 1 else ()
        popt = replace(popt, render=replace(popt.render, integrator="path"))
    for m in modes:  # one device scene: the other renderers are derived from the first
        out.append(profile_mode(scene, popt, m, out[0].renderer if out else None))
    for r in out:
        r.passes = len(plan_passes(popt.width, popt.height, popt.spp, popt.max_lanes))
    if len(out) > 1:
        # the modes against each other, interleaved (the machine may be shared): best of
        # ``repeat`` more renders each, with each mode's earlier timed runs

        for _ in range(max(1, popt.repeat)):
            for r in out:
                t, run_entries = _time_once(r.renderer)
                if t < r.seconds:
                    r.seconds, r.entries = t, run_entries
    for r in out:
        del r.renderer
        rays = r.occupancy.get("closest_hit_rays", 0) + r.occupancy.get("shadow_rays", 0)
        if r.mode == "megakernel":
            r.stages = _megakernel_stages(r.entries, rays)
        elif r.mode in LIGHT_TRACERS:
            r.stages = _megakernel_stages(r.entries, rays, LIGHT_FUSED[r.mode])
    return out


def verdict(results: list[ModeResult]) -> list[str]:
    """Which mode wins on this scene and why, from the measured numbers."""
    by = {r.mode: r for r in results}
    lines = []
    lt = next((r for r in results if r.mode in LIGHT_TRACERS), None)
    if lt is not None:
        return _light_verdict(lt, by.get("megakernel"))
    wf = by.get("wavefront")
    if wf is not None and wf.unsorted_seconds:
        st = {s.name: s for s in wf.stages}
        un = {s.name: s for s in wf.unsorted_stages}
        ch, chu = st.get("closest hit"), un.get("closest hit")
        sh, shu = st.get("shadow rays"), un.get("shadow rays")
        srt = st.get("compact + sort")
        parts = [f"coherence sort: wavefront {wf.seconds:.3f} s sorted vs {wf.unsorted_seconds:.3f} s "
                 f"unsorted ({wf.unsorted_seconds / max(wf.seconds, 1e-12):.2f}x)"]
        if ch and chu:
            parts.append(f"closest-hit kernels {ch.kernel_ms:.1f} vs {chu.kernel_ms:.1f} ms")
        if sh and shu:
            parts.append(f"shadow-ray kernels {sh.kernel_ms:.1f} vs {shu.kernel_ms:.1f} ms")
        if srt and un.get("compact + sort"):
            parts.append(f"compaction + sort {srt.kernel_ms:.1f} ms vs compaction alone "
                         f"{un['compact + sort'].kernel_ms:.1f} ms")
        lines.append("; ".join(parts))
    if wf is not None and wf.tail_ab:
        ab = wf.tail_ab
        lines.append(f"fused tail: --wavefront-tail {ab['render_tail']} {wf.seconds:.3f} s vs {ab['tail']} "
                     f"{ab['seconds']:.3f} s ({ab['seconds'] / max(wf.seconds, 1e-12):.2f}x)")
    mk = by.get("megakernel")
    if mk is None or wf is None:
        return lines
    faster, slower = (mk, wf) if mk.seconds <= wf.seconds else (wf, mk)
    lines.append(f"{faster.mode} wins: {slower.seconds / max(faster.seconds, 1e-12):.2f}x faster "
                 f"({mk.seconds:.3f} s megakernel, {wf.seconds:.3f} s wavefront, best of the timed runs)")
    occ = mk.occupancy.get("occupancy", 0.0)
    wf_outside = max(0.0, wf.seconds * 1e3 - wf.kernel_ms)
    mk_outside = max(0.0, mk.seconds * 1e3 - mk.kernel_ms)
    lines.append(f"  kernel time: megakernel {mk.kernel_ms:.1f} ms, wavefront {wf.kernel_ms:.1f} ms "
                 f"({wf.kernel_ms / max(mk.kernel_ms, 1e-12):.2f}x); outside kernels (launches, syncs, "
                 f"Python): {mk_outside:.1f} ms in {mk.launches} launches vs {wf_outside:.1f} ms in "
                 f"{wf.launches} launches")
    lines.append(f"  megakernel SIMD occupancy {100 * occ:.1f}% (W = {mk.occupancy.get('simd_width_assumed')}: "
                 f"{mk.occupancy.get('executed_lane_iterations', 0) - mk.occupancy.get('lane_iterations', 0)} "
                 f"idle lane-iterations of {mk.occupancy.get('executed_lane_iterations', 0)}); wavefront "
                 f"kernels run live paths only ({wf.occupancy.get('lane_bounces', 0)} lane-bounces, "
                 f"{100 * wf.occupancy.get('live_fraction', 0):.1f}% of full-width bounces) but keep the path "
                 f"state in memory: peak {_mem(wf.peak_bytes)} vs {_mem(mk.peak_bytes)}")
    gap = (wf.seconds - mk.seconds) * 1e3  # > 0: the megakernel wins
    gap_k, gap_o = wf.kernel_ms - mk.kernel_ms, wf_outside - mk_outside
    causes = {"kernel time": (gap_k, "the stages write and read the path state through memory, "
                              "a cost the fused kernel's registers avoid"),
              "time outside kernels": (gap_o, "every bounce traces each stage's Python code again and "
                                       "launches and synchronises its kernels, also for the long tail "
                                       "of bounces with few live paths")}
    if faster is mk:
        main_cause = max(causes, key=lambda k: causes[k][0])
        why = (f"of the {gap:.1f} ms gap, {gap_k:.1f} ms is kernel time and {gap_o:.1f} ms time outside "
               f"kernels; the larger, {main_cause}: {causes[main_cause][1]}; the wavefront's compaction "
               f"saves the {100 * (1 - occ):.0f}% idle SIMD lanes of the fused kernel, which is less")
    else:
        why = (f"its kernels skip the megakernel's idle SIMD lanes ({100 * (1 - occ):.0f}% of the fused "
               f"kernel's lane-iterations) and run each BSDF's code on its own lanes: kernel time "
               f"{-gap_k:.1f} ms less, against {gap_o:.1f} ms more outside kernels in {wf.launches} launches")
    lines.append(f"  why: {why}")
    ab = wf.tail_ab
    if ab and ab.get("seconds"):
        rel = ab["seconds"] / max(mk.seconds, 1e-12)
        lines.append(f"  with --wavefront-tail {ab['tail']} (the last paths in one fused loop) the wavefront "
                     f"takes {ab['seconds']:.3f} s, {rel:.2f}x the megakernel's time: "
                     + ("the best mode measured here" if rel < 1 and faster is mk else
                        "faster than without" if ab["seconds"] < wf.seconds else "no gain"))
    return lines


def _light_verdict(lt: ModeResult, mk: ModeResult | None) -> list[str]:
    """A light-tracing integrator against the path tracer's megakernel: speed and rays
    per sample (not error: see :data:`LIGHT_NOT_APPLICABLE`)."""
    if mk is None:
        return []
    per = {r.mode: (r.occupancy.get("closest_hit_rays", 0) / max(r.samples, 1),
                    r.occupancy.get("shadow_rays", 0) / max(r.samples, 1)) for r in (lt, mk)}
    rel = lt.samples_per_second / max(mk.samples_per_second, 1e-12)
    lines = [f"{lt.mode} vs path (megakernel): {rel:.2f}x the path tracer's samples/s "
             f"({lt.samples_per_second / 1e6:.3f} vs {mk.samples_per_second / 1e6:.3f} Msamples/s; "
             f"{lt.seconds:.3f} s vs {mk.seconds:.3f} s, best of the timed runs)"]
    lines.append(f"  rays per sample: {lt.mode} {per[lt.mode][0]:.2f} closest hit + {per[lt.mode][1]:.2f} "
                 f"shadow, path {per['megakernel'][0]:.2f} + {per['megakernel'][1]:.2f}; kernel time "
                 f"{lt.kernel_ms:.1f} vs {mk.kernel_ms:.1f} ms, peak {_mem(lt.peak_bytes)} vs {_mem(mk.peak_bytes)}")
    lines.append(f"  not measured for {lt.mode}: " + "; ".join(lt.not_applicable))
    return lines


# --------------------------------------------------------------------------- output

def _fmt_rate(rays: int, ms: float) -> str:
    return f"{rays / (ms * 1e3):8.2f}" if rays and ms > 0 else "       -"


def _mem(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n / 2**10:.1f} KiB"


def format_table(r: ModeResult) -> str:
    lines = []
    title = f"{r.mode}: {r.seconds:.3f} s wall, {r.samples_per_second / 1e6:.3f} Msamples/s, " \
            f"{r.launches} launches ({r.jit_kernels} JIT kernels), kernel time {r.kernel_ms:.1f} ms, " \
            f"peak memory {_mem(r.peak_bytes)}"
    lines.append(title)
    lines.append(f"  warm-up render {r.warmup_s:.2f} s (LLVM backend/compile {r.warmup_backend_ms:.0f} ms);"
                 f" timed run: codegen {r.codegen_ms:.1f} ms, backend {r.backend_ms:.1f} ms")
    occ = r.occupancy
    if r.mode in LIGHT_TRACERS:
        lines.append(f"  {r.mode}: one fused kernel per pass, split by kernel only; queries counted by an "
                     "instrumented render (not timed)")
        if occ:
            lines.append(f"  rays: {occ['closest_hit_rays']} closest hit, {occ['shadow_rays']} shadow, "
                         f"{occ['splats']} splats into the film")
            for kind, n in occ["rays_by_kind"].items():
                lines.append(f"    {kind:44s} {n:10d}")
            for kind, lp in occ["loops"].items():
                lines.append(f"  {kind.split(': ')[-1]} loop: SIMD occupancy {100 * lp['occupancy']:.1f}% "
                             f"(W = {occ['simd_width_assumed']} assumed), "
                             f"{lp['mean_iterations_per_lane']:.2f} iterations per lane on average, "
                             f"at most {lp['max_iterations_per_lane']}")
        for na in r.not_applicable:
            lines.append(f"  does not apply: {na}")
    elif r.mode == "wavefront":
        staged = f"{r.staged_seconds:.3f} s" if r.staged_seconds is not None else "-"
        lines.append(f"  stages from an instrumented wavefront run ({staged} wall, synchronised at "
                     "every stage boundary); exclusive times")
        if occ:
            live = occ.get("live_per_bounce", [])
            shown = ", ".join(str(x) for x in live[:8]) + (", ..." if len(live) > 8 else "")
            lines.append(f"  occupancy: kernels run live paths only (compacted); live paths per bounce "
                         f"(first pass) {shown}; {occ.get('lane_bounces', 0)} lane-bounces = "
                         f"{100 * occ.get('live_fraction', 0):.1f}% of what full-width bounces would run; "
                         f"rays: {occ.get('closest_hit_rays', 0)} closest hit, {occ.get('shadow_rays', 0)} shadow")
        if r.unsorted_seconds:
            lines.append(f"  without the coherence sort: {r.unsorted_seconds:.3f} s "
                         f"({r.unsorted_seconds / max(r.seconds, 1e-12):.2f}x the sorted render)")
        if r.tail_ab:
            lines.append(f"  with --wavefront-tail {r.tail_ab['tail']} instead of {r.tail_ab['render_tail']}: "
                         f"{r.tail_ab['seconds']:.3f} s ({r.tail_ab['seconds'] / max(r.seconds, 1e-12):.2f}x)")
    else:
        lines.append("  stages are fused into one kernel: split by kernel only; rays counted by an "
                     "instrumented render (closest hit + shadow)")
        if occ:
            lines.append(f"  occupancy: {100 * occ['occupancy']:.1f}% of the lane-iterations the SIMD packets "
                         f"ran were live (W = {occ['simd_width_assumed']} assumed, {occ['lanes']} lanes, "
                         f"{occ['mean_iterations_per_lane']:.1f} iterations per lane on average, "
                         f"at most {occ['max_iterations_per_lane']}); rays: {occ['closest_hit_rays']} "
                         f"closest hit, {occ['shadow_rays']} shadow")
        fused = next((s for s in r.stages if s.name == FUSED), None)
        passes = r.passes or 0
        if fused is not None and passes and fused.jit_kernels > passes:
            lines.append(f"  note: the path kernel ran {fused.jit_kernels} times for {passes} pass(es): "
                         "each of L.x, L.y, L.z and the NaN count is evaluated by its own "
                         "kernel, each recomputing the whole path loop")
    total_k = sum(s.kernel_ms for s in r.stages) or 1e-12
    total_w = sum(s.wall_ms for s in r.stages)
    hdr = f"  {'stage':44s} {'kernel ms':>10s} {'share':>6s} {'wall ms':>9s} {'launches':>8s} " \
          f"{'lanes':>11s} {'rays':>10s} {'Mrays/s':>8s}"
    lines.append(hdr)
    for s in sorted(r.stages, key=lambda s: -s.kernel_ms):
        wall = f"{s.wall_ms:9.1f}" if s.wall_ms else "        -"
        lines.append(f"  {s.name[:44]:44s} {s.kernel_ms:10.1f} {100 * s.kernel_ms / total_k:5.1f}% "
                     f"{wall} {s.launches:8d} {s.lanes:11d} {s.rays if s.rays else '-':>10} "
                     f"{_fmt_rate(s.rays, s.kernel_ms)}")
    wall = f"{total_w:9.1f}" if total_w else "        -"
    lines.append(f"  {'total':44s} {sum(s.kernel_ms for s in r.stages):10.1f} {100.0:5.1f}% {wall} "
                 f"{sum(s.launches for s in r.stages):8d}")
    return "\n".join(lines)


def save_chart(results: list[ModeResult], out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1, 2.4]})
    ax = axes[0]
    names = [r.mode for r in results]
    ax.bar(names, [r.seconds * 1e3 for r in results], color=["tab:blue", "tab:orange"][:len(results)],
           label="wall")
    ax.bar(names, [r.kernel_ms for r in results], width=0.4, color="k", alpha=0.5,
           label="sum of kernel times")
    for i, r in enumerate(results):
        ax.text(i, r.seconds * 1e3, f"{r.launches} launches\n{r.samples_per_second / 1e6:.2f} MS/s",
                ha="center", va="bottom", fontsize=8)
    ax.set_ylim(0, 1.25 * max(max(r.seconds * 1e3, r.kernel_ms) for r in results))
    ax.set_ylabel("ms")
    ax.set_title("render time per mode")
    ax.legend(fontsize=8)
    ax = axes[1]
    wf = next((r for r in results if r.mode == "wavefront" and r.stages), None)
    if wf is not None:
        st = sorted(wf.stages, key=lambda s: -s.kernel_ms)
        y = range(len(st))
        ax.barh([i - 0.2 for i in y], [s.kernel_ms for s in st], height=0.4, label="kernel time")
        ax.barh([i + 0.2 for i in y], [s.wall_ms for s in st], height=0.4, label="wall time")
        ax.set_yticks(list(y), [s.name for s in st], fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel("ms (instrumented wavefront run, exclusive)")
        ax.set_title("wavefront stages")
        ax.legend(fontsize=8)
    lt = next((r for r in results if r.mode in LIGHT_TRACERS and r.occupancy), None)
    if wf is None and lt is not None:
        kinds = lt.occupancy["rays_by_kind"]
        ax.barh(list(kinds), list(kinds.values()))
        ax.set_yticks(range(len(kinds)), list(kinds), fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel("queries (instrumented render)")
        ax.set_title(f"{lt.mode}: rays and splats by kind")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- command line

def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("profile", help="profile a render: megakernel vs wavefront, per stage",
                              description=__doc__.split("\n")[0], allow_abbrev=False)
    p.add_argument("scene", help="scene file")
    add_render_flags(p, omit=("mode",), size=(128, 128), spp=16, accel="auto", integrator="path")
    p.add_argument("--mode", choices=("both", *MODES), default="both",
                   help="the execution modes to profile (default both, with the verdict); with "
                        "--integrator ptracer or bdpt: both = it and the path megakernel, megakernel = it alone")
    p.add_argument("--wavefront-tail", dest="wavefront_tail", type=int, default=0, metavar="N",
                   help="the wavefront's fused tail, as render's (default 0); the A/B also "
                        f"times the other setting ({TAIL_AB} when this is 0)")
    p.add_argument("--repeat", type=int, default=1,
                   help="timed renders per mode after the warm-up; the fastest is reported")
    p.add_argument("--out", default=None,
                   help="chart to write (PNG; default profile_<scene stem>.png); "
                        "the numbers go beside it as .json")
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    options = options_from_args(args, mode="megakernel")  # profile_mode sets each mode
    if args.repeat <= 0:
        raise DrptError(f"--repeat must be positive, got {args.repeat}")
    scene = Path(args.scene)
    out = Path(args.out) if args.out else Path(f"profile_{scene.stem}.png")
    if out.suffix.lower() != ".png":
        raise DrptError(f"{out}: the chart is written as PNG (use a .png name)")
    if str(out.parent) not in ("", ".") and not out.parent.is_dir():
        raise DrptError(f"{out}: folder {out.parent} does not exist")
    popt = ProfileOptions(render=options, repeat=args.repeat)
    width, height = options.width, options.height
    modes = MODES if args.mode == "both" else (args.mode,)
    results = run_profile(scene, popt, modes)
    head = (f"{scene.name}: {width}x{height}, {options.spp} spp, {options.integrator}, "
            f"{options.bsdf}, accel {options.accel}")
    print(head)
    for r in results:
        print()
        print(format_table(r))
    found = verdict(results)
    if found:
        print()
        print("\n".join(found))
    save_chart(results, out, head)
    js = out.with_suffix(".json")
    data = {"scene": str(scene), "options": popt.as_dict(),
            "modes": {r.mode: r.as_dict() for r in results},
            "verdict": found,
            "notes": "times in ms unless named *_seconds; stage times are exclusive; wavefront "
                     "stages come from an instrumented run (see drpt/tools/profile.py)"}
    js.write_text(json.dumps(data, indent=1))
    print(f"{out} and {js} written")
    return 0


if __name__ == "__main__":  # pragma: no cover - convenience
    parser = argparse.ArgumentParser(prog="drpt")
    add_parser(parser.add_subparsers(dest="command", required=True))
    a = parser.parse_args(["profile", *sys.argv[1:]])
    try:
        sys.exit(a.func(a))
    except DrptError as e:
        print(f"drpt: error: {e}", file=sys.stderr)
        sys.exit(2)
