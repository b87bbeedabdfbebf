"""``python -m drpt compare``: drpt against Mitsuba 3, or one image against another.

Two forms::

    python -m drpt compare SCENE [render flags] [--ref-spp M] [--ref-batches B]
                                 [--control] [--cache DIR | --no-cache] [--out DIR]
    python -m drpt compare A.exr B.exr [--out DIR]

Scene form
    The render flags are ``render``'s (:func:`drpt.cli.args.add_render_flags`:
    ``--size`` (default 128 128), ``--spp`` (default 64), ``--bsdf``,
    ``--max-depth``, ``--rr-depth``, ``--accel``, ``--seed``, ``--backend``,
    ...). The scene is rendered by Mitsuba's ``path`` integrator on drpt's
    backend at ``--ref-spp`` samples per pixel in ``--ref-batches``
    independent batches whose spread gives the reference's per-pixel
    variance of the mean, and cached (:func:`drpt.tools.reference.get_reference`:
    any change of the scene, its files, the exporter or a setting renders a
    new reference; otherwise it is reused). Then drpt renders the scene with
    the same settings (its own per-pixel variance comes with the render)
    and the two are compared. ``--filter`` is both renders' pixel filter
    (Mitsuba's film gets the same ``rfilter``).

    The verdict (:func:`verdict`) is ``agrees``, ``differs`` or ``undecided``, from a
    block z-test (:func:`block_test`): the means of ``b x b`` blocks
    (:func:`block_size`: 8, or twice the filter's support) per channel, each
    difference over its standard error, against the Sidak threshold of level
    :data:`ALPHA` over the blocks. drpt's pixels are independent (filter importance
    sampling), so its block variance is the sum of its pixels'; the reference's comes
    from its batches' spread (it holds the correlation Mitsuba's splatting gives
    neighbouring pixels). A failing render is followed by a second drpt render with
    another seed: ``differs`` when it fails the same blocks (:func:`confirm`) and
    Mitsuba's ``--control`` (if asked for) passes; otherwise ``undecided``.

    The per-pixel fraction outside the 99.7% interval is still reported, without a
    verdict: it is ~0.27% for an unbiased render only when the pixel errors are
    Gaussian with the estimated variances, and they are not where a pixel's few samples
    misjudge its variance: with a Gaussian filter a pixel near an edge seldom samples
    across it (10-35% outside where the images agree), and in heavy-tailed scenes (rare
    bright paths) most pixels have not drawn the rare samples. ``--control`` renders
    Mitsuba at drpt's spp with drpt's variance estimator
    (:func:`~drpt.tools.reference.get_control`, cached) and judges it by the same tests.

Image form
    Two images (any format :func:`drpt.imageio.read_image` reads; alpha is
    dropped, a gray image is compared against each channel of an RGB one; 8-bit
    images are decoded by ``x ** --gamma``, the curve ``render`` writes them with).
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
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import metrics
from ..cli.args import add_render_flags, given_settings, options_from_args
from ..errors import DrptError, Loc, SceneError, warn
from ..imageio import _LDR, read_image, write_image
from ..metrics import BLOCK_SIZES, sidak_z
from ..options import MAX_SEED, with_scene_settings
from ..render.renderer import Renderer
from ..scene import load_scene
from .reference import (
    add_reference_args,
    cache_dir_from_args,
    check_reference_args,
    get_control,
    get_reference,
)
from .xmlref import MitsubaXML

IMAGE_EXTENSIONS = (".exr", ".hdr", ".pfm", ".png", ".jpg", ".jpeg", ".tga")
CI_Z = 3.0  # the 99.7% interval
EXPECTED_OUTSIDE = 0.0027  # 2 (1 - Phi(3))
ALPHA = 0.01  # the block test's false-alarm rate for an unbiased render (Sidak over its blocks)
REL_FLOOR = 1e-3  # block differences below 0.1% of the reference where neither side has noise pass

__all__ = ["add_parser", "main", "compare_images", "compare_scene"]


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
    add_render_flags(p, size=(128, 128), spp=64)
    add_reference_args(p, ref_spp=1024)
    p.add_argument("--control", action="store_true",
                   help="also render Mitsuba at --spp (single-sample renders, cached) and judge "
                        "it by the same tests: what an unbiased renderer reads on this scene at "
                        "this spp (the verdict is 'undecided' when Mitsuba itself fails)")
    p.add_argument("--out", default=None, help="output folder (default compare_<name>/)")
    p.add_argument("--gamma", type=float, default=2.2,
                   help="compare A B: the power curve 8-bit images (.png, .tga, .jpg) are "
                        "decoded with, as render --gamma writes them (default 2.2)")
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
        if not (np.isfinite(args.gamma) and args.gamma > 0):
            raise DrptError(f"--gamma must be a positive finite number, got {args.gamma}")
        report = compare_images(inputs[0], inputs[1], out, gamma=args.gamma)
    else:
        scene = inputs[0]
        if scene.suffix.lower() in IMAGE_EXTENSIONS:
            raise DrptError(f"{scene}: an image alone cannot be compared; give a scene file, "
                            "or two images (compare A B)")
        options = options_from_args(args)
        out = Path(args.out) if args.out else Path(f"compare_{scene.stem}")
        report = compare_scene(scene, out, options, ref_spp=args.ref_spp,
                               ref_batches=args.ref_batches, cache_dir=cache_dir_from_args(args),
                               control=args.control, args=args)
    print(format_table(report))
    print(f"{out}: metrics.json, side_by_side.png"
          + (", drpt.exr, reference.exr" if report["mode"] == "scene" else ""))
    return 0


# ------------------------------------------------------------------ helpers
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
    rows = []
    if m.get("verdict") is not None:
        rows.append(("verdict", f"{m['verdict']}: {m['verdict_reason']}"))
        b = m["block"]
        line = (f"max |z| {m['block_max_abs_z']:.2f} over {m['block_tests']} block means "
                f"({b}x{b}, RGB; threshold {m['block_threshold']:.2f})")
        if m.get("block_max_abs_z_control") is not None:
            line += f"; Mitsuba itself: {m['block_max_abs_z_control']:.2f}"
        rows.append(("block z-test", line))
    rows += [("relMSE", f"{m['rel_mse']:.4e}"), ("MAE", f"{m['mae']:.4e}"),
             ("SMAPE", f"{m['smape']:.4e}")]
    if m["outside_ci"] is None:
        rows.append(("outside 99.7% CI", "n/a (no variance for images)"))
    elif m.get("outside_ci_control") is None:
        rows.append(("outside 99.7% CI",
                     f"{100 * m['outside_ci']:.2f}% of pixel values (~{100 * EXPECTED_OUTSIDE:.2f}% "
                     "only for Gaussian errors; no verdict: see the block z-test)"))
    else:
        spp = report["control"]["spp"]
        rows.append(("outside 99.7% CI",
                     f"{100 * m['outside_ci']:.2f}% of pixel values (Mitsuba itself at {spp} spp: "
                     f"{100 * m['outside_ci_control']:.2f}%; ~{100 * EXPECTED_OUTSIDE:.2f}% for "
                     "Gaussian errors)"))
    if report["mode"] == "scene" and not report.get("like_for_like", True):
        rows.append(("NOT like for like", f"drpt left out {len(report['not_read'])} thing(s) Mitsuba "
                                          "renders (metrics.json: not_read)"))
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
def compare_images(a: Path, b: Path, out: Path, gamma: float = 2.2) -> dict:
    """Compare image ``a`` with reference ``b``; write metrics.json and the PNG.
    8-bit images are decoded by ``x ** gamma``, the curve ``render`` writes them with;
    an 8-bit image against a float one compares both clamped to [0, 1], what the 8-bit
    one can hold."""
    x = _rgb(read_image(a, gamma=gamma), a)
    ref = _rgb(read_image(b, gamma=gamma), b)
    # an 8-bit image holds [0, 1]: the other one is compared as it would be written
    clamped = (a.suffix.lower() in _LDR) != (b.suffix.lower() in _LDR)
    if clamped:
        x, ref = np.clip(x, 0.0, 1.0), np.clip(ref, 0.0, 1.0)
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
        "gamma": float(gamma),
        "clamped": bool(clamped),
        "outside_ci_note": "null: two images carry no variance, so there is no confidence "
                           "interval",
    }
    write_side_by_side(out / "side_by_side.png", x, ref, metrics.error_map(x, ref),
                       labels=(a.name, f"{b.name} (reference)"))
    _write_json(out / "metrics.json", report)
    return report


# ------------------------------------------------------------ block test
def block_size(pixel_filter) -> int:
    """The block side of the verdict's test: at least 8 pixels and twice the filter's
    support (4 radii), so that the pixels whose filter reaches across an edge (whose
    few samples misjudge their own variance) are a minority of every block."""
    want = max(8.0, 4.0 * pixel_filter.radius)
    return next((b for b in BLOCK_SIZES if b >= want), BLOCK_SIZES[-1])


def block_test(x, var_x, ref, ref_block_var, b: int, alpha: float = ALPHA,
               splat_j: float = 1.0) -> dict:
    """drpt's ``x`` (pixels with variances ``var_x``: independent, or splatted by a
    filter of :func:`drpt.metrics.filter_j` ``splat_j``) against ``ref``
    (``ref_block_var``: the variance of each ``b x b`` block mean) by the z of every
    block mean and channel; it passes when every ``|z|`` stays below the Sidak
    threshold of level ``alpha``. The standard deviation has a floor of
    :data:`REL_FLOOR` times the reference block, so that noiseless regions (a sky
    seen directly) that differ by float rounding pass."""
    var = (metrics.block_variance_independent(var_x, b) / splat_j
           + np.asarray(ref_block_var, np.float64))
    floor = REL_FLOOR * np.abs(metrics.block_means(ref, b))
    z = metrics.block_z(x, ref, var + floor * floor, 0.0, b)
    threshold = metrics.sidak_z(z.size, alpha)
    az = np.abs(z)
    worst = np.unravel_index(int(np.argmax(az)), az.shape)
    return {"block": int(b), "tests": int(z.size), "threshold": threshold,
            "max_abs_z": float(az.max()), "passed": bool(az.max() <= threshold),
            "worst_block": {"x": int(worst[1] * b), "y": int(worst[0] * b),
                            "channel": "RGB"[worst[2]], "z": float(z[worst])},
            "failing": [tuple(int(i) for i in ix) for ix in np.argwhere(az > threshold)],
            "_z": z}


def confirm(z_first: np.ndarray, failing, z_second: np.ndarray, alpha: float = ALPHA) -> bool:
    """Whether a second, independent render fails the blocks that failed the first
    (the same sign, beyond the Sidak threshold over those blocks): a bias does, the
    rare bright samples of a heavy-tailed scene seldom land in the same blocks twice."""
    if not failing:
        return False
    t = sidak_z(len(failing), alpha)
    return any(abs(z_second[ix]) > t and np.sign(z_second[ix]) == np.sign(z_first[ix])
               for ix in failing)


def verdict(first: dict, confirmed: bool | None, control: dict | None) -> tuple[str, str]:
    """``("agrees" | "differs" | "undecided", why)``."""
    b = first["block"]
    if first["passed"]:
        return "agrees", (f"every {b}x{b} block within |z| {first['threshold']:.2f} "
                          f"(max {first['max_abs_z']:.2f})")
    w = first["worst_block"]
    where = f"block at ({w['x']}, {w['y']}) {w['channel']} z {w['z']:+.1f}"
    if control is not None and not control["passed"]:
        return "undecided", (f"{where}, but Mitsuba itself fails this test at this spp "
                             f"(max |z| {control['max_abs_z']:.1f}): raise --spp")
    if confirmed:
        return "differs", f"{where}, and a second drpt render (another seed) fails there too"
    return "undecided", (f"{where}, but a second drpt render (another seed) passes there: "
                         "heavy-tailed noise at this spp; raise --spp")


# ------------------------------------------------------------ scene form
def compare_scene(scene_path: Path, out: Path, options, ref_spp: int = 1024,
                  ref_batches: int = 8, cache_dir: Path | None = None,
                  control: bool = False, args=None) -> dict:
    """Render ``scene_path`` with drpt (``options``, a :class:`~drpt.options.RenderOptions`)
    and Mitsuba (cached, same size, depths, material mode and seed + 100000) and write the
    comparison. With ``control``, Mitsuba at drpt's spp is judged against the reference
    by the same interval (``metrics["outside_ci_control"]``, ``report["control"]``).

    A Mitsuba XML scene: with ``args`` (the parsed command line), the file's own
    size, spp, depths, ``hide_emitters`` and filter apply where no flag was given
    (:func:`~drpt.options.with_scene_settings`), and Mitsuba renders the reference
    from the file itself (:class:`~drpt.tools.xmlref.MitsubaXML`), not from drpt's
    export: the same size, and the file's filter and integrator unless ``options``
    differ from them."""
    options.validate()
    scene = load_scene(scene_path)
    source = None
    if scene_path.suffix.lower() == ".xml":
        if args is not None:
            options, scene = with_scene_settings(options, scene, given_settings(args))
        not_read = list(getattr(scene.settings, "not_read", ()))
        if not_read and not getattr(args, "ignore_unsupported", False):
            raise SceneError(Loc(scene_path), f"drpt does not read all of the file ({not_read[0]}"
                             + (f"; and {len(not_read) - 1} more" if len(not_read) > 1 else "")
                             + "): Mitsuba's reference of the file as written would not be the scene "
                             "drpt renders (--ignore-unsupported compares anyway, marked not like for like)")
        source = MitsubaXML.for_scene(scene, options)
    width, height, spp, seed = options.width, options.height, options.spp, options.seed
    bsdf, max_depth, rr_depth = options.bsdf, options.path.max_depth, options.path.rr_depth
    if spp < 2:  # (one sample per pixel has no variance: the tests would see only the reference's)
        raise DrptError(f"--spp must be at least 2 (for a variance), got {spp}")
    check_reference_args(ref_spp, ref_batches, max_depth, rr_depth, announce=False)
    _prepare_out(out)
    reference = get_reference(
        scene, scene_path.stem, width, height, ref_spp=ref_spp, ref_batches=ref_batches,
        bsdf=bsdf, max_depth=max_depth, rr_depth=rr_depth, seed=seed, cache_dir=cache_dir,
        progress=options.progress, rfilter=options.filter, source=source,
        hide_emitters=options.path.hide_emitters)
    ref, ref_var = reference.image, reference.variance

    options = replace(options, variance=True)  # (light tracing's too: the tests read it)
    renderer = Renderer(scene, options)
    for message in renderer.warnings:
        warn(message)
    result = renderer.render()
    if result.nonfinite:
        warn(f"{result.nonfinite} samples were NaN/Inf and were set to 0")

    summary = metrics.summary(result.image, ref, result.variance, ref_var, z=CI_Z)
    b = block_size(options.pixel_filter)
    ref_block_var = (reference.block_variance or {}).get(b)
    if ref_block_var is None:
        ref_block_var = metrics.block_variance_independent(ref_var, b)
    # drpt's pixels are independent with filter importance sampling; were they splatted
    # (a film that spreads each sample over its neighbours), a block's variance would be
    # its pixels' sum over J (metrics.filter_j)
    splats = not options.pixel_filter.is_box and not getattr(options, "filter_sampling", True)
    splat_j = metrics.filter_j(options.pixel_filter) if splats else 1.0
    test = block_test(result.image, result.variance, ref, ref_block_var, b, splat_j=splat_j)
    confirmed = None
    if not test["passed"]:
        other = seed + 1 if seed < MAX_SEED else seed - 1
        again = Renderer(scene, replace(options, seed=other, progress=False)).render()
        second = block_test(again.image, again.variance, ref, ref_block_var, b, splat_j=splat_j)
        confirmed = confirm(test["_z"], test["failing"], second["_z"])
    control_info = control_test = None
    if control:
        c_mean, c_var, control_info = get_control(
            scene, scene_path.stem, width, height, spp, bsdf=bsdf, max_depth=max_depth,
            rr_depth=rr_depth, seed=seed, cache_dir=cache_dir, progress=options.progress,
            rfilter=options.filter, source=source, hide_emitters=options.path.hide_emitters)
        summary["outside_ci_control"] = metrics.outside_ci(c_mean, c_var, ref, ref_var, CI_Z)
        # the control's block variances come from its single-sample renders (a splatting
        # filter correlates its pixels); the test otherwise is drpt's
        c_block = control_info.pop("block_variance")[b]
        control_test = block_test(c_mean, np.zeros_like(c_var), ref, ref_block_var + c_block, b)
        summary["block_max_abs_z_control"] = control_test["max_abs_z"]
    word, why = verdict(test, confirmed, control_test)
    summary.update({"verdict": word, "verdict_reason": why, "block": b,
                    "block_tests": test["tests"], "block_threshold": test["threshold"],
                    "block_max_abs_z": test["max_abs_z"], "block_worst": test["worst_block"],
                    "block_confirmed": confirmed})
    not_read = list(getattr(getattr(scene, "settings", None), "not_read", ()))
    report = {
        "mode": "scene",
        "scene": str(scene_path),
        # drpt rendered the file as written (False: it left out what not_read lists, while
        # Mitsuba's reference renders all of it)
        "like_for_like": not not_read,
        "not_read": not_read,
        "width": int(width),
        "height": int(height),
        "bsdf": bsdf,
        "max_depth": int(max_depth),
        "rr_depth": int(rr_depth),
        "filter": str(options.pixel_filter),
        "metrics": summary,
        "verdict_note": f"drpt's {b}x{b} block means against the reference's, per channel: "
                        f"every |z| below the Sidak threshold of level {ALPHA:g} agrees; a failure "
                        "confirmed by a second drpt render of another seed (and not shared by "
                        "Mitsuba's --control) differs; otherwise undecided",
        "outside_ci_expected": EXPECTED_OUTSIDE,
        "outside_ci_note": f"fraction of pixel channels with |drpt - ref| > {CI_Z:g} * "
                           "sqrt(var_drpt + var_ref); ~0.0027 if both are unbiased with Gaussian "
                           "errors, more when the per-sample values are heavy tailed and the spp "
                           "low (metrics.outside_ci_control, with --control: Mitsuba itself at "
                           "drpt's spp, the level an unbiased renderer reaches here)",
        "control": control_info,
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
