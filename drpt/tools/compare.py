"""``python -m drpt compare``: drpt against Mitsuba 3, or one image against another.

Two forms::

    python -m drpt compare SCENE [--size W H] [--spp N] [--ref-spp M] [--bsdf MODE]
                                 [--max-depth D] [--rr-depth K] [--seed S]
                                 [--ref-batches B] [--cache DIR | --no-cache] [--out DIR]
    python -m drpt compare A.exr B.exr [--out DIR]

Scene form
    The scene is exported to Mitsuba 3 (:func:`drpt.export.mitsuba.to_mitsuba_dict`)
    and rendered by Mitsuba's ``path`` integrator (``llvm_ad_rgb``) at
    ``--ref-spp`` samples per pixel, split into ``--ref-batches`` independent
    renders (different seeds) whose spread gives the reference's per-pixel
    variance of the mean: ``var_ref = var_batches(ddof=1) / B``. The
    reference (mean, variance, time) is cached in
    ``<cache>/<scene stem>_<key>.npz`` (default ``$XDG_CACHE_HOME/drpt/references``,
    i.e. ``~/.cache/drpt/references``); the key is a SHA-256 of the exported
    Mitsuba scene (the XML and PLY files :func:`~drpt.export.mitsuba.write_xml`
    writes), the exporter's source, the scene file's contents, the size, mtime
    and path of every texture and sky image it uses, the Mitsuba version and
    every render setting (size, spp, batches, depths, bsdf mode, seed). Any
    change renders a new reference; otherwise it is reused. Then drpt renders
    the scene with the same settings (its own per-pixel variance comes with
    the render) and the two are compared.

Image form
    Two images (any format :func:`drpt.imageio.read_image` reads; alpha is
    dropped, a gray image is compared against each channel of an RGB one).
    ``B`` is the reference. Without variances there is no confidence
    interval: ``outside_ci`` is ``null`` in the JSON.

Output, in ``--out`` (default ``compare_<scene stem>/`` or
``compare_<A stem>_vs_<B stem>/``): ``metrics.json`` (metrics of
:func:`drpt.metrics.summary`, settings, times, cache use),
``side_by_side.png`` (render | reference | false-color relative error map
with a colorbar), and in the scene form ``drpt.exr`` and ``reference.exr``
(linear float32). A short table goes to stdout.

User mistakes (missing file, unknown extension, images of different sizes,
bad numbers) raise :class:`drpt.errors.DrptError`.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DrptError

CACHE_VERSION = 1
IMAGE_EXTENSIONS = (".exr", ".hdr", ".pfm", ".png", ".jpg", ".jpeg", ".tga")
CI_Z = 3.0  # the 99.7% interval
EXPECTED_OUTSIDE = 0.0027  # 2 (1 - Phi(3))

__all__ = ["Reference", "add_parser", "main", "add_reference_args", "cache_dir_from_args", "default_cache_dir", "reference_key", "compare_images",
           "compare_scene", "check_reference_args", "get_reference"]


# ------------------------------------------------------------------ parser
def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``compare`` subcommand on an ``add_subparsers()`` object."""
    p = subparsers.add_parser(
        "compare", allow_abbrev=False,
        help="compare drpt with a Mitsuba 3 reference, or two images",
        description="compare SCENE: render with drpt and Mitsuba 3 (cached) and compare; "
                    "compare A B: compare two images (B is the reference)")
    p.add_argument("inputs", nargs="+", metavar="SCENE | A B",
                   help="a scene file, or two images")
    p.add_argument("--size", nargs=2, type=int, metavar=("W", "H"), default=(128, 128),
                   help="image size (default 128 128)")
    p.add_argument("--spp", type=int, default=64, help="drpt samples per pixel (default 64)")
    add_reference_args(p, ref_spp=1024)
    p.add_argument("--bsdf", choices=["phong", "cook-torrance", "diffuse"], default="phong",
                   help="how MTL materials are read (as for render; default phong)")
    p.add_argument("--max-depth", type=int, default=-1,
                   help="longest path in segments, -1 unbounded (default)")
    p.add_argument("--rr-depth", type=int, default=5,
                   help="depth at which Russian roulette starts (default 5)")
    p.add_argument("--seed", type=int, default=0,
                   help="drpt seed (default 0); the reference uses seed + 100000")
    p.add_argument("--out", default=None, help="output folder (default compare_<name>/)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    """Run ``compare`` for parsed ``args``; user errors raise DrptError."""
    inputs = [Path(s) for s in args.inputs]
    if len(inputs) > 2:
        raise DrptError(f"compare takes a scene or two images, got {len(inputs)} arguments")
    if len(inputs) == 2:
        for p in inputs:
            if p.suffix.lower() not in IMAGE_EXTENSIONS:
                raise DrptError(f"{p}: not an image (extension {p.suffix or '(none)'!r}); "
                                f"compare A B takes two images of type "
                                f"{', '.join(IMAGE_EXTENSIONS)}")
        out = Path(args.out) if args.out else Path(f"compare_{inputs[0].stem}_vs_{inputs[1].stem}")
        report = compare_images(inputs[0], inputs[1], out)
    else:
        scene = inputs[0]
        if scene.suffix.lower() in IMAGE_EXTENSIONS:
            raise DrptError(f"{scene}: an image alone cannot be compared; give a scene file, "
                            "or two images (compare A B)")
        out = Path(args.out) if args.out else Path(f"compare_{scene.stem}")
        cache = cache_dir_from_args(args)
        report = compare_scene(scene, out, width=args.size[0], height=args.size[1],
                               spp=args.spp, ref_spp=args.ref_spp, ref_batches=args.ref_batches,
                               bsdf=args.bsdf, max_depth=args.max_depth,
                               rr_depth=args.rr_depth, seed=args.seed, cache_dir=cache,
                               progress=not args.quiet)
    print(format_table(report))
    print(f"{out}: metrics.json, side_by_side.png"
          + (", drpt.exr, reference.exr" if report["mode"] == "scene" else ""))
    return 0


def add_reference_args(p: argparse.ArgumentParser, ref_spp: int) -> None:
    """The options of every command that judges renders against the cached
    Mitsuba reference (compare, converge, knobs): its spp and batches, and
    the cache (read back with :func:`cache_dir_from_args`)."""
    p.add_argument("--ref-spp", type=int, default=ref_spp,
                   help=f"Mitsuba reference samples per pixel (default {ref_spp})")
    p.add_argument("--ref-batches", type=int, default=8,
                   help="independent Mitsuba renders the reference is split into, for its "
                        "variance (default 8)")
    p.add_argument("--cache", default=None,
                   help="reference cache folder (default ~/.cache/drpt/references)")
    p.add_argument("--no-cache", action="store_true",
                   help="render the reference even if it is cached (and do not store it)")


def cache_dir_from_args(args: argparse.Namespace) -> Path | None:
    """The reference cache folder the options name (None: do not cache)."""
    if args.no_cache:
        return None
    return Path(args.cache) if args.cache else default_cache_dir()


# ------------------------------------------------------------------ helpers
def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "drpt" / "references"


def _prepare_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise DrptError(f"{out}: exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DrptError(f"{out}: cannot create output folder: {e.strerror or e}") from e


def _rgb(img: np.ndarray, path: Path) -> np.ndarray:
    c = img.shape[2]
    if c == 4:
        return img[..., :3]
    if c in (1, 3):
        return img
    raise DrptError(f"{path}: cannot compare an image with {c} channels")


def _write_json(path: Path, data: dict) -> None:
    try:
        path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    except OSError as e:
        raise DrptError(f"{path}: cannot write: {e.strerror or e}") from e


def _tonemap(img: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """What a .png of the image shows: clamp to [0, 1], then ``x ** (1/gamma)``."""
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    return np.clip(img, 0.0, 1.0) ** (1.0 / gamma)


def write_side_by_side(path: Path, x: np.ndarray, ref: np.ndarray, emap: np.ndarray,
                       labels=("drpt", "reference")) -> None:
    """render | reference | relative error map (false color, with a colorbar)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    h, w = emap.shape
    panel = 3.2
    fig, axes = plt.subplots(1, 3, figsize=(3 * panel + 0.8, panel * h / w + 0.6),
                             constrained_layout=True)
    for ax, img, label in zip(axes[:2], (x, ref), labels):
        ax.imshow(_tonemap(img), interpolation="nearest")
        ax.set_title(label)
        ax.set_axis_off()
    vmax = float(np.percentile(emap, 99)) if emap.size else 1.0
    vmax = max(vmax, 1e-6)
    im = axes[2].imshow(emap, cmap="inferno", vmin=0.0, vmax=vmax, interpolation="nearest")
    axes[2].set_title("relative error")
    axes[2].set_axis_off()
    cb = fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04)
    cb.set_label("mean_c |x - ref| / (|ref| + 0.01)", fontsize=7)
    try:
        fig.savefig(path, dpi=100)
    except OSError as e:
        raise DrptError(f"{path}: cannot write: {e.strerror or e}") from e
    finally:
        plt.close(fig)


