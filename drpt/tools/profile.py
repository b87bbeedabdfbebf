"""``python -m drpt profile SCENE``: where a render spends its time, in two execution modes.

The same render (same options, same seed, same image) is run twice:

* **megakernel** (``dr.JitFlag.SymbolicLoops = True``, drpt's default): the
  whole path loop, with the BVH traversal loops inside it, is traced once and
  compiled into one fused kernel per pass;
* **wavefront** (``SymbolicLoops = False``): Dr.Jit runs every loop in
  *evaluated* mode, iteration by iteration from Python, launching kernels for
  each iteration of each loop (path bounces and BVH traversal steps alike),
  with the loop state written to memory in between.

Each mode first renders once as a warm-up, so compilation (LLVM backend time)
lands there and is reported apart; the timed render then runs with
``dr.JitFlag.KernelHistory`` on and every entry of ``dr.kernel_history()`` is
kept (``execution_time``, ``codegen_time``, ``backend_time``, ``size``,
``operation_count``, ``type``, ``cache_hit``, ...). Peak memory comes from
``dr.detail.malloc_watermark`` on drpt's backend.

Stages
------
Dr.Jit 1.5 records no label in the kernel history (``dr.set_label`` names
variables for GraphViz only and does not reach the IR; ``dr.profile_range``
marks the CPU timeline for external profilers), so kernels cannot be assigned
to stages from the history alone. The stage split therefore comes from a
third, *instrumented* wavefront render: the device scene's queries
(closest hit, interaction, shadow rays, emission, BSDF and emitter sampling
and evaluation: :data:`SCENE_STAGES`) and the direct-light estimators are
replaced, on those instances, by wrappers that evaluate each stage's inputs
on entry and its outputs on exit, so each kernel is launched by exactly one
stage; kernels are then
attributed to the innermost stage running when they were launched (exclusive
times: a shadow ray inside next-event estimation counts as "shadow rays", not
twice). ``LaunchBlocking`` is on in that run so wall-clock time also lands on
the stage that launched the work. The extra evaluations make this run a bit
slower than the plain wavefront run; both are reported. Rays per stage are
the active lanes entering the closest-hit and shadow-ray queries (counted with
``dr.count`` under an "instrumentation" entry that is excluded from the stage
sums). In megakernel mode the history can only be split by kernel: the fused
path kernel and the small reduction / copy kernels around it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..errors import DrptError
from ..options import RenderOptions

INSTRUMENTATION = "instrumentation (ray counts, history reads)"
TOP = "accumulation + readback"


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
    staged_seconds: float | None = None  # wall time of the instrumented run (wavefront)

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
            "passes": getattr(self, "passes", None),
            "stages": [s.as_dict() for s in self.stages],
            "kernels": self.entries,
        }


# --------------------------------------------------------------------------- stage tracking

def _jit_leaves(obj, out: list, depth: int = 0) -> list:
    """Dr.Jit arrays reachable from ``obj`` (tuples, lists, dicts, plain objects)."""
    import drjit as dr

    if depth > 4 or obj is None or isinstance(obj, (bool, int, float, str)):
        return out
    if isinstance(obj, dr.ArrayBase) or hasattr(type(obj), "DRJIT_STRUCT"):
        out.append(obj)
    elif isinstance(obj, (tuple, list)):
        for x in obj:
            _jit_leaves(x, out, depth + 1)
    elif isinstance(obj, dict):
        for x in obj.values():
            _jit_leaves(x, out, depth + 1)
    elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("drpt."):
        for x in vars(obj).values():
            _jit_leaves(x, out, depth + 1)
    elif type(obj).__name__ == "PCG32":
        out.extend([obj.state, obj.inc])
    return out


def _eval(*objs) -> None:
    import drjit as dr

    leaves = _jit_leaves(objs, [])
    if leaves:
        dr.eval(*leaves)


class StageTracker:
    """Attributes kernel launches and wall time to the innermost running stage."""

    def __init__(self):
        self.stages: dict[str, Stage] = {}
        self.stack = [TOP]
        self.t = time.perf_counter()

    def stage(self, name: str) -> Stage:
        if name not in self.stages:
            self.stages[name] = Stage(name)
        return self.stages[name]

    def flush(self) -> None:
        import drjit as dr

        dr.sync_thread()
        now = time.perf_counter()
        st = self.stage(self.stack[-1])
        st.wall_ms += (now - self.t) * 1e3
        st.add(_history())
        self.t = time.perf_counter()
        self.stage(INSTRUMENTATION).wall_ms += (self.t - now) * 1e3

    def enter(self, name: str, args=()) -> None:
        _eval(args)  # the inputs belong to the caller's stage
        self.flush()
        self.stack.append(name)

    def leave(self, result) -> None:
        _eval(result)
        self.flush()
        self.stack.pop()

    def count_rays(self, name: str, active, n_fallback: int) -> None:
        import drjit as dr
        from drjit.auto import Bool

        _eval(active)  # pending work of the caller stays with the caller
        self.enter(INSTRUMENTATION)
        if isinstance(active, Bool):
            n = int(dr.count(active)[0]) if dr.width(active) > 1 else int(bool(active[0])) * n_fallback
        else:
            n = n_fallback if active else 0
        self.stage(name).rays += n
        self.leave(None)


#: The device scene's queries the staged run times (drpt.render.scene.DeviceScene):
#: method -> (stage, index of its ``active`` argument where it traces rays, else None).
SCENE_STAGES = {
    "intersect_preliminary": ("closest-hit traversal", 2),
    "occluded": ("shadow rays", 3),
    "interaction": ("surface interaction", None),
    "emitted": ("emission + MIS", None),
    "pdf_area_emitter": ("emission + MIS", None),
    "sample_bsdf": ("BSDF sampling", None),
    "eval_bsdf": ("BSDF evaluation (NEE)", None),
    "sample_area_emitter": ("light sampling", None),
    "sample_environment": ("env lookups", None),
    "eval_environment": ("env lookups", None),
    "eval_pdf_environment": ("env lookups", None),
}
#: The direct-light estimators (drpt.render.integrators.common.DirectLight): what
#: they do besides the scene queries above.
DIRECT_STAGES = {"area": "NEE: area lights (rest)", "delta": "NEE: delta lights (rest)",
                 "env_light": "NEE: environment (rest)"}


def _staged(method, tracker: StageTracker, stage: str, ray_arg: int | None):
    """``method`` run as ``stage``: inputs evaluated on entry, outputs on exit,
    and the active lanes of argument ``ray_arg`` counted as rays."""

    def wrapped(*args, **kwargs):
        if ray_arg is not None:
            import drjit as dr

            active = args[ray_arg] if len(args) > ray_arg else kwargs.get("active", True)
            tracker.count_rays(stage, active, max(dr.width(args[0]), dr.width(args[1])))
        tracker.enter(stage, (args, kwargs))
        result = method(*args, **kwargs)
        tracker.leave(result)
        return result

    return wrapped


def _hook(obj, tracker: StageTracker, stages: dict[str, tuple[str, int | None]]) -> None:
    """Replace ``obj``'s methods named in ``stages`` by staged ones (instance
    attributes: the class, and every other instance, stay untouched)."""
    for name, (stage, ray_arg) in stages.items():
        setattr(obj, name, _staged(getattr(obj, name), tracker, stage, ray_arg))


def _instrument(renderer, tracker: StageTracker) -> None:
    """Time the device scene's queries, the direct-light estimators and the
    integrator's entry points as stages."""
    _hook(renderer.scene, tracker, SCENE_STAGES)
    integ = renderer.integrator
    _hook(integ.direct, tracker, {k: (v, None) for k, v in DIRECT_STAGES.items()})

    sample = integ.sample

    def staged_sample(rng, o, d, active, *rest):
        import drjit as dr

        tracker.enter("camera rays + RNG setup")
        tracker.stage("camera rays + RNG setup").rays += max(dr.width(o), dr.width(d))
        tracker.leave((rng, o, d, active))
        tracker.enter("integrator loop (throughput, RR, state)")
        L = sample(rng, o, d, active, *rest)
        tracker.leave(L)
        return L

    integ.sample = staged_sample

    sequence = getattr(integ, "sample_sequence", None)
    if sequence is None:
        return
    camera = "camera rays + RNG setup"

    def staged_sequence(rng, camera_ray, count, **kwargs):
        # The first camera rays are made before the loop and timed as their
        # stage; the next paths' are made inside a symbolic conditional (path
        # regeneration), where nothing can be evaluated, so their time stays
        # in the loop's stage. The ray count is exact: one per sample.
        import drjit as dr

        first = [True]

        def staged_camera(rng):
            if not first[0]:
                return camera_ray(rng)
            first[0] = False
            tracker.enter(camera, (rng,))
            ray = camera_ray(rng)  # (o, d) or (o, d, filter weight or None)
            tracker.leave((rng, *(v for v in ray if v is not None)))
            return ray

        tracker.enter(INSTRUMENTATION, (count,))
        tracker.stage(camera).rays += int(dr.sum(count)[0])
        tracker.leave(None)
        tracker.enter("integrator loop (throughput, RR, state)")
        out = sequence(rng, staged_camera, count, **kwargs)
        tracker.leave(out)
        return out

    integ.sample_sequence = staged_sequence


