"""The commands ``render``, ``view`` and ``export`` (the tools' are :mod:`drpt.tools`)."""

from __future__ import annotations

import argparse
import math
import os
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..aovs import parse_aovs, split
from ..backend import ensure
from ..denoise import denoise_result, denoised_path, require
from ..distributed import checkpoint
from ..distributed.engine import check_address
from ..distributed.job import Job, print_workers, run
from ..errors import DrptError, note, warn
from ..export.mitsuba import write_xml
from ..imageio import WRITE_EXTENSIONS, write_image
from ..memory import bytes_per_pixel
from ..memory import check as check_memory
from ..options import resolve_sampler, with_scene_settings
from ..render.renderer import SRGB_TO_XYZ, Renderer
from ..scene import load_scene
from .args import (
    add_distributed_flags,
    add_render_flags,
    add_view_flags,
    check_view_args,
    given_settings,
    options_from_args,
)

#: the most local worker processes --workers starts per core (each is a Python
#: process with its own copy of the scene and its own compiled kernels)
WORKERS_PER_CORE = 4


def _add_render_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="?", help="scene file (the seed's text format, or Mitsuba XML: .xml)")
    p.add_argument("--input", "-input", dest="input", help="scene file (seed flag)")
    p.add_argument("--output", "-output", "-o", dest="output",
                   help="image to write, its type from the extension: .exr, .hdr or .pfm "
                        "(linear float), .png or .tga (8-bit, gamma); default <scene>.png")
    add_render_flags(p, seed_flags=True)
    add_distributed_flags(p)
    p.add_argument("--gamma", "-Gamma", dest="gamma", type=float, default=2.2,
                   help="display gamma for .png/.tga (default 2.2)")
    p.add_argument("-gui", "--gui", dest="gui", action="store_true",
                   help="seed flag: move the camera in the viewer (as drpt view) first; "
                        "its \"render\" button (or closing the page) starts the render")
    p.add_argument("--gui-timeout", dest="gui_timeout", type=float, default=None, metavar="T",
                   help="with -gui: start the render with the scene's camera when no page is "
                        "open T seconds after the viewer starts (default: wait for a page)")
    add_view_flags(p)
    p.add_argument("--aovs", default=None, metavar="LIST",
                   help="AOVs written as extra layers of an .exr output, comma-separated TYPE "
                        "or NAME:TYPE, TYPE one of albedo, depth, position, uv, geo_normal, "
                        "sh_normal (normal) (Mitsuba's aov integrator; replaces a scene's own)")
    p.add_argument("--denoise", action="store_true",
                   help="also write the image denoised by Intel Open Image Denoise (pyoidn), "
                        "guided by the albedo and normal AOVs, as OUT.denoised.EXT")
    p.add_argument("--bdpt-strategies", dest="bdpt_strategies", action="store_true",
                   help="with --integrator bdpt: also write each connection strategy's "
                        "MIS-weighted image (paths of at most 5 segments) as "
                        "OUT.bdpt_dD_sS_tT.EXT")
    p.add_argument("--bdpt-merge", dest="bdpt_merge", choices=("on", "off"), default=None,
                   help="with --integrator bdpt in scenes with glass or mirrors and area lights: "
                        "estimate caustics seen through them (camera S+ D S+ light) by merging "
                        "caustic photons (progressive photon mapping: consistent, biased at any "
                        "finite spp) instead of only by hitting the light (default on)")


def _check_output(output: Path) -> None:
    """Fail before rendering, not after, on an output drpt cannot write."""
    if output.suffix.lower() not in WRITE_EXTENSIONS:
        raise DrptError(f"{output}: unsupported image type '{output.suffix}' "
                        f"(use one of {', '.join(sorted(WRITE_EXTENSIONS))})")
    if not output.parent.exists() and str(output.parent) != "":
        raise DrptError(f"{output}: folder {output.parent} does not exist")
    if output.is_dir():
        raise DrptError(f"{output}: is a folder; give an image file to write")