def format_table(report: dict) -> str:
    m = report["metrics"]
    rows = [("relMSE", f"{m['rel_mse']:.4e}"), ("MAE", f"{m['mae']:.4e}"),
            ("SMAPE", f"{m['smape']:.4e}")]
    if m["outside_ci"] is None:
        rows.append(("outside 99.7% CI", "n/a (no variance for images)"))
    else:
        rows.append(("outside 99.7% CI",
                     f"{100 * m['outside_ci']:.2f}%  (~{100 * EXPECTED_OUTSIDE:.2f}% if unbiased)"))
    if report["mode"] == "scene":
        d, r = report["drpt"], report["reference"]
        rows.append(("drpt time", f"{d['seconds']:.2f} s  ({d['spp']} spp, "
                                  f"+{d['build_seconds']:.2f} s build)"))
        rows.append(("Mitsuba time", f"{r['seconds']:.2f} s  ({r['spp']} spp in "
                                     f"{r['batches']} batches"
                                     + (", cached)" if r["cached"] else ")")))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


# ------------------------------------------------------------ image form
def compare_images(a: Path, b: Path, out: Path) -> dict:
    """Compare image ``a`` with reference ``b``; write metrics.json and the PNG."""
    from .. import metrics
    from ..imageio import read_image

    x = _rgb(read_image(a), a)
    ref = _rgb(read_image(b), b)
    if x.shape[:2] != ref.shape[:2]:
        raise DrptError(f"image sizes differ: {a} is {x.shape[1]}x{x.shape[0]}, "
                        f"{b} is {ref.shape[1]}x{ref.shape[0]}")
    if x.shape[2] != ref.shape[2]:  # gray vs RGB
        x, ref = np.broadcast_arrays(x, ref)
    for img, p in ((x, a), (ref, b)):
        if not np.all(np.isfinite(img)):
            raise DrptError(f"{p}: image has NaN/Inf values")
    _prepare_out(out)
    summary = metrics.summary(x, ref)
    report = {
        "mode": "images",
        "image": str(a),
        "reference": str(b),
        "width": int(x.shape[1]),
        "height": int(x.shape[0]),
        "metrics": summary,
        "outside_ci_note": "null: two images carry no variance, so there is no confidence "
                           "interval",
    }
    write_side_by_side(out / "side_by_side.png", x, ref, metrics.error_map(x, ref),
                       labels=(a.name, f"{b.name} (reference)"))
    _write_json(out / "metrics.json", report)
    return report


