"""bdpt's MIS weights with the light subpath counted less, on a low-discrepancy sampler (not a test).

Renders bdpt (64x64, depth 8, ``--sampler`` SAMPLER, ``ldsampler`` unless named) for each
variant ``SHARE:CHOICES`` of :data:`~drpt.render.integrators.bdpt.LD_LIGHT_SHARE` (how many
samples the weights count each strategy with ``s >= 2`` as, against ``s = 0, 1``) and
:data:`~drpt.render.integrators.bdpt.CONNECTION_CHOICES`, in one process, in turns over the
seeds ``FIRST .. FIRST + SEEDS - 1`` (the same load for every variant), and prints per variant
the mean relMSE against ``bdpt_equal_time.py``'s reference (minus its estimated relMSE), the
CPU seconds summed over the seeds, and both and their product over the first variant's (below
1: better at equal time). ``SHARE`` 1 is the weights of independent samples (the power
heuristic over the plain densities).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_ld_share.py [--scene cornell] [--variants
1:2,0.4:2] [--seeds 8] [--first 2] [--spp 64] [--sampler ldsampler] [--reference PATH]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bdpt_equal_time as eq  # noqa: E402 (the sibling benchmark: its scenes and references)


def main() -> None:
    import numpy as np

    from drpt.metrics import rel_mse
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.integrators import bdpt as B
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--scene", default="cornell")
    p.add_argument("--variants", default="1:2,0.4:2", help="SHARE:CHOICES,...")
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--first", type=int, default=2)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--sampler", default="ldsampler")
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--ref-spp", type=int, default=2048)
    p.add_argument("--reference", type=Path, default=None)
    a = p.parse_args()
    variants = [tuple(float(v) for v in x.split(":")) for x in a.variants.split(",")]
    scene = load_scene(eq.scene_files(Path(tempfile.mkdtemp()))[a.scene])
    base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth),
                         integrator="bdpt", sampler=a.sampler)
    ref, ref_err = eq.reference(scene, base, a.scene, a)
    totals = {v: [0.0, 0.0] for v in variants}  # relMSE, CPU seconds
    for seed in range(a.first, a.first + a.seeds):
        for v in variants:
            B.LD_LIGHT_SHARE, B.CONNECTION_CHOICES = v  # read when the integrator is made
            r = Renderer(scene, replace(base, spp=a.spp, seed=seed))
            if seed == a.first:
                r.derive(replace(r.opt, spp=1)).render()  # compiles the kernels
            c = time.process_time()
            img = r.render()
            totals[v][1] += time.process_time() - c
            totals[v][0] += rel_mse(img.image, ref) - ref_err
    e0, c0 = totals[variants[0]]
    for v in variants:
        e, c = totals[v]
        print(f"{a.scene} {a.sampler} share {v[0]:g} choices {v[1]:g}: relMSE {e / a.seeds:.4g}, {c:.2f} s CPU; "
              f"over the first: error {e / e0:.3f}, CPU {c / c0:.3f}, error x CPU {e * c / (e0 * c0):.3f} "
              f"(seeds {a.first}-{a.first + a.seeds - 1}, {a.spp} spp)", flush=True)
    if not np.isfinite(e0):
        print("no error to compare", flush=True)


if __name__ == "__main__":
    main()
