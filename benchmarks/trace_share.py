"""How much of a path-traced frame the ray queries take (not a test).

Renders SCENE three ways, interleaved in one process, ROUNDS rounds: as is; with every
closest-hit query traced twice (the nearer hit kept: the same image); and with every
shadow query traced twice. The second query's ray is the first's times an opaque 1.0,
so Dr.Jit cannot merge the two (an inline accelerator's tests are straight-line code,
which Dr.Jit's value numbering would otherwise share between equal queries). The extra
time of each doubled render is the time of that kind of query in the frame. Prints the
best and median render seconds of each.

Run: PYTHONPATH=. .venv/bin/python benchmarks/trace_share.py SCENE [ROUNDS] [ACCEL] [SIZE] [SPP]
(defaults 6, bvh, 150, 4; material mode cook-torrance).
"""

from __future__ import annotations

import statistics
import sys

import drjit as dr
from drjit.auto import Array3f, Float

from drpt.options import RenderOptions
from drpt.render import scene as device_scene
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

DeviceScene = device_scene.DeviceScene
ONCE = (DeviceScene.intersect_preliminary, DeviceScene.occluded)


def _copy(o, d):
    """The ray ``(o, d)`` again, as new variables: times an opaque 1.0."""
    one = dr.opaque(Float, 1.0)
    return Array3f(o) * one, Array3f(d) * one


def closest_twice(self, o, d, active, *args, **kw):
    h1 = ONCE[0](self, o, d, active, *args, **kw)
    h2 = ONCE[0](self, *_copy(o, d), active, *args, **kw)
    return dr.select(h2.t < h1.t, h2, h1)


def shadow_twice(self, o, d, tmax, active, *args, **kw):
    return ONCE[1](self, o, d, tmax, active, *args, **kw) | ONCE[1](self, *_copy(o, d), tmax, active, *args, **kw)


VARIANTS = {"as is": ONCE, "closest hit twice": (closest_twice, ONCE[1]),
            "shadow twice": (ONCE[0], shadow_twice)}


def main(argv: list[str]) -> None:
    scene = load_scene(argv[0])
    rounds = int(argv[1]) if len(argv) > 1 else 6
    accel = argv[2] if len(argv) > 2 else "bvh"
    size = int(argv[3]) if len(argv) > 3 else 150
    spp = int(argv[4]) if len(argv) > 4 else 4
    opts = RenderOptions(width=size, height=size, spp=spp, accel=accel, bsdf="cook-torrance",
                         progress=False).validate()
    renderers = {k: Renderer(scene, opts) for k in VARIANTS}

    def render(k):
        # the kernels are traced at every render: patch around each one
        DeviceScene.intersect_preliminary, DeviceScene.occluded = VARIANTS[k]
        try:
            return renderers[k].render().seconds
        finally:
            DeviceScene.intersect_preliminary, DeviceScene.occluded = ONCE

    for k in VARIANTS:
        render(k)  # compile
    times = {k: [] for k in VARIANTS}
    for r in range(rounds):
        for k in (list(VARIANTS) if r % 2 == 0 else list(reversed(VARIANTS))):
            times[k].append(render(k))
    for k, t in times.items():
        print(f"{k:18s} best {min(t):.3f} s  median {statistics.median(t):.3f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
