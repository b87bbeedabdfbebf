"""Per-pixel variance at equal spp, drpt's path tracer against Mitsuba's (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/variance_vs_mitsuba.py SCENE [FILTER SIZE SPP ROUNDS [MAX_DEPTH]]

Renders ``SCENE`` (drpt's format: at ``SIZE`` x ``SIZE`` with ``--filter FILTER``, default
gaussian 128; a Mitsuba XML file: its own film, filter and integrator) with ``SPP`` samples
per pixel (default 64) ``ROUNDS`` times (default 32, seeds 0, 1, ...) with drpt's default
path tracer and with Mitsuba (the exported scene, or the XML file itself), interleaved in
one process, and prints:

* the ratio of the mean over pixels of each pixel's variance across the rounds, drpt's to
  Mitsuba's, with its jackknife standard error over the rounds (the statistic the
  efficiency comparisons use; at a bright emitter's edge a few pixels can carry most of the
  variance, and the error says how far 8 rounds can be trusted);
* the share of the variance in the top 1% of pixels (by drpt's and Mitsuba's variance
  summed, so that the choice favours neither), and the ratio outside them;
* the ratio of the mean images (a bias check, not a test).

``MAX_DEPTH`` (drpt's format only) sets both renderers' ``max_depth`` (1: the emitters the
camera sees, 2: direct light). ``filter_efficiency.py`` compares the filters' ways and
times; this compares the estimators' noise.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np


def _ratio(a: np.ndarray, b: np.ndarray, mask=None) -> float:
    va, vb = a.var(0, ddof=1), b.var(0, ddof=1)
    if mask is not None:
        va, vb = va[mask], vb[mask]
    return float(va.mean() / vb.mean())


def main(argv: list[str]) -> None:
    import mitsuba as mi

    from drpt import llvm_tuning
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.options import PathOptions, RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    path = Path(argv[0])
    flt = argv[1] if len(argv) > 1 else "gaussian"
    size = int(argv[2]) if len(argv) > 2 else 128
    spp = int(argv[3]) if len(argv) > 3 else 64
    rounds = int(argv[4]) if len(argv) > 4 else 32
    depth = int(argv[5]) if len(argv) > 5 else -1
    ensure()
    xml = path.suffix == ".xml"
    if xml:
        scene = load_scene(path, defines={"spp": str(spp)})
        opt, scene = with_scene_settings(RenderOptions(progress=False), scene)
        opt = replace(opt, spp=spp)
    else:
        scene = load_scene(path)
        opt = RenderOptions(width=size, height=size, spp=spp, filter=flt, progress=False,
                            path=PathOptions(max_depth=depth))
    renderer = Renderer(scene, opt)
    set_mitsuba_variant()
    with llvm_tuning.dr_default():
        if xml:
            ms = mi.load_file(str(path), spp=str(spp))
        else:
            ms = mi.load_dict(to_mitsuba_dict(scene, opt.width, opt.height, spp, max_depth=depth,
                                              rfilter=opt.filter, bsdf=opt.bsdf))
    ours, theirs = [], []
    for k in range(rounds):
        ours.append(renderer.derive(replace(renderer.opt, seed=k)).render().image.astype(np.float64))
        with llvm_tuning.dr_default():
            theirs.append(np.asarray(mi.render(ms, spp=spp, seed=k), np.float64)[..., :3])
    a, b = np.stack(ours), np.stack(theirs)
    ratio = _ratio(a, b)
    keep = np.ones(rounds, bool)
    jack = []
    for k in range(rounds):  # leave one round out
        keep[k] = False
        jack.append(_ratio(a[keep], b[keep]))
        keep[k] = True
    err = float(np.sqrt((rounds - 1) / rounds * np.sum((np.array(jack) - np.mean(jack)) ** 2)))
    both = (a.var(0, ddof=1) + b.var(0, ddof=1)).sum(-1)
    top = both >= np.quantile(both, 0.99)
    share = float(both[top].sum() / both.sum())
    print(f"{path.name}: {opt.width}x{opt.height}, {spp} spp, filter {opt.filter}, {rounds} rounds"
          + (f", max_depth {depth}" if depth >= 0 and not xml else ""))
    print(f"  variance drpt / Mitsuba {ratio:.3f} +- {err:.3f}; the top 1% of pixels hold "
          f"{share:.0%} of the variance, outside them {_ratio(a, b, ~top):.3f}; "
          f"mean image drpt / Mitsuba {a.mean() / b.mean():.4f}")


if __name__ == "__main__":
    main(sys.argv[1:])
