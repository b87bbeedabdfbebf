"""``python -m drpt gallery``: render every bundled scene, with its error against Mitsuba 3.

::

    python -m drpt gallery [--size W H | --scale K] [render flags] [--scenes A,B,...]
                           [--out DIR]

The scenes are the entries of the committed reference table
(:data:`drpt.tools.reference.REFERENCES`): each names a bundled scene file
and the material mode and depth it is rendered with (``cornellbox`` and
``cornellbox_ct`` are the Cornell box read as Phong and as Cook-Torrance).
The other render flags are ``render``'s (:func:`drpt.cli.args.add_render_flags`,
``--spp`` default 64). The dining room is generated first
(:mod:`drpt.tools.scenegen.diningroom`) when ``scenes/diningroom/`` is
missing.

Size
    By default each scene is rendered at ``--scale`` (default 2) times the size
    of its reference; ``--size W H`` renders every scene at ``W x H`` instead.
Error against the reference
    When the render's size is an integer multiple ``k`` of the reference's
    (same ``k`` for both axes), the render is
    box-downsampled by ``k`` (the mean of each ``k x k`` block) and compared
    with the reference EXR. Both renderers use a box pixel filter, so the
    downsampled render estimates exactly the reference's pixels. Otherwise
    the error columns say ``n/a``. The reference's variance ``var_ref`` is
    measured from its batches where ``reference/`` has a ``*_var.exr``, else
    taken as drpt's per-sample variance over the reference's spp. Columns
    (:mod:`drpt.metrics`): ``relMSE`` of the downsampled render; ``noise
    relMSE``, the relMSE an unbiased render would show from the noise of both
    images, ``mean((var + var_ref) / (ref^2 + 0.01))`` with drpt's per-pixel
    variance estimate ``var`` (relMSE well above it points to a bias); and
    the fraction of values outside the 99.7% interval (``outside_ci`` with
    ``var + var_ref``). That fraction is ~0.3% for an unbiased render only
    where drpt's per-pixel variance estimate is reliable: glossy caustics and
    sunlight through glass make heavy-tailed samples and push it to a few
    percent without any bias (the block z-tests in ``tests/`` are the bias
    check).

Outputs in ``--out`` (default ``gallery/``): ``<name>.png`` (gamma 2.2),
``gallery.md`` and ``gallery.html`` (each image with render time, build
time, samples/s and the error columns) and ``gallery.json`` (the same
numbers).
"""

from __future__ import annotations

import argparse
import html
import json
import time
from pathlib import Path

import numpy as np

from .. import metrics
from ..backend import ensure
from ..cli.args import add_render_flags, options_from_args
from ..errors import DrptError, warn
from ..imageio import read_image, write_image
from ..render.renderer import Renderer
from ..scene import load_scene
from . import reference as refs
from .table import markdown_table

