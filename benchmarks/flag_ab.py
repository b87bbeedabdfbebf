"""Time and per-pixel variance of one scene with a class attribute of drpt set two ways, in turns
in one process (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/flag_ab.py SCENE MODULE:CLASS.ATTR [--rounds 8]
        [--values False True]

``SCENE`` is a word of a scene name of ``equal_time_vs_mitsuba.py`` (``null_envmap``,
``emitter_inside``, ...), set up as that benchmark sets it up (size, spp, the file's settings);
``MODULE:CLASS.ATTR`` a class attribute read when a kernel is traced (an A/B switch such as
``drpt.render.integrators.volpath:VolPathIntegrator.split_sheets``), or ``MODULE:ATTR`` a
module's constant (``drpt.render.renderer:STRAIGHT_PATHS_PER_LANE``), set to each of
``--values`` (Python literals, default ``False True``: A, then B) before each render. Each
way has a renderer of its own (a renderer replays its frozen passes, recorded with the value
set when it traced them: :mod:`drpt.render.frozen`), which renders twice to compile and record
with its value; then the ways take turns for ``--rounds`` rounds (AB, BA, ...), round ``k``
with seed ``k`` for both. Prints each way's median wall seconds, the median and
quartiles of the per-round ratios A / B (above 1: B is faster) by wall and by CPU seconds of
the process (``time.process_time``, all threads: the measure to quote on a loaded machine),
the mean per-pixel variance across the rounds of each way (B / A) and the efficiency B / A.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import time
import warnings
from pathlib import Path

import equal_time_vs_mitsuba as eq
import numpy as np

from drpt.backend import ensure
from drpt.tools.converge import image_room, make_drpt


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("scene")
    ap.add_argument("flag")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--values", nargs=2, default=["False", "True"])
    args = ap.parse_args(argv)
    ensure()
    warnings.simplefilter("ignore")
    module, attr = args.flag.split(":")
    cls = importlib.import_module(module)
    if "." in attr:
        cls_name, attr = attr.rsplit(".", 1)
        cls = getattr(cls, cls_name)
    values = [ast.literal_eval(v) for v in args.values]
    case = next(c for c in eq.cases([args.scene], True, Path("/tmp/flag_ab_room")) if args.scene in c.name)
    scene, opts, _ = eq.setup(case, 192, 1_000_000)
    before = getattr(cls, attr)
    wall, cpu = ([], []), ([], [])
    renders = []
    try:
        for w in (0, 1):  # (compile both, and record each one's frozen pass with its value)
            setattr(cls, attr, values[w])
            renders.append(make_drpt(scene, opts)[1])
            shape = renders[w](opts.spp, 1000).image.shape
            renders[w](opts.spp, 1001)
        imgs = (image_room(args.rounds, shape), image_room(args.rounds, shape))  # (paged in before timing)
        for k in range(args.rounds):
            for w in ((0, 1) if k % 2 == 0 else (1, 0)):
                setattr(cls, attr, values[w])
                t0, c0 = time.perf_counter(), time.process_time()
                img = renders[w](opts.spp, k).image
                wall[w].append(time.perf_counter() - t0)
                cpu[w].append(time.process_time() - c0)
                imgs[w][k] = img
                del img
    finally:
        setattr(cls, attr, before)
    var = [float(np.mean(np.var(i, axis=0, ddof=1))) for i in imgs]
    r_wall = np.array(wall[0]) / np.array(wall[1])
    r_cpu = np.array(cpu[0]) / np.array(cpu[1])
    out = {"wall": [float(np.median(w)) for w in wall], "ratio_wall": float(np.median(r_wall)),
           "ratio_cpu": float(np.median(r_cpu)), "variance": var}
    print(f"{case.name}, {opts.width}x{opts.height}, {opts.spp} spp, {args.rounds} rounds; "
          f"{attr} = {values[0]!r} (A) / {values[1]!r} (B)")
    print(f"  median s A {out['wall'][0]:.3f}, B {out['wall'][1]:.3f}; A / B per round: wall "
          f"{np.median(r_wall):.3f} ({np.quantile(r_wall, 0.25):.3f}-{np.quantile(r_wall, 0.75):.3f}), "
          f"CPU {np.median(r_cpu):.3f} ({np.quantile(r_cpu, 0.25):.3f}-{np.quantile(r_cpu, 0.75):.3f})")
    print(f"  variance A {var[0]:.4e}, B {var[1]:.4e}, B / A {var[1] / var[0]:.3f}; efficiency B / A: "
          f"wall {np.median(r_wall) * var[0] / var[1]:.3f}, CPU {np.median(r_cpu) * var[0] / var[1]:.3f}")
    return out


if __name__ == "__main__":
    main()