# --------------------------------------------------------------------------- running

@dataclass
class ProfileOptions:
    """What ``profile`` renders (``render``, a :class:`~drpt.options.RenderOptions`;
    its progress bar is off) and how many timed renders per mode (``repeat``)."""

    render: RenderOptions = field(default_factory=lambda: RenderOptions(width=128, height=128))
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
        return self.render.max_lanes

    def as_dict(self) -> dict:
        return {**asdict(self.render), "repeat": self.repeat}


def _renderer(scene, popt: ProfileOptions):
    from dataclasses import replace

    from ..render.renderer import Renderer

    return Renderer(scene, replace(popt.render, progress=False))


FUSED = "fused megakernel (camera + whole path loop)"


def _megakernel_stages(entries: list[dict], rays: int) -> list[Stage]:
    """Megakernel history split by kernel (stages are fused and cannot be separated).

    The path kernels are the JIT kernels with at least half the operation
    count of the largest one; the rest are accumulation kernels.
    """
    jit = [e for e in entries if e["type"] == "JIT"]
    big = max((e["operation_count"] for e in jit), default=-1)
    groups: dict[str, list[dict]] = defaultdict(list)
    for e in entries:
        if e["type"] == "JIT" and e["operation_count"] * 2 >= big:
            groups[FUSED].append(e)
        elif e["type"] == "JIT":
            groups["other JIT kernels (accumulation)"].append(e)
        else:
            groups[f"{e['type']} (accumulation + readback)"].append(e)
    out = []
    for name, es in groups.items():
        st = Stage(name)
        st.add(es)
        if name.startswith("fused"):
            st.rays = rays
        out.append(st)
    return out


