"""Adaptive sampling (``--adaptive``) against uniform sampling at equal time.

For each scene: a uniform drpt reference at ``--ref-spp`` (its own seed), then at each
``--spp`` level a uniform and an adaptive render (each after a discarded warm-up render
that compiles its kernels), ``--repeats`` seeds each. Time is the process's CPU time
(all of Dr.Jit's threads), which other work on a shared machine disturbs less than wall
time. Error is excess relMSE against the
reference (relMSE minus the reference's own noise floor ``mean(var_ref / (ref^2 +
0.01))``). Error falls as 1 / time for both, so the **equal-time error ratio** is
``(err_adaptive * t_adaptive) / (err_uniform * t_uniform)`` (below 1: adaptive wins),
the geometric mean over the levels and repeats.

    python benchmarks/adaptive_vs_uniform.py scenes/newscene/newscene_hard.txt \
        --size 64 64 --spp 16 64 --ref-spp 2048
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drpt.metrics import rel_mse  # noqa: E402
from drpt.options import RenderOptions  # noqa: E402
from drpt.render.renderer import Renderer  # noqa: E402
from drpt.scene import load_scene  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--size", type=int, nargs=2, default=(64, 64))
    ap.add_argument("--spp", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    W, H = a.size
    for path in a.scenes:
        scene = load_scene(path)
        base = Renderer(scene, RenderOptions(width=W, height=H, spp=a.ref_spp, seed=999, progress=False))
        ref = base.render()
        floor = float(np.mean(ref.variance / (ref.image.astype(np.float64) ** 2 + 0.01)))
        ratios, per_sample = [], []
        for spp in a.spp:
            for adaptive in (False, True):  # warm-up: compile the kernels
                base.derive(dataclasses.replace(base.opt, spp=max(spp, 8), seed=1, adaptive=adaptive)).render()
            for rep in range(a.repeats):
                row = {}
                for adaptive in (False, True):
                    r = base.derive(dataclasses.replace(base.opt, spp=spp, seed=10 + rep, adaptive=adaptive))
                    t0 = time.process_time()
                    res = r.render()
                    t = time.process_time() - t0
                    err = max(rel_mse(res.image, ref.image) - floor, 1e-12)
                    row[adaptive] = (err, t)
                (eu, tu), (ea, ta) = row[False], row[True]
                ratios.append(ea * ta / (eu * tu))
                per_sample.append(ea / eu)
                print(f"{Path(path).name} spp {spp} seed {10 + rep}: uniform {eu:.4g} in {tu:.2f} s, "
                      f"adaptive {ea:.4g} in {ta:.2f} s, equal-time error ratio {ratios[-1]:.3f}",
                      flush=True)
        g = math.exp(sum(math.log(x) for x in ratios) / len(ratios))
        gs = math.exp(sum(math.log(x) for x in per_sample) / len(per_sample))
        print(f"{Path(path).name}: equal-time error ratio (adaptive / uniform) {g:.3f}, at equal spp "
              f"{gs:.3f} (reference floor {floor:.3g})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