__all__ = ["add_parser", "main", "downsample", "render_gallery"]


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``gallery`` subcommand on an ``add_subparsers()`` object."""
    p = subparsers.add_parser(
        "gallery", allow_abbrev=False,
        help="render every bundled scene to a gallery page with errors against Mitsuba 3",
        description="render the bundled scenes (the entries of drpt.tools.reference."
                    "REFERENCES) and write PNGs plus gallery.md/.html with times and the "
                    "error against each committed Mitsuba reference")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--size", nargs=2, type=int, metavar=("W", "H"), default=None,
                      help="render every scene at W x H (default: --scale times the "
                           "reference's size)")
    size.add_argument("--scale", type=int, default=2,
                      help="render each scene at this multiple of its reference's size "
                           "(default 2)")
    # (no -D, --ignore-unsupported, --strict: the bundled scenes are text files)
    add_render_flags(p, omit=("size", "bsdf", "max_depth", "scene"), spp=64)
    p.add_argument("--scenes", default=None,
                   help="comma-separated subset of the scene names (default: all)")
    p.add_argument("--out", default="gallery", help="output folder (default gallery/)")
    p.set_defaults(func=main)
    return p


def downsample(img: np.ndarray, k: int) -> np.ndarray:
    """Mean of each ``k x k`` pixel block (``H`` and ``W`` multiples of ``k``)."""
    h, w = img.shape[:2]
    return img.reshape(h // k, k, w // k, k, *img.shape[2:]).mean((1, 3))


def _factor(size, ref_size) -> int | None:
    (w, h), (rw, rh) = size, ref_size
    if w % rw or h % rh or w // rw != h // rh:
        return None
    return w // rw


def render_gallery(out: Path, options, names=None, size=None, scale: int = 2) -> list[dict]:
    """Render ``names`` (default: every reference) into ``out`` with drpt's
    ``options`` (a :class:`~drpt.options.RenderOptions`; each scene sets the
    size, material mode and depth); returns one row per scene."""
    from dataclasses import replace

    options.validate()
    spp = options.spp
    table = refs.REFERENCES
    names = list(table) if names is None else list(names)
    unknown = [n for n in names if n not in table]
    if unknown:
        raise DrptError(f"unknown scene(s) {', '.join(unknown)}; choose from {', '.join(table)}")
    if scale <= 0 or (size is not None and min(size) <= 0):
        raise DrptError("--size, --scale and --spp must be positive")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DrptError(f"{out}: cannot create output folder: {e.strerror or e}") from e

    ensure()
    rows = []
    for name in names:
        scene_file, rw, rh, ref_spp, depth, mode = table[name]
        W, H = size if size is not None else (rw * scale, rh * scale)
        t0 = time.perf_counter()
        scene = load_scene(refs.scene_path(scene_file))
        load_s = time.perf_counter() - t0
        renderer = Renderer(scene, replace(options, width=W, height=H, bsdf=mode, variance=True,
                                           path=replace(options.path, max_depth=depth),
                                           # (a scene with media: volpath, as its reference)
                                           integrator="volpath" if scene.media else options.integrator))
        for message in renderer.warnings:
            warn(f"{name}: {message}")
        r = renderer.render()
        if r.nonfinite:
            warn(f"{name}: {r.nonfinite} samples were NaN/Inf and were set to 0")
        write_image(out / f"{name}.png", r.image)
        row = {"name": name, "scene": scene_file, "bsdf": mode, "width": W, "height": H,
               "spp": spp, "seconds": r.seconds, "build_seconds": r.build_seconds,
               "load_seconds": load_s, "samples_per_second": r.samples_per_second,
               "image": f"{name}.png", "reference": None}
        k = _factor((W, H), (rw, rh))
        ref_file = refs.reference_path(name)
        if k is not None and ref_file.is_file():
            ref = read_image(ref_file)[..., :3].astype(np.float64)
            x = downsample(r.image.astype(np.float64), k)
            # variance of a k x k block mean: the mean of the pixel variances / k^2
            var = downsample(r.variance.astype(np.float64), k) / (k * k)
            var_file = refs.variance_path(name)
            if var_file.is_file():  # measured from the reference's batches
                var_ref = read_image(var_file)[..., :3].astype(np.float64)
            else:  # drpt's per-sample variance over the reference's spp
                var_ref = var * (k * k * spp) / ref_spp
            row["reference"] = {
                "file": str(ref_file.relative_to(refs.ROOT)), "width": rw, "height": rh,
                "spp": ref_spp, "downsample": k,
                "rel_mse": metrics.rel_mse(x, ref),
                "noise_rel_mse": float(np.mean((var + var_ref) / (ref * ref + 1e-2))),
                "outside_ci": metrics.outside_ci(x, var, ref, var_ref),
            }
        rows.append(row)
        msg = f"{name}: {W}x{H}, {spp} spp, {r.seconds:.1f} s"
        if row["reference"]:
            msg += f", relMSE {row['reference']['rel_mse']:.2e}"
        print(msg, flush=True)
    _write_pages(out, rows)
    return rows


def _cells(row: dict) -> list[str]:
    ref = row["reference"]
    cells = [row["name"], row["bsdf"], f"{row['width']}x{row['height']}", str(row["spp"]),
             f"{row['seconds']:.1f}", f"{row['build_seconds']:.1f}",
             f"{row['samples_per_second'] / 1e6:.2f}"]
    if ref is None:
        cells += ["n/a", "n/a", "n/a", "no reference at this size"]
    else:
        cells += [f"{ref['rel_mse']:.2e}", f"{ref['noise_rel_mse']:.2e}",
                  f"{100 * ref['outside_ci']:.2f}%",
                  f"{ref['width']}x{ref['height']}, {ref['spp']} spp"
                  + (f" (render / {ref['downsample']})" if ref["downsample"] > 1 else "")]
    return cells


HEADER = ["scene", "bsdf", "size", "spp", "render s", "build s", "Msamples/s", "relMSE",
          "noise relMSE", "outside 99.7% CI", "Mitsuba reference"]
EXPLAIN = ("Error columns compare the render, box-downsampled to the size of the committed "
           "Mitsuba 3 reference (reference/), with that reference. *noise relMSE* is the "
           "relMSE an unbiased render would show from the noise of both images (drpt's "
           "per-pixel variance estimate and the reference's); relMSE well above it points to "
           "a bias. The fraction outside the 99.7% interval is ~0.3% without bias only where "
           "the per-pixel variance estimates are reliable; heavy-tailed samples (glossy "
           "caustics, sunlight through glass) push it to a few percent. Render time excludes "
           "the BVH build (build s) and scene loading.")


def _write_pages(out: Path, rows: list[dict]) -> None:
    md = ["# drpt gallery", "", EXPLAIN, "", markdown_table(HEADER, [_cells(r) for r in rows])]
    md.append("")
    for r in rows:
        md += [f"## {r['name']}", "", f"![{r['name']}]({r['image']})", "",
               f"`{r['scene']}`, `--bsdf {r['bsdf']}`, {r['width']}x{r['height']}, "
               f"{r['spp']} spp: {r['seconds']:.1f} s, "
               f"{r['samples_per_second'] / 1e6:.2f} Msamples/s", ""]
    h = ["<!doctype html>", "<meta charset='utf-8'><title>drpt gallery</title>",
         "<style>body{font-family:sans-serif}td,th{padding:2px 8px;text-align:right}"
         "img{image-rendering:pixelated;width:384px}figure{display:inline-block}</style>",
         "<h1>drpt gallery</h1>", f"<p>{html.escape(EXPLAIN)}</p>", "<table>",
         "<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in HEADER) + "</tr>"]
    h += ["<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in _cells(r)) + "</tr>"
          for r in rows]
    h.append("</table>")
    h += [f"<figure><img src='{html.escape(r['image'])}' alt='{html.escape(r['name'])}'>"
          f"<figcaption>{html.escape(r['name'])}</figcaption></figure>" for r in rows]
    try:
        (out / "gallery.md").write_text("\n".join(md), encoding="utf-8")
        (out / "gallery.html").write_text("\n".join(h) + "\n", encoding="utf-8")
        (out / "gallery.json").write_text(json.dumps(rows, indent=2) + "\n", encoding="utf-8")
    except OSError as e:
        raise DrptError(f"{out}: cannot write: {e.strerror or e}") from e


def main(args: argparse.Namespace) -> int:
    """Run ``gallery`` for parsed ``args``; user errors raise DrptError."""
    options = options_from_args(args)
    names = None
    if args.scenes:
        names = [s.strip() for s in args.scenes.split(",") if s.strip()]
    out = Path(args.out)
    render_gallery(out, options, names=names, size=tuple(args.size) if args.size else None,
                   scale=args.scale)
    print(f"{out}: gallery.md, gallery.html, gallery.json and one PNG per scene")
    return 0
