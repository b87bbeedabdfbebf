"""Path-tracing throughput of drpt vs Mitsuba 3 on the bundled scenes, same run.

Each renderer renders once to compile (warm-up), then three times timed (the
best counts: the machine may be shared); the ratio is drpt samples/s over
Mitsuba samples/s at equal size, spp and depth. ``accels`` (comma-separated
``build_accel`` kinds, default ``auto``) renders with each accelerator in turn,
next to the same Mitsuba timing, e.g. ``bvh,bvh2`` for the 4-wide (default) and binary BVH.

    .venv/bin/python benchmarks/render_vs_mitsuba.py [size] [spp] [accels]
"""

import sys
import time
from pathlib import Path

import drjit as dr

ROOT = Path(__file__).resolve().parents[1]
SCENES = [("scenes/cornellbox/cornellbox.txt", "phong"),
          ("scenes/newscene/newscene.txt", "cook-torrance")]


def main(size=256, spp=64, accels="auto"):
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.options import PathOptions
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    print("| scene | depth | accel | drpt Msamples/s | Mitsuba Msamples/s | ratio |\n"
          "|---|---|---|---|---|---|")
    for path, mode in SCENES:
        scene = load_scene(ROOT / path)
        for depth in (8, -1):
            rates = {}
            for accel in accels.split(","):
                r = Renderer(scene, RenderOptions(width=size, height=size, spp=spp, bsdf=mode,
                                                  accel=accel, progress=False,
                                                  path=PathOptions(max_depth=depth)))
                r.render()
                rates[accel] = max(r.render().samples_per_second for _ in range(3))
            ms = mi.load_dict(to_mitsuba_dict(scene, size, size, spp, max_depth=depth, bsdf=mode))
            dr.eval(mi.render(ms, spp=spp))
            best = float("inf")
            for seed in (1, 2, 3):
                dr.sync_thread()
                t0 = time.perf_counter()
                dr.eval(mi.render(ms, spp=spp, seed=seed))
                dr.sync_thread()
                best = min(best, time.perf_counter() - t0)
            mi_rate = size * size * spp / best
            for accel, rate in rates.items():
                print(f"| {Path(path).name} | {depth} | {accel} | {rate / 1e6:.2f} "
                      f"| {mi_rate / 1e6:.2f} | {rate / mi_rate:.2f} |")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]), *sys.argv[3:4])