# ------------------------------------------------------------ scene form
def _file_hash(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _stat(path) -> list:
    p = Path(path)
    try:
        st = p.stat()
        return [str(p.resolve()), st.st_size, st.st_mtime_ns]
    except OSError:
        return [str(p), None, None]


def reference_key(scene, settings: dict) -> str:
    """SHA-256 (hex) identifying a reference render; see the module docs."""
    import mitsuba as mi

    from ..export import mitsuba as export
    from ..scene.model import Skybox

    h = hashlib.sha256()

    def add(tag: str, data: bytes) -> None:
        h.update(tag.encode() + b"\0" + len(data).to_bytes(8, "little") + data)

    add("meta", json.dumps({"cache_version": CACHE_VERSION, "mitsuba": mi.__version__,
                            "settings": settings}, sort_keys=True).encode())
    with tempfile.TemporaryDirectory(prefix="drpt_key_") as tmp:
        export.write_xml(scene, Path(tmp) / "scene.xml", settings["width"],
                               settings["height"], settings["batch_spp"],
                               max_depth=settings["max_depth"], rr_depth=settings["rr_depth"],
                               seed=settings["ref_seed"], bsdf=settings["bsdf"])
        for f in sorted(Path(tmp).rglob("*")):
            if f.is_file():
                add("export:" + str(f.relative_to(tmp)), f.read_bytes())
    for src in sorted(Path(export.__file__).parent.glob("*.py")):
        add("exporter:" + src.name, src.read_bytes())
    add("scene", Path(scene.path).read_bytes())
    deps = [_stat(m.map_kd) for m in scene.materials if m.map_kd is not None]
    deps += [_stat(light.path) for light in scene.lights if isinstance(light, Skybox)]
    add("deps", json.dumps(deps).encode())
    return h.hexdigest()


def _load_cached(path: Path):
    try:
        with np.load(path, allow_pickle=False) as z:
            mean, var = z["mean"].astype(np.float32), z["variance"].astype(np.float32)
            meta = json.loads(str(z["meta"]))
        return mean, var, meta
    except Exception as e:  # a broken cache entry is re-rendered, not fatal
        print(f"drpt: warning: ignoring unreadable cached reference {path}: {e}",
              file=sys.stderr)
        return None


def _save_cached(path: Path, mean, var, meta: dict) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=path.stem, suffix=".tmp.npz", dir=path.parent)
        os.close(fd)
        np.savez(tmp, mean=mean, variance=var, meta=np.array(json.dumps(meta)))
        os.replace(tmp, path)
    except OSError as e:
        print(f"drpt: warning: cannot cache the reference in {path.parent}: "
              f"{e.strerror or e}", file=sys.stderr)


