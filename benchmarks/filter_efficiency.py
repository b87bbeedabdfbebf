"""Equal-spp noise and equal-time efficiency of the pixel filters (not a test).

Renders SCENE (drpt's format, or a Mitsuba XML file with its own settings) with a
tent or Gaussian filter three ways, interleaved in one process for ROUNDS rounds of
one render each: drpt's splatting film (the default), drpt's filter importance
sampling (``--filter-sampling``) and Mitsuba (the exported scene, or the XML file
itself, with Dr.Jit's own LLVM settings). Each round uses another seed. Prints per
way the median render seconds, the mean per-pixel variance across the rounds'
images (at equal spp) and the efficiency ``1 / (seconds * variance)``, and the
ratios to Mitsuba. Where a few pixels carry most of the variance (a light's edge on the
Cornell box) 8 rounds move the variance ratio by about 10%: ``variance_vs_mitsuba.py``
gives it with its standard error.

Run: PYTHONPATH=. .venv/bin/python benchmarks/filter_efficiency.py SCENE [FILTER] [SIZE] [SPP] [ROUNDS]
(defaults gaussian, 128, 64, 8; FILTER is ignored for an XML file, which names its own).
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
    flt = argv[1] if len(argv) > 1 else "gaussian"
    size = int(argv[2]) if len(argv) > 2 else 128
    spp = int(argv[3]) if len(argv) > 3 else 64
    rounds = int(argv[4]) if len(argv) > 4 else 8
    ensure()
    xml = path.suffix == ".xml"
    scene = load_scene(path, defines={"spp": str(spp)}) if xml else load_scene(path)
    base = RenderOptions(width=size, height=size, spp=spp, filter=flt, progress=False)
    if xml:
        base = replace(with_scene_settings(RenderOptions(progress=False), scene)[0], spp=spp)
    ways = {"splat": Renderer(scene, base),
            "filter sampling": Renderer(scene, replace(base, filter_sampling=True))}
    set_mitsuba_variant()
    with llvm_tuning.dr_default():
        if xml:
            ms = mi.load_file(str(path), spp=str(spp))
        else:
            ms = mi.load_dict(to_mitsuba_dict(scene, base.width, base.height, spp, rfilter=base.filter,
                                              bsdf=base.bsdf))
    times: dict[str, list[float]] = {k: [] for k in (*ways, "mitsuba")}
    images: dict[str, list[np.ndarray]] = {k: [] for k in times}
    for r in ways.values():  # compile
        r.render()
    with llvm_tuning.dr_default():
        mi.render(ms, spp=spp)
    for k in range(rounds):
        for name, r in ways.items():
            t = time.perf_counter()
            img = r.derive(replace(r.opt, seed=k)).render().image
            times[name].append(time.perf_counter() - t)
            images[name].append(img.astype(np.float64))
        with llvm_tuning.dr_default():
            t = time.perf_counter()
            img = np.asarray(mi.render(ms, spp=spp, seed=k), np.float64)[..., :3]
            times["mitsuba"].append(time.perf_counter() - t)
            images["mitsuba"].append(img)
    out = {}
    for name in times:
        sec = statistics.median(times[name])
        var = float(np.stack(images[name]).var(0, ddof=1).mean())
        out[name] = (sec, var, 1.0 / (sec * var))
    m = out["mitsuba"]
    print(f"{path.name}: {base.width}x{base.height}, {spp} spp, filter {base.filter}, {rounds} rounds")
    for name, (sec, var, eff) in out.items():
        print(f"  {name:16s} {sec:7.3f} s  variance {var:.4g} ({var / m[1]:.2f}x Mitsuba's)  "
              f"efficiency {eff:.4g} ({eff / m[2]:.2f}x Mitsuba's)")


if __name__ == "__main__":
    main(sys.argv[1:])
