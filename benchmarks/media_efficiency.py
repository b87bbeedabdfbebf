"""Equal-time efficiency of drpt's volpath against Mitsuba's volpath (not a test).

Renders SCENE (a Mitsuba XML file with its own settings, e.g. a corpus
``participating_media/`` scene, or a drpt scene with media, exported) with drpt's
``volpath`` and with Mitsuba's ``volpath`` and ``volpathmis`` (Dr.Jit's own LLVM
settings), interleaved in one process for ROUNDS rounds of one render each, each round
with another seed. Prints per way the median render seconds, wall and CPU (``time.process_time``:
all the process's threads, which moves less than wall time on a loaded machine), the mean
per-pixel variance across the rounds' images (at equal spp), the efficiency ``1 / (seconds *
variance)`` by each, and the ratios to Mitsuba's volpath.

Run: PYTHONPATH=. .venv/bin/python benchmarks/media_efficiency.py SCENE [SIZE] [SPP] [ROUNDS]
(defaults 64, 64, 8; SIZE is ignored for an XML file, which names its own film).
"""

from __future__ import annotations

import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def main(argv: list[str]) -> None:
    import mitsuba as mi

    from drpt import llvm_tuning
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    path = Path(argv[0])
    size = int(argv[1]) if len(argv) > 1 else 64
    spp = int(argv[2]) if len(argv) > 2 else 64
    rounds = int(argv[3]) if len(argv) > 3 else 8
    ensure()
    xml = path.suffix == ".xml"
    scene = load_scene(path, defines={"spp": str(spp)}) if xml else load_scene(path)
    base = RenderOptions(width=size, height=size, spp=spp, progress=False, integrator="volpath")
    if xml:
        base = replace(with_scene_settings(RenderOptions(progress=False), scene)[0], spp=spp,
                       integrator="volpath")
    drpt = Renderer(scene, base)
    set_mitsuba_variant()
    mits = {}
    with llvm_tuning.dr_default():
        for name in ("volpath", "volpathmis"):
            if xml:
                mits[name] = mi.load_file(str(path), spp=str(spp), integrator=name)
            else:
                d = to_mitsuba_dict(scene, base.width, base.height, spp, bsdf=base.bsdf)
                d["integrator"]["type"] = name
                mits[name] = mi.load_dict(d)
    ways = ["drpt volpath", *(f"mitsuba {n}" for n in mits)]
    times: dict[str, list[float]] = {k: [] for k in ways}
    cpu: dict[str, list[float]] = {k: [] for k in ways}
    images: dict[str, list[np.ndarray]] = {k: [] for k in ways}
    drpt.render()  # compile
    with llvm_tuning.dr_default():
        for ms in mits.values():
            mi.render(ms, spp=spp)
    for k in range(rounds):
        t, c = time.perf_counter(), time.process_time()
        img = drpt.derive(replace(drpt.opt, seed=k)).render().image
        times["drpt volpath"].append(time.perf_counter() - t)
        cpu["drpt volpath"].append(time.process_time() - c)
        images["drpt volpath"].append(img.astype(np.float64))
        for name, ms in mits.items():
            with llvm_tuning.dr_default():
                t, c = time.perf_counter(), time.process_time()
                img = np.asarray(mi.render(ms, spp=spp, seed=k), np.float64)[..., :3]
                times[f"mitsuba {name}"].append(time.perf_counter() - t)
                cpu[f"mitsuba {name}"].append(time.process_time() - c)
                images[f"mitsuba {name}"].append(img)
    out = {}
    for name in ways:
        sec, cs = statistics.median(times[name]), statistics.median(cpu[name])
        var = float(np.stack(images[name]).var(0, ddof=1).mean())
        out[name] = (sec, cs, var, 1.0 / (sec * var), 1.0 / (cs * var))
    m = out["mitsuba volpath"]
    print(f"{path.name}: {base.width}x{base.height}, {spp} spp, {rounds} rounds")
    for name, (sec, cs, var, eff, ceff) in out.items():
        print(f"  {name:18s} {sec:7.3f} s (CPU {cs:7.3f} s)  variance {var:.4g} ({var / m[2]:.2f}x Mitsuba "
              f"volpath's)  efficiency {eff / m[3]:.2f}x Mitsuba volpath's (by CPU {ceff / m[4]:.2f}x)")


if __name__ == "__main__":
    main(sys.argv[1:])