def moment_channels(scene, result) -> dict:
    """The AOVs of Mitsuba's ``moment`` integrator for a render with
    ``RenderOptions.moment``: ``<name>.X/Y/Z`` (the pixel in CIE XYZ) and
    ``m2_<name>.X/Y/Z`` (the mean of its samples' squares), ``<name>`` the nested
    integrator's name in the file; empty for other renders."""
    if result.moment2 is None:
        return {}

    name = getattr(getattr(scene, "settings", None), "moment", None) or "_arg_0"
    xyz = result.image.astype(np.float64) @ SRGB_TO_XYZ.T
    out = {f"{name}.{c}": xyz[..., i] for i, c in enumerate("XYZ")}
    out.update({f"m2_{name}.{c}": result.moment2[..., i] for i, c in enumerate("XYZ")})
    return out


def aov_channels(scene, opts, result) -> dict:
    """The AOV layers of a render with ``RenderOptions.aovs`` (:mod:`drpt.aovs`), and for
    a Mitsuba ``aov`` integrator its nested integrator's image as ``<name>.R/G/B``."""
    if result.aov is None:
        return {}
    layers, _ = split(opts.aovs, opts.denoise, result.aov)
    name = getattr(getattr(scene, "settings", None), "aov_image", None)
    if name and opts.aovs:
        layers = {**{f"{name}.{c}": result.image[..., i] for i, c in enumerate("RGB")}, **layers}
    return layers


def cmd_render(args: argparse.Namespace) -> int:
    scene_path = args.scene or args.input
    if not scene_path:
        raise DrptError("no scene given: drpt render SCENE (or -input SCENE)")
    if args.scene and args.input:
        raise DrptError("give the scene once, either as SCENE or as -input")
    opts = options_from_args(args, seed_mode=args.input is not None)
    if not (math.isfinite(args.gamma) and args.gamma > 0):
        raise DrptError(f"--gamma must be a positive finite number, got {args.gamma}")
    if args.output is not None and not args.output.strip():
        raise DrptError("--output is empty: give an image file (.exr, .png, .tga, ...)")
    output = Path(args.output) if args.output is not None else Path(Path(scene_path).stem + ".png")
    _check_output(output)
    if args.gui:
        check_view_args(args)
    if args.gui_timeout is not None:
        if not args.gui:
            raise DrptError("--gui-timeout applies to -gui")
        if not (math.isfinite(args.gui_timeout) and args.gui_timeout >= 0):
            raise DrptError(f"--gui-timeout must be >= 0 seconds, got {args.gui_timeout}")
    scene = load_scene(scene_path)
    opts, scene = with_scene_settings(opts, scene, given_settings(args))
    opts = _aov_options(opts, args, output)
    # --sampler auto: a resumed render's is its checkpoint's
    opts = resolve_sampler(opts, checkpoint.recorded_sampler(output)
                           if args.resume and opts.sampler == "auto" else None)
    if args.bdpt_merge is not None:
        if opts.integrator != "bdpt":
            raise DrptError(f"--bdpt-merge needs --integrator bdpt, not {opts.integrator}")
        opts = replace(opts, bdpt_merge=args.bdpt_merge == "on")
    if args.bdpt_strategies:
        opts = replace(opts, bdpt_strategies=True).validate()
        if args.workers is not None or args.cluster is not None or args.resume or opts.adaptive:
            raise DrptError("--bdpt-strategies renders in one process: --workers, --cluster, --resume "
                            "and --adaptive do not apply")
        if args.bdpt_merge == "on":
            raise DrptError("--bdpt-strategies renders without caustic merging (its strategy images "
                            "have no merging strategy): give --bdpt-merge off or leave it out")

    if args.workers is not None and args.cluster is not None:
        raise DrptError("give --workers N (a local cluster) or --cluster ADDRESS, not both")
    most = WORKERS_PER_CORE * max(2, os.cpu_count() or 1)
    if args.workers is not None and not 1 <= args.workers <= most:
        raise DrptError(f"--workers must be between 1 and {most} ({WORKERS_PER_CORE} local worker "
                        f"processes per core), got {args.workers}")
    if args.cluster is not None:
        check_address(args.cluster)
    if not (math.isfinite(args.checkpoint_seconds) and args.checkpoint_seconds >= 0):
        raise DrptError(f"--checkpoint-seconds must be >= 0, got {args.checkpoint_seconds}")

    local = args.workers is None and args.cluster is None
    check_memory(opts.width, opts.height, per_pixel=bytes_per_pixel(opts, local))
    ensure()
    if args.gui:
        scene, opts = _gui(scene, opts, args)
    if opts.adaptive:
        job = _adaptive_job(scene, opts, args)
    elif opts.bdpt_strategies:
        job = _strategies_job(scene, opts, output, args)
    else:
        job = run(scene, opts, output, workers=args.workers, cluster=args.cluster,
                  resume=args.resume, checkpoint_seconds=args.checkpoint_seconds, on_warning=warn)
    result = job.result
    if result.nonfinite:
        warn(f"{result.nonfinite} samples were NaN/Inf and were set to 0")
    write_image(output, result.image, gamma=args.gamma,
                extra={**moment_channels(scene, result), **aov_channels(scene, opts, result)})
    if opts.denoise:
        write_image(denoised_path(output), denoise_result(result), gamma=args.gamma)
    checkpoint.remove(output)
    total = result.spp + job.resumed_spp  # samples per pixel in the image (fewer than --spp
    spp = f"{total} spp"                  # when a target error or time limit stopped it)
    if job.resumed_spp:
        spp += f" ({job.resumed_spp} from the checkpoint, {total - job.resumed_spp} now)"
    extra = f"+{result.build_seconds:.2f} s build"
    if args.workers is not None or args.cluster is not None:
        extra += f", +{job.startup_seconds:.2f} s to start the cluster"
    stop = ""
    if opts.target_error is not None or opts.time_limit is not None:
        reason = f"{job.stopped} reached" if job.stopped else f"all {opts.spp} spp"
        stop = f", estimated relMSE {result.estimated_rel_mse:.3g} ({reason})"
    print(f"{output}: {opts.width}x{opts.height}, {spp}, {opts.sampler}, {result.seconds:.2f} s ({extra}), "
          f"{result.samples_per_second / 1e6:.3g} Msamples/s{stop}")
    if opts.progress and (args.workers is not None or args.cluster is not None):
        print_workers(job)
    return 0


