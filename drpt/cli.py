"""Command line: ``python -m drpt <command> ...``.

``render`` accepts modern options and, unchanged, the seed renderer's own
flags (``-input scene.txt -size 800 800 -output x.tga -spp 64 -MonteCarlo
-cook_torrance -RR_cutdown 0.6 -Gamma 2.2 -SpatialTree -resolution 5
-SAHeuristic 2000 -gui``). With ``-input`` the seed's defaults apply (Whitted
ray tracing, Phong shading, uniform grid; with ``-SpatialTree`` its BVH rule,
SAH only in nodes of at most ``2 * 2000`` primitives); otherwise drpt's (MIS
path tracing, BVH with full binned SAH). A flag whose feature is not built yet
says so in one line.

User mistakes print one line and exit with status 2; no traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import DrptError

# Features that are accepted but arrive in later work, with the issue that
# brings them. The message is printed once, in one line.
LATER = {
    "gui": "drpt has no OpenGL preview (-gui): it renders straight to the output file",
}


def _note(key: str) -> None:
    print(f"drpt: note: {LATER[key]}", file=sys.stderr)


def _add_render_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="?", help="scene file (the seed's text format)")
    p.add_argument("--input", "-input", dest="input", help="scene file (seed flag)")
    p.add_argument("--output", "-output", "-o", dest="output",
                   help="image to write: .exr (linear float32), .png or .tga (gamma); "
                        "default <scene>.png")
    p.add_argument("--size", "-size", nargs=2, type=int, metavar=("W", "H"), default=None,
                   help="image size in pixels (default 512 512)")
    p.add_argument("--spp", "-spp", type=int, default=None, help="samples per pixel (default 64)")
    p.add_argument("--max-depth", type=int, default=-1,
                   help="longest path in segments, Mitsuba's convention: 1 = emitters only, "
                        "2 = direct light, -1 = unbounded (default)")
    p.add_argument("--rr-depth", type=int, default=5,
                   help="depth at which Russian roulette starts (default 5)")
    p.add_argument("--rr-prob", type=float, default=None,
                   help="fixed path continuation probability for Russian roulette "
                        "(default: adaptive, min(throughput, 0.95))")
    p.add_argument("-RR_cutdown", dest="rr_cutdown", type=float, default=None,
                   help="seed flag: fixed continuation probability p at every bounce")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--accel", choices=["auto", "bvh", "bvh2", "bvh4", "grid", "inline", "brute"],
                   default=None,
                   help="acceleration structure: auto (default: inline up to 64 primitives, "
                        "else bvh), inline (every primitive compiled into the kernel as "
                        "constants), bvh (4-wide BVH; alias bvh4), "
                        "bvh2 (the binary BVH it is collapsed from: 2-3x slower, for "
                        "comparison), grid (uniform grid, 3D-DDA; -resolution N cells per "
                        "axis) or brute")
    p.add_argument("--bvh", dest="bvh_method", metavar="auto|sah|median|threshold|morton|ploc",
                   default=None,
                   help="BVH build rule: auto (default: sah up to 100k primitives, ploc "
                        "above), sah (binned SAH everywhere: best trees, slowest build), "
                        "median (object median), threshold (the seed's: SAH only in nodes of "
                        "at most 2K primitives, median above; K from --sah-threshold), "
                        "morton (Morton-ordered binned SAH: fast build) or ploc (bottom-up "
                        "clustering in Morton order: fast build, trees close to sah's)")
    p.add_argument("--sah-threshold", "-SAHeuristic", "-SAH", dest="sah_threshold",
                   metavar="K", default=None,
                   help="K of --bvh threshold (implies it; 0 = median everywhere; default 2000, "
                        "the seed's)")
    p.add_argument("--min-leaf", dest="min_leaf", metavar="N", default=None,
                   help="minimum primitives per BVH leaf (default 1)")
    p.add_argument("-SpatialTree", dest="spatial_tree", action="store_true",
                   help="seed flag: use the BVH (the seed's default is the grid)")
    p.add_argument("-resolution", dest="resolution", metavar="N", default=None,
                   help="seed flag: grid cells per axis, or with the BVH its minimum leaf size "
                        "(as --min-leaf)")
    p.add_argument("--integrator", choices=["path", "whitted"], default=None,
                   help="path (MIS path tracing, default) or whitted")
    p.add_argument("-MonteCarlo", dest="monte_carlo", action="store_true",
                   help="seed flag: Monte Carlo path tracing (the seed's default is Whitted)")
    p.add_argument("--bsdf", choices=["diffuse", "phong", "cook-torrance"], default=None,
                   help="how MTL materials are read: phong (Kd, Ks, Ns; default) or "
                        "cook-torrance (Kd, Roughness, Metalness); diffuse uses Kd only")
    p.add_argument("-cook_torrance", dest="cook_torrance", action="store_true",
                   help="seed flag: Cook-Torrance shading")
    p.add_argument("--env-sampling", choices=["luminance", "uniform"], default="luminance",
                   help="how sky directions are sampled: by luminance (default) or uniformly "
                        "over the sphere (for comparison)")
    p.add_argument("--gamma", "-Gamma", dest="gamma", type=float, default=2.2,
                   help="display gamma for .png/.tga (default 2.2)")
    p.add_argument("-gui", dest="gui", action="store_true", help="seed flag: OpenGL preview")
    p.add_argument("--max-lanes", type=int, default=1 << 21,
                   help="samples traced at once; bounds memory (default 2097152)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")


def _check_output(output: Path) -> None:
    """Fail before rendering, not after, on an output drpt cannot write."""
    from .imageio import WRITE_EXTENSIONS

    if output.suffix.lower() not in WRITE_EXTENSIONS:
        raise DrptError(f"{output}: unsupported image type '{output.suffix}' "
                        f"(use one of {', '.join(sorted(WRITE_EXTENSIONS))})")
    if not output.parent.exists() and str(output.parent) != "":
        raise DrptError(f"{output}: folder {output.parent} does not exist")


def _int_flag(name: str, text: str | None) -> int | None:
    """Parse an integer flag value; a bad one is a one-line DrptError."""
    if text is None:
        return None
    try:
        return int(text)
    except ValueError:
        raise DrptError(f"{name} must be an integer, got {text!r}") from None


def _bvh_options(args: argparse.Namespace, accel: str, seed_mode: bool) -> dict:
    """RenderOptions fields for the BVH build rule from the render flags."""
    from .accel import METHODS, NO_MIN_LEAF

    resolution = _int_flag("-resolution", args.resolution)
    k = _int_flag("--sah-threshold/-SAHeuristic", args.sah_threshold)
    min_leaf = _int_flag("--min-leaf", args.min_leaf)
    if accel not in ("bvh", "bvh2", "bvh4"):
        if args.bvh_method is not None or min_leaf is not None:
            raise DrptError("--bvh and --min-leaf apply to the BVH only "
                            "(--accel bvh, or -SpatialTree with -input)")
        if k is not None:
            print("drpt: note: -SAHeuristic applies to the BVH (-SpatialTree); "
                  f"ignored with --accel {accel}", file=sys.stderr)
        if resolution is not None and accel == "grid" and not 1 <= resolution <= 256:
            raise DrptError(f"-resolution must be between 1 and 256 grid cells per axis, "
                            f"got {resolution}")
        return {"grid_resolution": resolution if accel == "grid" else None}
    if args.bvh_method is not None and args.bvh_method not in METHODS:
        raise DrptError(f"--bvh must be one of {', '.join(METHODS)}, got {args.bvh_method!r}")
    # With -input the seed's default BVH is its threshold rule (-SAHeuristic 2000).
    method = args.bvh_method or ("threshold" if (k is not None or seed_mode) else "auto")
    if k is not None and method != "threshold":
        raise DrptError(f"--sah-threshold/-SAHeuristic applies to --bvh threshold, "
                        f"not --bvh {method}")
    if k is not None and k < 0:
        raise DrptError(f"--sah-threshold/-SAHeuristic must be >= 0, got {k}")
    if min_leaf is not None and resolution is not None and min_leaf != resolution:
        raise DrptError(f"--min-leaf {min_leaf} and -resolution {resolution} disagree: "
                        "with the BVH both give the minimum leaf size, give one")
    if min_leaf is None:
        min_leaf = resolution
    if min_leaf is not None and min_leaf < 1:
        name = "--min-leaf" if args.min_leaf is not None else "-resolution"
        raise DrptError(f"{name} (minimum primitives per BVH leaf) must be >= 1, got {min_leaf}")
    if method in NO_MIN_LEAF and min_leaf not in (None, 1):
        raise DrptError("--min-leaf/-resolution applies to --bvh sah, median and threshold, "
                        f"not {method}")
    return {"bvh_method": method, "sah_threshold": k,
            "bvh_min_leaf": min_leaf if min_leaf is not None else 1}


def _positive(name: str, value: int | float | None) -> None:
    if value is not None and value <= 0:
        raise DrptError(f"{name} must be positive, got {value}")


def cmd_render(args: argparse.Namespace) -> int:
    from .backend import ensure
    from .imageio import write_image
    from .options import PathOptions
    from .options import RenderOptions
    from .render.renderer import Renderer
    from .scene import load_scene

    scene_path = args.scene or args.input
    if not scene_path:
        raise DrptError("no scene given: drpt render SCENE (or -input SCENE)")
    if args.scene and args.input:
        raise DrptError("give the scene once, either as SCENE or as -input")
    seed_mode = args.input is not None

    width, height = args.size or (512, 512)
    spp = args.spp if args.spp is not None else 64
    _positive("size", min(width, height))
    _positive("spp", spp)
    _positive("--max-lanes", args.max_lanes)
    if args.max_depth == 0 or args.max_depth < -1:
        raise DrptError(f"--max-depth must be -1 (unbounded) or >= 1, got {args.max_depth}")
    if not (args.gamma > 0):
        raise DrptError(f"gamma must be positive, got {args.gamma}")
    rr_prob = args.rr_prob
    rr_depth = args.rr_depth
    if args.rr_cutdown is not None:
        rr_prob, rr_depth = args.rr_cutdown, 1
    if rr_prob is not None and not (0.0 < rr_prob <= 1.0):
        raise DrptError(f"Russian roulette probability must be in (0, 1], got {rr_prob}")

    integrator = args.integrator or ("path" if (args.monte_carlo or not seed_mode) else "whitted")
    # flags that shape a BVH ask for one rather than the inline accelerator
    bvh_flags = any(f is not None for f in (args.bvh_method, args.min_leaf, args.sah_threshold,
                                            args.resolution))
    accel = args.accel or ("grid" if seed_mode and not args.spatial_tree
                           else "bvh" if args.spatial_tree else "auto")
    if accel == "auto" and bvh_flags:
        accel = "bvh"
    bsdf = args.bsdf or ("cook-torrance" if args.cook_torrance else "phong")
    accel_opts = _bvh_options(args, accel, seed_mode)
    if args.gui:
        _note("gui")

    output = Path(args.output) if args.output else Path(Path(scene_path).stem + ".png")
    _check_output(output)
    scene = load_scene(scene_path)

    ensure()
    opts = RenderOptions(width=width, height=height, spp=spp, seed=args.seed, accel=accel,
                         **accel_opts, bsdf=bsdf, integrator=integrator,
                         env_sampling=args.env_sampling,
                         path=PathOptions(max_depth=args.max_depth, rr_depth=rr_depth,
                                          rr_prob=rr_prob),
                         max_lanes=args.max_lanes, progress=not args.quiet)
    renderer = Renderer(scene, opts)
    for message in renderer.warnings:
        print(f"drpt: warning: {message}", file=sys.stderr)
    result = renderer.render()
    if result.nonfinite:
        print(f"drpt: warning: {result.nonfinite} samples were NaN/Inf and were set to 0",
              file=sys.stderr)
    write_image(output, result.image, gamma=args.gamma)
    print(f"{output}: {width}x{height}, {spp} spp, {result.seconds:.2f} s "
          f"(+{result.build_seconds:.2f} s build), "
          f"{result.samples_per_second / 1e6:.2f} Msamples/s")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from .export.mitsuba import write_xml
    from .scene import load_scene

    scene = load_scene(args.scene)
    width, height = args.size
    write_xml(scene, Path(args.output), width=width, height=height, spp=args.spp,
              max_depth=args.max_depth, bsdf=args.bsdf)
    print(f"{args.output}: Mitsuba 3 scene written")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="drpt", description=__doc__.split("\n")[0],
                                     allow_abbrev=False)
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render a scene to an image", allow_abbrev=False)
    _add_render_args(render)
    render.set_defaults(func=cmd_render)

    export = sub.add_parser("export", help="write the scene as Mitsuba 3 XML plus meshes",
                            allow_abbrev=False)
    export.add_argument("scene")
    export.add_argument("output", help="the .xml file to write (meshes go beside it)")
    export.add_argument("--size", nargs=2, type=int, default=(512, 512), metavar=("W", "H"))
    export.add_argument("--spp", type=int, default=64)
    export.add_argument("--max-depth", type=int, default=-1)
    export.add_argument("--bsdf", choices=["phong", "cook-torrance", "diffuse"], default="phong",
                        help="how MTL materials are read (as for render)")
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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except DrptError as e:
        print(f"drpt: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("drpt: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
