"""``python -m drpt bench [SCENE ...]``: ray and render throughput, drpt vs Mitsuba 3.

For each scene and each acceleration structure (``--accel auto,bvh,grid``)
drpt's numbers are measured, and in the same run Mitsuba 3's (on drpt's
backend: ``llvm_ad_rgb`` or ``cuda_ad_rgb``) on the exported scene, on the
*same* rays. ``--accel`` takes a comma-separated list of the accelerator
names every command uses (:func:`drpt.options.parse_accel`): a kind
(``auto``, ``inline``, ``bvh``, ``bvh2``, ``bvh4``, ``grid``, ``brute``) or a
BVH kind with its build rule, ``KIND-RULE``. ``auto`` is drpt's default choice
(:func:`drpt.accel.resolve_kind`: ``inline`` for tiny scenes, else ``bvh``); it
gets a row, labelled with its pick, only where that pick is not asked for
already. ``bvh`` builds with drpt's default rule (``auto``), ``bvh-sah`` with
binned SAH everywhere, ``bvh-morton``, ``bvh-ploc`` (bottom-up clustering),
``bvh-median`` (object median, the seed's ``SAH_NUM=0``) and ``bvh-threshold``
(the seed's rule, SAH only in nodes of at most ``2 * --sah-threshold``
primitives, default 2000), so the seed's table (grid vs BVH without SAH vs
BVH with SAH) is ``--accel grid,bvh-median,bvh-threshold,bvh-sah``. The other
render flags are ``render``'s (:func:`drpt.cli.args.add_render_flags`; ``--size``
default 256 256, ``--spp`` 16; ``--seed`` also seeds the random rays). Per
accelerator:

* build time (drpt: ``build_accel``; Mitsuba: ``mi.load_dict`` of the
  exported scene, which includes its BVH build) and drpt's accel memory;
* closest-hit Mrays/s on **primary** rays (camera rays through pixel centres
  of a ~``--rays``-pixel image with the aspect of ``--size``) and on
  **incoherent** rays (uniform random points inside the scene bounds, uniform
  random directions, ``tmax`` = inf);
* shadow-ray (``occluded`` / ``ray_test``) Mrays/s from the incoherent
  origins to a second set of random points, ``tmax`` = distance between them;
* path-tracing render seconds and samples/s at ``--size`` / ``--spp`` and
  equal ``--max-depth``.

Every kernel runs once before timing (compilation lands there), timers are
bracketed by ``dr.sync_thread()``, and each number is the best of
``--repeat`` (3) runs. Ratios are drpt / Mitsuba for throughputs (higher is
better for drpt) and Mitsuba / drpt for times (build, render seconds), so a
ratio above 1 always means drpt is faster.

Outputs in ``--out`` (default ``bench/``): ``bench.md`` (the printed table),
``bench.csv`` (one row per scene and accel) and ``bench.png`` (bar chart of
the ratios).
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path

import numpy as np

from .. import llvm_tuning
from ..accel import build_accel, resolve_kind
from ..backend import ensure, mitsuba_variant, set_mitsuba_variant
from ..cli.args import add_render_flags, options_from_args
from ..errors import DrptError
from ..export.mitsuba import to_mitsuba_dict
from ..options import BVH_KINDS, parse_accel, parse_accel_list
from ..render.camera import RayCamera
from ..render.renderer import Renderer
from ..scene import load_scene
from ..scene.files import check_input
from .table import markdown_table

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_SCENES = [ROOT / "scenes" / "cornellbox" / "cornellbox.txt",
                  ROOT / "scenes" / "newscene" / "newscene.txt"]
# How MTL materials are read in the bundled scenes bench's numbers come from, without
# --bsdf (the seed's readings, as docs/performance.md measured them); other scenes: auto,
# every command's default.
DEFAULT_BSDF = {"cornellbox.txt": "phong", "newscene.txt": "cook-torrance"}
FIELDS = ["scene", "accel", "rays", "build_s", "accel_mib", "primary_mrays",
          "incoherent_mrays", "shadow_mrays", "render_s", "msamples_s",
          "mi_load_s", "mi_primary_mrays", "mi_incoherent_mrays", "mi_shadow_mrays",
          "mi_render_s", "mi_msamples_s",
          "ratio_build", "ratio_primary", "ratio_incoherent", "ratio_shadow", "ratio_render"]
RATIOS = [("ratio_build", "build / load"), ("ratio_primary", "primary hit"),
          ("ratio_incoherent", "incoherent hit"), ("ratio_shadow", "shadow"),
          ("ratio_render", "render")]


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``bench`` subcommand on an ``add_subparsers()`` object."""
    p = subparsers.add_parser(
        "bench", allow_abbrev=False,
        help="ray and render throughput of drpt vs Mitsuba 3",
        description="benchmark drpt's accelerators and path tracer against Mitsuba 3 "
                    "on the same rays and scenes, in one run")
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help="scene files (default: the bundled Cornell box and newscene)")
    p.add_argument("--accel", default="auto,bvh,grid",
                   help="comma-separated accelerators: auto (drpt's default: inline for "
                        "scenes of at most 64 primitives, else embree where Embree 3 is "
                        "installed, else bvh; a row only where it differs from the other "
                        "accelerators asked for), inline (primitives compiled into the "
                        "kernel), embree (Embree 3's BVH), bvh (drpt's 4-wide BVH, default "
                        "build rule: SAH, or PLOC above 100k primitives), bvh-sah (full "
                        "binned SAH), bvh-median, bvh-threshold (the seed's rule), bvh-morton "
                        "(fast build), bvh-ploc (bottom-up clustering), bvh2 (binary BVH, "
                        "default build rule; bvh2-RULE with a rule), grid, brute "
                        "(default auto,bvh,grid)")
    p.add_argument("--sah-threshold", type=int, default=2000, metavar="K",
                   help="K of bvh-threshold: SAH in nodes of at most 2K primitives "
                        "(default 2000, the seed's)")
    p.add_argument("--min-leaf", type=int, default=1, metavar="N",
                   help="minimum primitives per leaf of the BVH variants (default 1)")
    add_render_flags(p, omit=("accel", "hide_emitters"), size=(256, 256), spp=16)
    p.add_argument("--rays", type=int, default=1 << 20,
                   help="rays per ray benchmark (default 1048576)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per number, best kept "
                                                          "(default 3)")
    p.add_argument("--out", default="bench", help="output folder (default bench/)")
    p.add_argument("--no-mitsuba", action="store_true", help="drpt numbers only")
    p.set_defaults(func=main)
    return p


