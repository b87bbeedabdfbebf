"""The viewer's latency: time from a camera move to its first new frame, and
frames per second, at 256x256 and 1 spp per frame (not a timed test).

Measures what the viewer's render thread does per frame: a
:class:`~drpt.render.progressive.Progressive` reset to the moved camera, one
frame traced, and its 8-bit JPEG encoding as viser sends it. After warm-up
(the kernel compiled once) a move compiles nothing.

    python benchmarks/view_latency.py [SCENE ...] [--size 256] [--moves 10] [--frames 20]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

DEFAULT_SCENES = [REPO / "scenes" / "cornellbox" / "cornellbox.txt",
                  REPO / "scenes" / "diningroom" / "diningroom.txt"]  # python scenes/make_diningroom.py


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", type=Path, default=DEFAULT_SCENES)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--moves", type=int, default=10)
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args()

    from viser._image_encoding import cv2_imencode_with_fallback

    from drpt.options import RenderOptions
    from drpt.render.progressive import Progressive
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from drpt.view.server import display_image

    for path in args.scenes:
        if not path.exists():
            print(f"{path}: missing, skipped")
            continue
        scene = load_scene(path)
        opt = RenderOptions(width=args.size, height=args.size, spp=10**6, progress=False)
        t0 = time.perf_counter()
        renderer = Renderer(scene, opt)
        build = time.perf_counter() - t0
        prog = Progressive(renderer, scene.camera, opt)
        t0 = time.perf_counter()
        prog.step()
        first = time.perf_counter() - t0
        lo, hi = scene.bounds()
        step = 0.01 * float(np.linalg.norm(hi - lo)) if np.isfinite(lo).all() else 0.01
        from drpt.view.server import MOVING_SCALE

        small = replace(opt, width=args.size // MOVING_SCALE, height=args.size // MOVING_SCALE)
        prog.reset(scene.camera, small)
        prog.step()  # warm-up of the moving size's kernel
        times = {}
        for name, o in (("moving", small), ("still", opt)):
            latencies = times[name] = []
            for i in range(args.moves):
                cam = replace(scene.camera, center=tuple(np.asarray(scene.camera.center)
                                                         + np.array([step * (i % 2 * 2 - 1), 0, 0])))
                t0 = time.perf_counter()
                prog.reset(cam, o)
                frame = prog.step()
                cv2_imencode_with_fallback("jpeg", display_image(frame.image, 0.0, 2.2), 90, "rgb")
                latencies.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        for _ in range(args.frames):
            prog.step()
        fps = args.frames / (time.perf_counter() - t0)
        print(f"{path.name}: {args.size}x{args.size}, build {build:.2f} s, first frame (compiles) "
              f"{first:.2f} s, {fps:.1f} frames/s")
        for name, o in (("moving", small), ("still", opt)):
            lat = 1e3 * np.asarray(times[name])
            print(f"  move -> first frame at {o.width}x{o.height} ({name}): median {np.median(lat):.0f} ms "
                  f"(min {lat.min():.0f}, max {lat.max():.0f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
