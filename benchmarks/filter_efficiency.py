"""Equal-spp noise and equal-time efficiency of the pixel filters (not a test).

Renders SCENE (drpt's format, or a Mitsuba XML file with its own settings) with a
tent or Gaussian filter three ways, interleaved in one process for ROUNDS rounds of
one render each: drpt's splatting film (the default), drpt's filter importance
sampling (``--filter-sampling``) and Mitsuba (the exported scene, or the XML file
itself, with Dr.Jit's own LLVM settings). Each round uses another seed. Prints per
way the median render seconds, the mean per-pixel variance across the rounds'
images (at equal spp) and the efficiency ``1 / (seconds * variance)``
(:func:`drpt.tools.converge.efficiency_rounds`), and the ratios to Mitsuba. Where a few
pixels carry most of the variance (a light's edge on the Cornell box) 8 rounds move the
variance ratio by about 10%: ``variance_vs_mitsuba.py`` gives it with its standard error.

Run: PYTHONPATH=. .venv/bin/python benchmarks/filter_efficiency.py SCENE [FILTER] [SIZE] [SPP] [ROUNDS]
(defaults gaussian, 128, 64, 8; FILTER is ignored for an XML file, which names its own).
"""

from __future__ import annotations

import sys
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
    from drpt.tools.converge import efficiency_rounds

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
    def drpt(r):
        return lambda seed: r.derive(replace(r.opt, seed=seed)).render().image

    def mitsuba(seed):
        with llvm_tuning.dr_default():
            return np.asarray(mi.render(ms, spp=spp, seed=seed))[..., :3]

    res = efficiency_rounds({**{name: drpt(r) for name, r in ways.items()}, "mitsuba": mitsuba}, rounds)
    out = {name: (v["seconds"], v["variance"], v["efficiency"]) for name, v in res.items()}
    m = out["mitsuba"]
    print(f"{path.name}: {base.width}x{base.height}, {spp} spp, filter {base.filter}, {rounds} rounds")
    for name, (sec, var, eff) in out.items():
        print(f"  {name:16s} {sec:7.3f} s  variance {var:.4g} ({var / m[1]:.2f}x Mitsuba's)  "
              f"efficiency {eff:.4g} ({eff / m[2]:.2f}x Mitsuba's)")


if __name__ == "__main__":
    main(sys.argv[1:])