def profile_mode(scene, popt: ProfileOptions, symbolic: bool, staged: bool = False) -> ModeResult:
    import drjit as dr

    mode = "megakernel" if symbolic else "wavefront"
    # (dr.JitFlag.CompressLoops would drop finished lanes in wavefront mode, but Dr.Jit 1.5
    # emits invalid LLVM IR for the BVH traversal loop with it: not offered.)
    flags = [(dr.JitFlag.SymbolicLoops, symbolic)]
    samples = popt.width * popt.height * popt.spp
    with contextlib.ExitStack() as flag_stack:
        for flag, value in flags:
            flag_stack.enter_context(dr.scoped_set_flag(flag, value))
        renderer = _renderer(scene, popt)
        # Warm-up: compiles every kernel (or loads it from Dr.Jit's caches).
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            t0 = time.perf_counter()
            renderer.render()
            dr.sync_thread()
            warmup = time.perf_counter() - t0
            warm_backend = sum(e["backend_ms"] for e in _history())
        # Timed runs (the fastest is kept: the machine may be shared).
        seconds, entries = float("inf"), []
        dr.flush_malloc_cache()
        dr.detail.malloc_clear_statistics()
        for _ in range(max(1, popt.repeat)):
            with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
                dr.kernel_history_clear()
                t0 = time.perf_counter()
                renderer.render()
                dr.sync_thread()
                t = time.perf_counter() - t0
                run_entries = _history()
            if t < seconds:
                seconds, entries = t, run_entries
        from ..backend import jit_backend

        peak = int(dr.detail.malloc_watermark(jit_backend()))
        result = ModeResult(mode, warmup, warm_backend, seconds, samples, peak, entries)
        if symbolic:
            result.stages = _megakernel_stages(entries, samples)
        elif staged:
            renderer = _renderer(scene, popt)
            tracker = StageTracker()
            _instrument(renderer, tracker)
            with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True), \
                    dr.scoped_set_flag(dr.JitFlag.LaunchBlocking, True):
                renderer.render()  # warm-up of the instrumented kernels
                dr.sync_thread()
                dr.kernel_history_clear()
                tracker.stages.clear()
                t0 = tracker.t = time.perf_counter()
                renderer.render()
                tracker.flush()
                result.staged_seconds = time.perf_counter() - t0
            result.stages = [s for s in tracker.stages.values() if s.name != INSTRUMENTATION]
            inst = tracker.stages.get(INSTRUMENTATION)
            result.instrumentation = inst.as_dict() if inst else None
    return result


