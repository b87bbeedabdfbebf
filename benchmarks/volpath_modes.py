"""volpath's megakernel against its wavefront (not a test).

Renders SCENE (a drpt scene with media, or a Mitsuba XML file with its own settings, e.g.
a corpus ``participating_media/`` scene) with ``--integrator volpath`` as one megakernel,
as the wavefront, and as the wavefront with ``--wavefront-tail TAIL``, interleaved in one
process for ROUNDS rounds (the same seed each round, after one warm-up render of each
way that compiles its kernels), and prints each way's median and best seconds and its
ratio to the megakernel's median (> 1: slower than the megakernel).

Run: PYTHONPATH=. .venv/bin/python benchmarks/volpath_modes.py SCENE [SIZE] [SPP] [ROUNDS] [TAIL]
(defaults 128, 16, 5, 16384; SIZE x SIZE also for an XML file).
"""

from __future__ import annotations

import statistics
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path


def main(argv: list[str]) -> None:
    from drpt.backend import ensure
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    path = Path(argv[0])
    size = int(argv[1]) if len(argv) > 1 else 128
    spp = int(argv[2]) if len(argv) > 2 else 16
    rounds = int(argv[3]) if len(argv) > 3 else 5
    tail = int(argv[4]) if len(argv) > 4 else 16384
    ensure()
    warnings.simplefilter("ignore")
    xml = path.suffix == ".xml"
    scene = load_scene(path, defines={"spp": str(spp)}) if xml else load_scene(path)
    base = with_scene_settings(RenderOptions(progress=False), scene)[0] if xml else RenderOptions(progress=False)
    base = replace(base, width=size, height=size, spp=spp, integrator="volpath", seed=1)
    ways = {"megakernel": base, "wavefront": replace(base, mode="wavefront"),
            f"wavefront, tail {tail}": replace(base, mode="wavefront", wavefront_tail=tail)}
    renderers = {name: Renderer(scene, opts) for name, opts in ways.items()}
    for r in renderers.values():
        r.render()  # warm-up: compiles the kernels
    times: dict[str, list[float]] = {name: [] for name in ways}
    for _ in range(rounds):
        for name, r in renderers.items():
            t0 = time.perf_counter()
            r.render()
            times[name].append(time.perf_counter() - t0)
    mk = statistics.median(times["megakernel"])
    print(f"{path.name}: {size}x{size}, {spp} spp, {rounds} interleaved rounds")
    for name, ts in times.items():
        med = statistics.median(ts)
        print(f"  {name:24s} median {med:.3f} s  best {min(ts):.3f} s  ({med / mk:.2f}x the megakernel's)")


if __name__ == "__main__":
    main(sys.argv[1:])