# --------------------------------------------------------------------------- timing

def _best(fn, repeat: int) -> float:
    """Best wall time of ``fn()`` (its results evaluated) after one warm-up call."""
    import drjit as dr

    dr.eval(fn())
    dr.sync_thread()
    best = math.inf
    for _ in range(repeat):
        dr.sync_thread()
        t0 = time.perf_counter()
        dr.eval(fn())
        dr.sync_thread()
        best = min(best, time.perf_counter() - t0)
    return max(best, 1e-9)


# --------------------------------------------------------------------------- rays

def make_rays(scene, n: int, aspect: float, seed: int) -> dict[str, np.ndarray]:
    """Primary, incoherent and shadow rays as float32 numpy arrays of shape (3, N)."""
    import drjit as dr
    from drjit.auto import Float, UInt32

    h = max(1, round(math.sqrt(n / aspect)))
    w = max(1, round(n / h))
    idx = dr.arange(UInt32, w * h)
    x = Float(idx % w) + 0.5
    y = Float(idx // w) + 0.5
    o, d = RayCamera(scene.camera, w, h).ray(x, y)
    prim_o = np.array([o.x.numpy(), o.y.numpy(), o.z.numpy()], np.float32).reshape(3, -1)
    prim_d = np.array([d.x.numpy(), d.y.numpy(), d.z.numpy()], np.float32)
    prim_o = np.broadcast_to(prim_o, prim_d.shape).copy()

    lo, hi = scene.bounds()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        lo, hi = np.full(3, -1.0), np.full(3, 1.0)  # only planes: a unit box
    rng = np.random.default_rng(seed)
    p = lo[:, None] + (hi - lo)[:, None] * rng.random((3, n))
    q = lo[:, None] + (hi - lo)[:, None] * rng.random((3, n))
    v = rng.normal(size=(3, n))
    v /= np.linalg.norm(v, axis=0, keepdims=True)
    s = q - p
    dist = np.linalg.norm(s, axis=0)
    dist = np.maximum(dist, 1e-6)
    return {"primary_o": prim_o, "primary_d": prim_d,
            "inc_o": p.astype(np.float32), "inc_d": v.astype(np.float32),
            "shadow_d": (s / dist).astype(np.float32),
            "shadow_t": (dist * (1 - 1e-4)).astype(np.float32)}


# --------------------------------------------------------------------------- drpt

def accel_options(base, name: str, sah_threshold: int = 2000, min_leaf: int = 1):
    """``base`` (a :class:`~drpt.options.RenderOptions`) with the accelerator
    ``name`` (:func:`drpt.options.parse_accel`), validated; ``sah_threshold``
    is the K of the threshold rule, ``min_leaf`` the BVH's minimum leaf."""
    from dataclasses import replace

    kind, method = parse_accel(name)
    if kind not in BVH_KINDS:
        return replace(base, accel=kind).validate()
    method = method or "auto"
    return replace(base, accel=kind, bvh_method=method, bvh_min_leaf=min_leaf,
                   sah_threshold=sah_threshold if method == "threshold" else None).validate()


def device_rays(rays: dict) -> tuple:
    """:func:`make_rays`'s rays as opaque, evaluated Dr.Jit arrays: primary
    origins and directions, incoherent origins and directions, shadow
    directions (from the incoherent origins) and shadow ``tmax``."""
    import drjit as dr
    from drjit.auto import Array3f, Float

    def a3(a):
        v = Array3f(*(Float(c) for c in a))
        dr.make_opaque(v)
        return v

    po, pd = a3(rays["primary_o"]), a3(rays["primary_d"])
    io, idr, sd = a3(rays["inc_o"]), a3(rays["inc_d"]), a3(rays["shadow_d"])
    st = Float(rays["shadow_t"])
    dr.make_opaque(st)
    dr.eval(po, pd, io, idr, sd, st)
    return po, pd, io, idr, sd, st


def bench_drpt(scene, options, rays: dict, repeat: int) -> dict:
    """drpt's numbers for ``options`` (accelerator, render size, spp, depth, bsdf)."""
    from drjit.auto import Float

    build_kw = ({"method": options.bvh_method, "min_leaf": options.bvh_min_leaf,
                 "sah_threshold": options.sah_threshold}
                if options.accel in ("bvh", "bvh2", "bvh4") else {})
    build = math.inf
    for _ in range(repeat):
        accel = None  # free the previous build first (the grid can be large)
        accel = build_accel(scene, kind=options.accel, **build_kw)
        build = min(build, accel.build_seconds)
    po, pd, io, idr, sd, st = device_rays(rays)
    inf = Float(math.inf)

    def hit(o, d):
        h = accel.intersect(o, d, inf)
        return h.t, h.prim

    n_prim, n_inc = pd.shape[1], idr.shape[1]
    t_prim = _best(lambda: hit(po, pd), repeat)
    t_inc = _best(lambda: hit(io, idr), repeat)
    t_shadow = _best(lambda: accel.occluded(io, sd, st), repeat)

    W, H, spp = options.width, options.height, options.spp
    r = Renderer(scene, options)
    r.render()  # warm-up: compilation
    render_s = min(r.render().seconds for _ in range(repeat))
    return {"rays": n_inc, "build_s": build, "accel_mib": accel.nbytes / 2**20,
            "primary_mrays": n_prim / t_prim / 1e6, "incoherent_mrays": n_inc / t_inc / 1e6,
            "shadow_mrays": n_inc / t_shadow / 1e6,
            "render_s": render_s, "msamples_s": W * H * spp / render_s / 1e6}


# --------------------------------------------------------------------------- Mitsuba

def mitsuba_rays(rays: dict) -> tuple:
    """:func:`make_rays`'s primary, incoherent and shadow rays as Mitsuba
    ``Ray3f`` (Mitsuba's variant must be set), evaluated."""
    import drjit as dr
    import mitsuba as mi

    def ray(o, d, t=None):
        r = mi.Ray3f(mi.Point3f(*(mi.Float(c) for c in o)),
                     mi.Vector3f(*(mi.Float(c) for c in d)))
        if t is not None:
            r.maxt = mi.Float(t)
        dr.make_opaque(r)
        return r

    return (ray(rays["primary_o"], rays["primary_d"]), ray(rays["inc_o"], rays["inc_d"]),
            ray(rays["inc_o"], rays["shadow_d"], rays["shadow_t"]))


def mitsuba_render_seconds(ms, spp: int, repeat: int) -> float:
    """Best wall time of Mitsuba rendering scene ``ms`` at ``spp`` with seeds
    ``1..repeat``, after one untimed render (compilation)."""
    import drjit as dr
    import mitsuba as mi

    dr.eval(mi.render(ms, spp=spp))  # warm-up
    dr.sync_thread()
    best = math.inf
    for seed in range(1, repeat + 1):
        t0 = time.perf_counter()
        dr.eval(mi.render(ms, spp=spp, seed=seed))
        dr.sync_thread()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_mitsuba(scene, rays: dict, bsdf: str, size, spp: int, max_depth: int,
                  repeat: int, rfilter: str = "box") -> dict:
    """Mitsuba's numbers, its kernels compiled for Dr.Jit's own LLVM target
    (Mitsuba as it ships, not drpt's tuning of it: :mod:`drpt.llvm_tuning`)."""
    with llvm_tuning.dr_default():
        return _bench_mitsuba(scene, rays, bsdf, size, spp, max_depth, repeat, rfilter)


def _bench_mitsuba(scene, rays: dict, bsdf: str, size, spp: int, max_depth: int,
                   repeat: int, rfilter: str) -> dict:
    import drjit as dr
    import mitsuba as mi

    set_mitsuba_variant()

    W, H = size
    load = math.inf
    for _ in range(repeat):
        desc = to_mitsuba_dict(scene, W, H, spp, max_depth=max_depth, bsdf=bsdf, rfilter=rfilter)
        dr.sync_thread()
        t0 = time.perf_counter()
        ms = mi.load_dict(desc)
        dr.sync_thread()
        load = min(load, time.perf_counter() - t0)

    rp, ri, rs = mitsuba_rays(rays)

    def hit(r):
        pi = ms.ray_intersect_preliminary(r)
        return pi.t, pi.prim_index

    n_prim, n_inc = rays["primary_d"].shape[1], rays["inc_d"].shape[1]
    t_prim = _best(lambda: hit(rp), repeat)
    t_inc = _best(lambda: hit(ri), repeat)
    t_shadow = _best(lambda: ms.ray_test(rs), repeat)

    render_s = mitsuba_render_seconds(ms, spp, repeat)
    return {"mi_load_s": load, "mi_primary_mrays": n_prim / t_prim / 1e6,
            "mi_incoherent_mrays": n_inc / t_inc / 1e6, "mi_shadow_mrays": n_inc / t_shadow / 1e6,
            "mi_render_s": render_s, "mi_msamples_s": W * H * spp / render_s / 1e6}


def _ratios(row: dict) -> None:
    row["ratio_build"] = row["mi_load_s"] / row["build_s"]
    row["ratio_primary"] = row["primary_mrays"] / row["mi_primary_mrays"]
    row["ratio_incoherent"] = row["incoherent_mrays"] / row["mi_incoherent_mrays"]
    row["ratio_shadow"] = row["shadow_mrays"] / row["mi_shadow_mrays"]
    row["ratio_render"] = row["msamples_s"] / row["mi_msamples_s"]


# --------------------------------------------------------------------------- output

def _fmt(v) -> str:
    if v is None or v == "":
        return "-"
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 100 else f"{v:.0f}"
    return str(v)


def format_table(rows: list[dict], mitsuba: bool) -> str:
    cols = [("scene", "scene"), ("accel", "accel"), ("build_s", "build s"),
            ("accel_mib", "accel MiB"), ("primary_mrays", "primary Mrays/s"),
            ("incoherent_mrays", "incoherent Mrays/s"), ("shadow_mrays", "shadow Mrays/s"),
            ("render_s", "render s"), ("msamples_s", "Msamples/s")]
    lines = [markdown_table([t for _, t in cols], ([_fmt(r.get(k)) for k, _ in cols] for r in rows),
                            padded_rule=False)]
    if mitsuba:
        mcols = [("scene", "scene"), ("mi_load_s", "load s"),
                 ("mi_primary_mrays", "primary Mrays/s"),
                 ("mi_incoherent_mrays", "incoherent Mrays/s"),
                 ("mi_shadow_mrays", "shadow Mrays/s"), ("mi_render_s", "render s"),
                 ("mi_msamples_s", "Msamples/s")]
        first = []  # each scene's first row: Mitsuba's numbers do not depend on the accel
        for r in rows:
            if all(f["scene"] != r["scene"] for f in first):
                first.append(r)
        lines += ["", f"Mitsuba 3 ({mitsuba_variant()}), same rays and render settings:", "",
                  markdown_table([t for _, t in mcols],
                                 ([_fmt(r.get(k)) for k, _ in mcols] for r in first),
                                 padded_rule=False)]
        rcols = [("scene", "scene"), ("accel", "accel")] + list(RATIOS)
        lines += ["", "drpt / Mitsuba (> 1: drpt faster; build compares Mitsuba's whole "
                      "scene load):", "",
                  markdown_table([t for _, t in rcols],
                                 ([f"{r[k]:.2f}x" if k.startswith("ratio") else str(r[k])
                                   for k, _ in rcols] for r in rows),
                                 padded_rule=False)]
    return "\n".join(lines)


def write_chart(rows: list[dict], path: Path, mitsuba: bool) -> None:
    """bench.png: :func:`chart` saved."""
    import matplotlib.pyplot as plt

    fig = chart(rows, mitsuba)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def chart(rows: list[dict], mitsuba: bool):
    """The bar chart of ``rows`` (ratios to Mitsuba, or drpt's rates without it) on a
    log axis: the build ratio runs to hundreds where the others sit near 1, and on a
    linear axis it flattened every other bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.5))
    keys = RATIOS if mitsuba else [("primary_mrays", "primary"),
                                   ("incoherent_mrays", "incoherent"),
                                   ("shadow_mrays", "shadow"), ("msamples_s", "render Msamples/s")]
    width = 0.8 / max(len(rows), 1)
    x = np.arange(len(keys))
    for i, r in enumerate(rows):
        ax.bar(x + (i - (len(rows) - 1) / 2) * width, [r[k] for k, _ in keys], width,
               label=f"{r['scene']} / {r['accel']}")
    ax.set_xticks(x, [label for _, label in keys])
    if mitsuba:
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_ylabel("drpt / Mitsuba 3 (> 1: drpt faster)")
    else:
        ax.set_ylabel("Mrays/s, Msamples/s")
    ax.set_yscale("log")
    ax.set_title("drpt bench")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- command

def main(args: argparse.Namespace) -> int:
    """Run ``bench`` for parsed ``args``; user errors raise DrptError."""
    from dataclasses import replace

    # --accel, --sah-threshold and --min-leaf are bench's own (a list, and per-row values)
    shared = argparse.Namespace(**{k: v for k, v in vars(args).items()
                                   if k not in ("accel", "sah_threshold", "min_leaf")})
    base = replace(options_from_args(shared), progress=False)
    accels = parse_accel_list(args.accel)
    # every row's options, and K and the minimum leaf even where no row uses them
    accel_options(base, "bvh-threshold", args.sah_threshold, args.min_leaf)
    row_options = {a: accel_options(base, a, args.sah_threshold, args.min_leaf) for a in accels}
    W, H = base.width, base.height
    for name, v in (("--rays", args.rays), ("--repeat", args.repeat)):
        if v <= 0:
            raise DrptError(f"{name} must be positive, got {v}")
    paths = [Path(s) for s in args.scenes] or DEFAULT_SCENES
    for p in paths:
        check_input(p, what="scene file")  # (missing, a folder, ...: one line)
    out = Path(args.out)
    ensure()
    mitsuba = not args.no_mitsuba
    if mitsuba:
        try:
            import mitsuba as mi  # noqa: F401
        except ImportError as e:
            raise DrptError(f"Mitsuba 3 is not installed ({e}); use --no-mitsuba") from e

    rows = []
    for path in paths:
        scene = load_scene(path)
        bsdf = args.bsdf or DEFAULT_BSDF.get(path.name, "auto")
        rays = make_rays(scene, args.rays, W / H, args.seed)
        mi_row = (bench_mitsuba(scene, rays, bsdf, (W, H), base.spp, base.path.max_depth,
                                args.repeat, base.filter) if mitsuba else {})
        for name in accels:
            label = name
            if name == "auto":
                picked = resolve_kind(scene, "auto")
                if picked in accels:
                    continue  # its row is already there
                label = f"auto ({picked})"
            row = {"scene": path.stem, "accel": label}
            row.update(bench_drpt(scene, replace(row_options[name], bsdf=bsdf), rays,
                                  args.repeat))
            row.update(mi_row)
            if mitsuba:
                _ratios(row)
            rows.append(row)

    out.mkdir(parents=True, exist_ok=True)
    table = format_table(rows, mitsuba)
    settings = (f"{W}x{H}, {base.spp} spp, max depth {base.path.max_depth}, {args.rays} rays, "
                f"best of {args.repeat}")
    if "bvh-threshold" in accels:
        settings += f", bvh-threshold K = {args.sah_threshold}"
    if args.min_leaf != 1 and any(a.startswith("bvh") for a in accels):
        settings += f", BVH min leaf {args.min_leaf}"
    (out / "bench.md").write_text(f"# drpt bench\n\n{settings}\n\n{table}\n")
    with open(out / "bench.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in FIELDS})
    write_chart(rows, out / "bench.png", mitsuba)
    print(settings)
    print(table)
    print(f"{out}: bench.md, bench.csv, bench.png")
    return 0
