"""Command line: ``python -m drpt <command> ...``.

``render`` accepts modern options and, unchanged, the seed renderer's own
flags (``-input scene.txt -size 800 800 -output x.tga -spp 64 -MonteCarlo
-cook_torrance -RR_cutdown 0.6 -Gamma 2.2 -SpatialTree -resolution 5
-SAHeuristic 2000 -gui``; ``-gui`` opens the viewer of ``drpt view`` first and
renders with the camera the user left it at). With ``-input`` the seed's defaults apply (Whitted
ray tracing, Phong shading, uniform grid; with ``-SpatialTree`` its BVH rule,
SAH only in nodes of at most ``2 * 2000`` primitives); otherwise drpt's (MIS
path tracing, the ``auto`` accelerator). A flag whose feature is not built yet
says so in one line. The render flags, shared with every tool, and their
checks live in :mod:`drpt.options`.

``--backend llvm|cuda`` (or ``$DRPT_BACKEND``) chooses the Dr.Jit backend
before any kernel is imported (:func:`select_backend`).

User mistakes print one line and exit with status 2; no traceback. Warnings
print one line each (:func:`drpt.errors.warn`).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from dataclasses import replace
from pathlib import Path

from .errors import DrptError, note, showwarning, warn
from .options import check_view_args

#: the most local worker processes --workers starts per core (each is a Python
#: process with its own copy of the scene and its own compiled kernels)
WORKERS_PER_CORE = 4


def _add_render_args(p: argparse.ArgumentParser) -> None:
    from .options import add_render_flags

    p.add_argument("scene", nargs="?", help="scene file (the seed's text format, or Mitsuba XML: .xml)")
    p.add_argument("--input", "-input", dest="input", help="scene file (seed flag)")
    p.add_argument("--output", "-output", "-o", dest="output",
                   help="image to write, its type from the extension: .exr, .hdr or .pfm "
                        "(linear float), .png or .tga (8-bit, gamma); default <scene>.png")
    add_render_flags(p, seed_flags=True)
    from .options import add_distributed_flags

    add_distributed_flags(p)
    p.add_argument("--gamma", "-Gamma", dest="gamma", type=float, default=2.2,
                   help="display gamma for .png/.tga (default 2.2)")
    p.add_argument("-gui", "--gui", dest="gui", action="store_true",
                   help="seed flag: move the camera in the viewer (as drpt view) first; "
                        "its \"render\" button (or closing the page) starts the render")
    p.add_argument("--gui-timeout", dest="gui_timeout", type=float, default=None, metavar="T",
                   help="with -gui: start the render with the scene's camera when no page is "
                        "open T seconds after the viewer starts (default: wait for a page)")
    from .options import add_view_flags

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


def _check_output(output: Path) -> None:
    """Fail before rendering, not after, on an output drpt cannot write."""
    from .imageio import WRITE_EXTENSIONS

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
    import numpy as np

    from .render.renderer import SRGB_TO_XYZ

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
    from .aovs import split

    layers, _ = split(opts.aovs, opts.denoise, result.aov)
    name = getattr(getattr(scene, "settings", None), "aov_image", None)
    if name and opts.aovs:
        layers = {**{f"{name}.{c}": result.image[..., i] for i, c in enumerate("RGB")}, **layers}
    return layers


def cmd_render(args: argparse.Namespace) -> int:
    from .backend import ensure
    from .distributed import checkpoint
    from .distributed.job import print_workers, run
    from .imageio import write_image
    from .options import apply_scene_settings, options_from_args
    from .scene import load_scene

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
    opts = apply_scene_settings(opts, scene, args)
    opts = _aov_options(opts, args, output)
    if args.bdpt_strategies:
        opts = replace(opts, bdpt_strategies=True).validate()
        if args.workers is not None or args.cluster is not None or args.resume or opts.adaptive:
            raise DrptError("--bdpt-strategies renders in one process: --workers, --cluster, --resume "
                            "and --adaptive do not apply")

    if args.workers is not None and args.cluster is not None:
        raise DrptError("give --workers N (a local cluster) or --cluster ADDRESS, not both")
    most = WORKERS_PER_CORE * max(2, os.cpu_count() or 1)
    if args.workers is not None and not 1 <= args.workers <= most:
        raise DrptError(f"--workers must be between 1 and {most} ({WORKERS_PER_CORE} local worker "
                        f"processes per core), got {args.workers}")
    if args.cluster is not None:
        from .distributed.engine import check_address

        check_address(args.cluster)
    if not (math.isfinite(args.checkpoint_seconds) and args.checkpoint_seconds >= 0):
        raise DrptError(f"--checkpoint-seconds must be >= 0, got {args.checkpoint_seconds}")

    from .memory import bytes_per_pixel
    from .memory import check as check_memory

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
        from .denoise import denoise_result, denoised_path

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
    print(f"{output}: {opts.width}x{opts.height}, {spp}, {result.seconds:.2f} s ({extra}), "
          f"{result.samples_per_second / 1e6:.2f} Msamples/s{stop}")
    if opts.progress and (args.workers is not None or args.cluster is not None):
        print_workers(job)
    return 0


def _adaptive_job(scene, opts, args):
    """An ``--adaptive`` render (:mod:`drpt.render.adaptive`), in this process."""
    from .distributed.job import Job
    from .render.renderer import Renderer

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
    from .distributed.job import Job
    from .imageio import write_image
    from .render.renderer import Renderer

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
    from dataclasses import replace

    from .aovs import parse_aovs

    exr = output.suffix.lower() == ".exr"
    if args.aovs is not None:
        if not exr:
            raise DrptError(f"--aovs: {output} holds no extra layers: write an .exr")
        opts = replace(opts, aovs=parse_aovs(args.aovs))
    elif opts.aovs and not exr:
        opts = replace(opts, aovs=())
    if args.denoise:
        from .denoise import require

        require()
        opts = replace(opts, denoise=True)
    return opts


def _viewer(scene, opts, args, *, output: Path | None, final: bool):
    try:
        from .view.server import Viewer
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
    import threading
    from dataclasses import replace

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
    from .backend import ensure
    from .options import apply_scene_settings, options_from_args
    from .scene import load_scene

    opts = options_from_args(args)
    if not (math.isfinite(args.gamma) and args.gamma > 0):
        raise DrptError(f"--gamma must be a positive finite number, got {args.gamma}")
    check_view_args(args)
    output = Path(args.output) if args.output else Path(Path(args.scene).stem + ".png")
    _check_output(output)
    scene = load_scene(args.scene)
    opts = apply_scene_settings(opts, scene, args)
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
    from .export.mitsuba import write_xml
    from .options import apply_scene_settings, options_from_args
    from .scene import load_scene

    opts = options_from_args(args)
    if not args.output.strip():
        raise DrptError("the output is empty: give the .xml file to write")
    out = Path(args.output)
    if str(out.parent) != "" and not out.parent.is_dir():  # render's rule: no folder is made
        raise DrptError(f"{out}: folder {out.parent} does not exist")
    scene = load_scene(args.scene)
    opts = apply_scene_settings(opts, scene, args)
    if len(scene.triangles) + len(scene.spheres) + len(scene.planes) == 0:
        warn("the scene has no primitives (no triangles, spheres or planes): the Mitsuba "
             "scene has no shapes, only its background or sky")
    write_xml(scene, Path(args.output), width=opts.width, height=opts.height, spp=opts.spp,
              max_depth=opts.path.max_depth, rr_depth=opts.path.rr_depth, bsdf=opts.bsdf,
              rfilter=opts.filter, hide_emitters=opts.path.hide_emitters)
    print(f"{args.output}: Mitsuba 3 scene written")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with drpt's error format: one line, exit status 2 (argparse's
    own prints the whole usage first), naming the command whose ``--help`` to read;
    an unknown flag gets the closest known one ("did you mean"). No flag is
    abbreviated: neither ``--sp`` for ``--spp`` (``allow_abbrev=False``) nor, as
    argparse otherwise allows, ``-Monte`` for ``-MonteCarlo``."""

    def error(self, message: str):
        import difflib
        import re

        bad = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if bad:
            close = difflib.get_close_matches(bad.group(1), re.findall(r"'([^']*)'", bad.group(2)),
                                              n=1, cutoff=0.6)
            if close:
                message += f"; did you mean {close[0]}?"
        command = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        print(f"drpt: error: {command}{message} (see {self.prog} --help)", file=sys.stderr)
        sys.exit(2)

    def _get_option_tuples(self, option_string):
        # single-dash flags: only a one-letter flag with its value attached (-Dname=value,
        # -oout.png), never a prefix of a longer flag (argparse's default)
        found = super()._get_option_tuples(option_string)
        if option_string[:2] != "--":
            found = [t for t in found if t[1] == option_string[:2]]
        return found

    def parse_args(self, args=None, namespace=None):
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            target = self
            for action in self._actions:
                if isinstance(action, argparse._SubParsersAction):
                    target = action.choices.get(getattr(ns, "command", None), self)
            target.error(_unrecognized(target, extras))
        return ns