def render_reference(scene, settings: dict, progress: bool = True):
    """Mitsuba mean image, variance of the mean, and render seconds."""
    import mitsuba as mi

    from ..export.mitsuba import to_mitsuba_dict

    per, batches, seed = settings["batch_spp"], settings["batches"], settings["ref_seed"]
    t0 = time.perf_counter()
    ms = mi.load_dict(to_mitsuba_dict(scene, settings["width"], settings["height"], per,
                                      max_depth=settings["max_depth"],
                                      rr_depth=settings["rr_depth"], seed=seed,
                                      bsdf=settings["bsdf"]))
    load_seconds = time.perf_counter() - t0
    runs = []
    t0 = time.perf_counter()
    for k in range(batches):
        runs.append(np.asarray(mi.render(ms, spp=per, seed=seed + 7919 * k), np.float64))
        if progress:
            print(f"\rreference: batch {k + 1}/{batches}", end="", file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    seconds = time.perf_counter() - t0
    runs = np.stack(runs)
    mean = runs.mean(0)
    var = runs.var(0, ddof=1) / batches
    return mean.astype(np.float32), var.astype(np.float32), seconds, load_seconds


def check_reference_args(ref_spp: int, ref_batches: int, max_depth: int, rr_depth: int,
                         note: bool = True) -> int:
    """Raise DrptError on bad reference settings; return the samples per batch."""
    if ref_spp <= 0:
        raise DrptError(f"--ref-spp must be positive, got {ref_spp}")
    if ref_batches < 2:
        raise DrptError(f"--ref-batches must be at least 2 (for a variance), got {ref_batches}")
    if ref_spp < ref_batches:
        raise DrptError(f"--ref-spp ({ref_spp}) must be at least --ref-batches ({ref_batches})")
    if max_depth == 0 or max_depth < -1:
        raise DrptError(f"--max-depth must be -1 (unbounded) or >= 1, got {max_depth}")
    if rr_depth <= 0:
        raise DrptError(f"--rr-depth must be positive, got {rr_depth}")
    per = -(-ref_spp // ref_batches)
    if per * ref_batches != ref_spp and note:
        print(f"drpt: note: --ref-spp {ref_spp} is not a multiple of {ref_batches} batches; "
              f"using {per * ref_batches}", file=sys.stderr)
    return per


@dataclass
class Reference:
    """A Mitsuba reference image as :func:`get_reference` returns it."""

    image: np.ndarray  # (H, W, 3) mean
    variance: np.ndarray  # (H, W, 3) variance of the mean, from the batches
    meta: dict  # holds the reference's render "seconds"
    cached: bool  # read from the cache
    key: str  # cache key (SHA-256 of the export and settings)
    cache_file: Path | None  # <cache_dir>/<stem>_<key[:24]>.npz, None without a cache
    settings: dict  # width, height, batch_spp, batches, max_depth, rr_depth, bsdf, ref_seed

    def info(self) -> dict:
        """What a report says about the reference (JSON-ready)."""
        import mitsuba as mi

        s = self.settings
        return {"renderer": f"mitsuba {mi.__version__} llvm_ad_rgb path",
                "spp": s["batch_spp"] * s["batches"], "batches": s["batches"],
                "seed": s["ref_seed"], "seconds": float(self.meta["seconds"]),
                "cached": self.cached,
                "cache_file": None if self.cache_file is None else str(self.cache_file),
                "key": self.key}


def get_reference(scene, stem: str, width: int, height: int, ref_spp: int = 1024,
                  ref_batches: int = 8, bsdf: str = "phong", max_depth: int = -1,
                  rr_depth: int = 5, seed: int = 0, cache_dir: Path | None = None,
                  progress: bool = True) -> Reference:
    """The Mitsuba reference of a loaded ``scene``: from the cache, or rendered (and cached).

    Checks the settings, sets up Mitsuba (``llvm_ad_rgb``) and Dr.Jit's LLVM
    backend. User mistakes raise DrptError.
    """
    from ..backend import ensure

    if min(width, height) <= 0:
        raise DrptError(f"size must be positive, got {width}x{height}")
    per = check_reference_args(ref_spp, ref_batches, max_depth, rr_depth)

    ensure()
    try:
        import mitsuba as mi
    except ImportError as e:
        raise DrptError(f"a Mitsuba reference needs Mitsuba 3 ('pip install mitsuba'): {e}") from e
    try:
        from drpt.backend import mitsuba_variant
        mi.set_variant(mitsuba_variant())
    except Exception as e:
        raise DrptError(f"Mitsuba has no usable 'llvm_ad_rgb' variant: {e}") from e

    settings = {"width": int(width), "height": int(height), "batch_spp": per,
                "batches": int(ref_batches), "max_depth": int(max_depth),
                "rr_depth": int(rr_depth), "bsdf": bsdf, "ref_seed": int(seed) + 100000}
    key = reference_key(scene, settings)
    cache_file = None if cache_dir is None else Path(cache_dir) / f"{stem}_{key[:24]}.npz"
    cached = _load_cached(cache_file) if cache_file is not None and cache_file.is_file() else None
    if cached is not None:
        ref, ref_var, meta = cached
        if ref.shape != (height, width, 3):
            cached = None
    if cached is None:
        ref, ref_var, secs, load_secs = render_reference(scene, settings, progress)
        meta = {"seconds": secs, "load_seconds": load_secs, "key": key, "settings": settings}
        if cache_file is not None:
            _save_cached(cache_file, ref, ref_var, meta)
    if not np.all(np.isfinite(ref)):
        raise DrptError("the Mitsuba reference has NaN/Inf pixels")
    return Reference(ref, ref_var, meta, cached is not None, key, cache_file, settings)


def compare_scene(scene_path: Path, out: Path, width: int = 128, height: int = 128,
                  spp: int = 64, ref_spp: int = 1024, ref_batches: int = 8,
                  bsdf: str = "phong", max_depth: int = -1, rr_depth: int = 5, seed: int = 0,
                  cache_dir: Path | None = None, progress: bool = True) -> dict:
    """Render ``scene_path`` with drpt and Mitsuba (cached) and write the comparison."""
    from .. import metrics
    from ..imageio import write_image
    from ..options import PathOptions
    from ..options import RenderOptions
    from ..render.renderer import Renderer
    from ..scene import load_scene

    if min(width, height) <= 0:
        raise DrptError(f"size must be positive, got {width}x{height}")
    if spp <= 0:
        raise DrptError(f"--spp must be positive, got {spp}")
    check_reference_args(ref_spp, ref_batches, max_depth, rr_depth, note=False)
    scene = load_scene(scene_path)
    _prepare_out(out)
    reference = get_reference(
        scene, scene_path.stem, width, height, ref_spp=ref_spp, ref_batches=ref_batches,
        bsdf=bsdf, max_depth=max_depth, rr_depth=rr_depth, seed=seed, cache_dir=cache_dir,
        progress=progress)
    ref, ref_var = reference.image, reference.variance

    opts = RenderOptions(width=width, height=height, spp=spp, seed=seed, bsdf=bsdf,
                         path=PathOptions(max_depth=max_depth, rr_depth=rr_depth),
                         progress=progress)
    renderer = Renderer(scene, opts)
    for message in renderer.warnings:
        print(f"drpt: warning: {message}", file=sys.stderr)
    result = renderer.render()
    if result.nonfinite:
        print(f"drpt: warning: {result.nonfinite} samples were NaN/Inf and were set to 0",
              file=sys.stderr)

    summary = metrics.summary(result.image, ref, result.variance, ref_var, z=CI_Z)
    report = {
        "mode": "scene",
        "scene": str(scene_path),
        "width": int(width),
        "height": int(height),
        "bsdf": bsdf,
        "max_depth": int(max_depth),
        "rr_depth": int(rr_depth),
        "metrics": summary,
        "outside_ci_expected": EXPECTED_OUTSIDE,
        "outside_ci_note": f"fraction of pixel channels with |drpt - ref| > {CI_Z:g} * "
                           "sqrt(var_drpt + var_ref); ~0.0027 if both are unbiased (more when "
                           "the variances are estimated from few samples)",
        "drpt": {"spp": int(spp), "seed": int(seed), "seconds": result.seconds,
                 "build_seconds": result.build_seconds, "nonfinite": int(result.nonfinite)},
        "reference": reference.info(),
    }
    write_image(out / "drpt.exr", result.image)
    write_image(out / "reference.exr", ref)
    write_side_by_side(out / "side_by_side.png", result.image, ref,
                       metrics.error_map(result.image, ref))
    _write_json(out / "metrics.json", report)
    return report
