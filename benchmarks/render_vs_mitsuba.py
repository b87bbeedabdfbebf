"""Path-tracing throughput of drpt vs Mitsuba 3 on the bundled scenes, same run.

Each renderer renders once to compile (warm-up), then three times timed (the
best counts: the machine may be shared); the ratio is drpt samples/s over
Mitsuba samples/s at equal size, spp and depth. ``accels`` (comma-separated
accelerator names of :func:`drpt.options.parse_accel`, default ``auto``) renders
with each accelerator in turn, next to the same Mitsuba timing, e.g. ``bvh,bvh2``
for the 4-wide (default) and binary BVH, or ``bvh-sah,bvh-ploc`` for two build rules.

    .venv/bin/python benchmarks/render_vs_mitsuba.py [size] [spp] [accels]
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = [("scenes/cornellbox/cornellbox.txt", "phong"),
          ("scenes/newscene/newscene.txt", "cook-torrance")]


def main(size=256, spp=64, accels="auto"):
    from drpt import llvm_tuning
    from drpt.backend import set_mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.options import PathOptions, RenderOptions, parse_accel, parse_accel_list
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from drpt.tools.bench import mitsuba_render_seconds

    mi = set_mitsuba_variant()

    print("| scene | depth | accel | drpt Msamples/s | Mitsuba Msamples/s | ratio |\n"
          "|---|---|---|---|---|---|")
    for path, mode in SCENES:
        scene = load_scene(ROOT / path)
        for depth in (8, -1):
            rates = {}
            for accel in parse_accel_list(accels):
                kind, rule = parse_accel(accel)
                opts = RenderOptions(width=size, height=size, spp=spp, bsdf=mode, accel=kind,
                                     bvh_method=rule or "auto", progress=False,
                                     path=PathOptions(max_depth=depth)).validate()
                r = Renderer(scene, opts)
                r.render()
                rates[accel] = max(r.render().samples_per_second for _ in range(3))
            with llvm_tuning.dr_default():  # Mitsuba as it ships
                ms = mi.load_dict(to_mitsuba_dict(scene, size, size, spp, max_depth=depth, bsdf=mode))
                best = mitsuba_render_seconds(ms, spp, 3)
            mi_rate = size * size * spp / best
            for accel, rate in rates.items():
                print(f"| {Path(path).name} | {depth} | {accel} | {rate / 1e6:.2f} "
                      f"| {mi_rate / 1e6:.2f} | {rate / mi_rate:.2f} |")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]), *sys.argv[3:4])