def _unrecognized(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """``unrecognized arguments: ...``, with the closest flag of ``parser`` for each
    unknown flag among them."""
    import difflib

    known = [o for a in parser._actions for o in a.option_strings]
    hints = []
    for arg in extras:
        if arg.startswith("-") and len(arg) > 1:
            name = arg.split("=", 1)[0]
            close = ([o for o in known if o.startswith(name)]
                     or difflib.get_close_matches(name, known, n=1, cutoff=0.6))
            if close:
                hints.append(f"{arg}: did you mean {close[0]}?")
    noun = "argument" if len(extras) == 1 else "arguments"
    return f"unrecognized {noun}: {' '.join(extras)}" + (f" ({'; '.join(hints)})" if hints else "")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="drpt", description=__doc__.split("\n")[0].replace("``", ""),
                     allow_abbrev=False)
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render a scene to an image", allow_abbrev=False)
    _add_render_args(render)
    render.set_defaults(func=cmd_render)

    view = sub.add_parser("view", help="look at a scene in the browser, progressively path traced",
                          allow_abbrev=False)
    view.add_argument("scene", help="scene file (the seed's text format, or Mitsuba XML: .xml)")
    view.add_argument("--output", "-o", dest="output", default=None,
                      help="image that the page's \"render\" writes (default <scene>.png)")
    from .options import add_render_flags, add_view_flags

    add_render_flags(view)
    add_view_flags(view)
    view.add_argument("--gamma", type=float, default=2.2, help="display gamma (default 2.2)")
    view.set_defaults(func=cmd_view)

    export = sub.add_parser("export", help="write the scene as Mitsuba 3 XML plus meshes",
                            allow_abbrev=False)
    export.add_argument("scene")
    export.add_argument("output", help="the .xml file to write (meshes go beside it)")
    from .options import add_render_flags

    # the flags of render that shape the Mitsuba scene, checked as render checks them
    add_render_flags(export, omit=("seed", "rr_depth", "rr_prob", "accel", "integrator", "mode",
                                   "env_sampling", "max_lanes", "backend", "quiet"))
    export.set_defaults(func=cmd_export)

    from .tools.compare import add_parser as add_compare_parser

    add_compare_parser(sub)
    from .tools.gallery import add_parser as add_gallery_parser

    add_gallery_parser(sub)
    from .tools.profile import add_parser as add_profile_parser

    add_profile_parser(sub)
    from .tools.bench import add_parser as add_bench_parser

    add_bench_parser(sub)
    from .tools.converge import add_parser as add_converge_parser

    add_converge_parser(sub)
    from .tools.knobs import add_parser as add_knobs_parser

    add_knobs_parser(sub)
    return parser