def run_profile(scene_path: str | Path, popt: ProfileOptions) -> list[ModeResult]:
    from ..backend import ensure
    from ..scene import load_scene

    scene_path = Path(scene_path)
    if not scene_path.is_file():
        raise DrptError(f"{scene_path}: scene file not found")
    scene = load_scene(scene_path)
    ensure()
    from ..render.renderer import plan_passes

    mk = profile_mode(scene, popt, True)
    wf = profile_mode(scene, popt, False, staged=True)
    mk.passes = wf.passes = len(plan_passes(popt.width, popt.height, popt.spp, popt.max_lanes))
    # Both modes trace the same rays (same seed, same image): the wavefront run counted
    # them, the fused kernel cannot. Credit the megakernel with those rays.
    traced = sum(s.rays for s in wf.stages if s.name in ("closest-hit traversal", "shadow rays"))
    for s in mk.stages:
        if s.name == FUSED and traced:
            s.rays = traced
    return [mk, wf]


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
    if r.mode == "wavefront":
        lines.append(f"  stages from an instrumented wavefront run ({r.staged_seconds:.3f} s wall, "
                     "LaunchBlocking, stage boundaries evaluated); exclusive times")
    else:
        lines.append("  stages are fused into one kernel: split by kernel only; its rays are "
                     "those the wavefront run counted (same rays)")
        fused = next((s for s in r.stages if s.name == FUSED), None)
        passes = getattr(r, "passes", 0)
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
    inst = getattr(r, "instrumentation", None)
    if inst:
        lines.append(f"  (not in the stages: {inst['wall_ms']:.1f} ms wall, {inst['launches']} launches "
                     "of profiler instrumentation: ray counting, history reads)")
    return "\n".join(lines)


def save_chart(results: list[ModeResult], out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1, 2.4]})
    ax = axes[0]
    names = [r.mode for r in results]
    ax.bar(names, [r.seconds * 1e3 for r in results], color=["tab:blue", "tab:orange"],
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
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- command line

def add_parser(subparsers) -> argparse.ArgumentParser:
    from ..options import add_render_flags

    p = subparsers.add_parser("profile", help="profile a render: megakernel vs wavefront, per stage",
                              description=__doc__.split("\n")[0], allow_abbrev=False)
    p.add_argument("scene", help="scene file")
    add_render_flags(p, size=(128, 128), spp=16, accel="auto", integrator="path",
                     bsdf="phong")
    p.add_argument("--repeat", type=int, default=1,
                   help="timed renders per mode after the warm-up; the fastest is reported")
    p.add_argument("--out", default=None,
                   help="chart to write (PNG; default profile_<scene stem>.png); "
                        "the numbers go beside it as .json")
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from ..options import options_from_args

    options = options_from_args(args)
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
    results = run_profile(scene, popt)
    head = (f"{scene.name}: {width}x{height}, {options.spp} spp, {options.integrator}, "
            f"{options.bsdf}, accel {options.accel}")
    print(head)
    for r in results:
        print()
        print(format_table(r))
    mk, wf = results
    faster = mk if mk.seconds <= wf.seconds else wf
    slower = wf if faster is mk else mk
    print(f"\n{faster.mode} is {slower.seconds / max(faster.seconds, 1e-12):.2f}x faster "
          f"({wf.launches} vs {mk.launches} launches)")
    save_chart(results, out, head)
    js = out.with_suffix(".json")
    data = {"scene": str(scene), "options": popt.as_dict(),
            "modes": {r.mode: r.as_dict() for r in results},
            "notes": "times in ms unless named *_seconds; stage times are exclusive; wavefront "
                     "stages come from an instrumented run (see drpt/profile.py)"}
    for r in results:
        inst = getattr(r, "instrumentation", None)
        if inst:
            data["modes"][r.mode]["instrumentation"] = inst
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