def _adaptive_job(scene, opts, args):
    """An ``--adaptive`` render (:mod:`drpt.render.adaptive`), in this process."""
    if args.workers is not None or args.cluster is not None or args.resume:
        raise DrptError("--adaptive renders in one process: --workers, --cluster and --resume "
                        "do not apply")
    renderer = Renderer(scene, opts)
    for w in renderer.warnings:
        warn(w)
    return Job(renderer.render())


def _strategies_job(scene, opts, output: Path, args):
    """A ``--bdpt-strategies`` render, in this process: the image, and each strategy's
    image as ``OUT.bdpt_dD_sS_tT.EXT`` (``D = s + t - 2`` bounces, pbrt-v4's names)."""
    renderer = Renderer(scene, opts)
    for w in renderer.warnings:
        warn(w)
    result = renderer.render()
    for (s, t), image in renderer.strategy_images(result.spp).items():
        name = f"{output.stem}.bdpt_d{s + t - 2}_s{s}_t{t}{output.suffix}"
        write_image(output.with_name(name), image, gamma=args.gamma)
    return Job(result)


def _aov_options(opts, args, output: Path):
    """``opts`` with ``--aovs`` and ``--denoise``: the flag's AOVs replace the scene's; AOVs
    need an .exr output (a scene's own are not traced for other formats); --denoise needs
    pyoidn (checked before rendering)."""

    exr = output.suffix.lower() == ".exr"
    if args.aovs is not None:
        if not exr:
            raise DrptError(f"--aovs: {output} holds no extra layers: write an .exr")
        opts = replace(opts, aovs=parse_aovs(args.aovs))
    elif opts.aovs and not exr:
        opts = replace(opts, aovs=())
    if args.denoise:
        require()
        opts = replace(opts, denoise=True)
    return opts