def select_backend(argv: list[str]) -> None:
    """Choose the Dr.Jit backend before any kernel module is imported.

    ``--backend NAME`` in ``argv`` wins over ``$DRPT_BACKEND`` (which
    ``import drpt`` already applied). Kernel modules bind ``drjit.auto``'s
    types when imported, and building the parser imports the accelerator
    vocabulary, so this runs first. A CUDA backend is checked at once
    (:func:`drpt.backend.ensure`): without a GPU the command stops before it
    reads or writes anything. LLVM is checked by the commands that render."""
    from . import backend

    pre = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    pre.add_argument("--backend", default=None)
    known, _ = pre.parse_known_args(argv)
    if known.backend is not None:
        backend.select(known.backend)
    if backend.name() != "llvm":
        backend.ensure()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    with warnings.catch_warnings():
        # Python warnings (scene and export notices) print on one line, as drpt's own.
        warnings.showwarning = showwarning
        try:
            select_backend(argv)
            args = build_parser().parse_args(argv)
            from .options import scene_flags
            from .scene import xml_flags

            with xml_flags(**scene_flags(args)):
                return args.func(args)
        except DrptError as e:
            print(f"drpt: error: {e}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("drpt: interrupted", file=sys.stderr)
            return 130


if __name__ == "__main__":
    sys.exit(main())