def _viewer(scene, opts, args, *, output: Path | None, final: bool):
    try:
        from ..view.server import Viewer  # optional: the 'view' extra (viser)
    except ImportError as e:
        raise DrptError(f"the viewer needs viser: pip install -e '.[view]' ({e})") from None
    camera_out = Path(args.camera_out) if args.camera_out else None
    viewer = Viewer(scene, opts, host=args.host, port=args.port, output=output,
                    camera_out=camera_out, gamma=args.gamma, final=final)
    print(f"drpt view: {viewer.url}", flush=True)
    return viewer


def _gui(scene, opts, args):
    """``render -gui``: the viewer until "render"; the scene with its camera
    and the options with its integrator, depth and accelerator."""
    viewer = _viewer(scene, opts, args, output=None, final=True)
    timeout = getattr(args, "gui_timeout", None)
    print("drpt render -gui: open that address in a browser and move the camera; the page's "
          "\"render\" button, or closing the page, starts the render with it (Ctrl-C stops). "
          + ("Without a browser it waits: --gui-timeout T renders the scene's camera after T s."
             if timeout is None else
             f"With no page open after {timeout:g} s it renders the scene's camera."), flush=True)
    timer = None
    if timeout is not None:
        def no_page() -> None:
            if not viewer.server.get_clients():
                note(f"no page opened the viewer within --gui-timeout {timeout:g} s: rendering "
                     "the scene's camera")
                viewer.request_render()

        timer = threading.Timer(timeout, no_page)
        timer.daemon = True
        timer.start()
    try:
        camera = viewer.wait()
        settings = viewer.settings()
    finally:
        if timer is not None:
            timer.cancel()
        viewer.close()
    return replace(scene, camera=camera), replace(settings, progress=opts.progress)


def cmd_view(args: argparse.Namespace) -> int:
    opts = options_from_args(args)
    if not (math.isfinite(args.gamma) and args.gamma > 0):
        raise DrptError(f"--gamma must be a positive finite number, got {args.gamma}")
    check_view_args(args)
    output = Path(args.output) if args.output else Path(Path(args.scene).stem + ".png")
    _check_output(output)
    scene = load_scene(args.scene)
    opts, scene = with_scene_settings(opts, scene, given_settings(args))
    ensure()
    viewer = _viewer(scene, opts, args, output=output, final=False)
    print(f"drpt view: open that address in a browser; its \"render\" button writes {output}; "
          "Ctrl-C stops the viewer", flush=True)
    try:
        viewer.wait()
    finally:
        viewer.close()
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    opts = options_from_args(args)
    if not args.output.strip():
        raise DrptError("the output is empty: give the .xml file to write")
    out = Path(args.output)
    if out.is_dir():
        raise DrptError(f"{out}: is a folder; give the .xml file to write")
    if out.suffix.lower() != ".xml":  # (an image name given where the scene goes)
        raise DrptError(f"{out}: the Mitsuba scene is written as an .xml file, not "
                        f"'{out.suffix or out.name}'")
    if str(out.parent) != "" and not out.parent.is_dir():  # render's rule: no folder is made
        raise DrptError(f"{out}: folder {out.parent} does not exist")
    scene = load_scene(args.scene)
    opts, scene = with_scene_settings(opts, scene, given_settings(args))
    if len(scene.triangles) + len(scene.spheres) + len(scene.planes) == 0:
        warn("the scene has no primitives (no triangles, spheres or planes): the Mitsuba "
             "scene has no shapes, only its background or sky")
    write_xml(scene, Path(args.output), width=opts.width, height=opts.height, spp=opts.spp,
              max_depth=opts.path.max_depth, rr_depth=opts.path.rr_depth, bsdf=opts.bsdf,
              rfilter=opts.filter, hide_emitters=opts.path.hide_emitters,
              sampler=resolve_sampler(opts).sampler)
    print(f"{args.output}: Mitsuba 3 scene written")
    return 0
