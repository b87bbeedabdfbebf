"""Which of bdpt's strategies its error on the seed's glass Cornell box is made of (not a test).

Renders SEEDS seeds of the glass Cornell box (:func:`bdpt_equal_time.seed_glass_cornell`;
``--scene``: another of ``bdpt_equal_time.py``'s scenes, all of whose pixels then count as
"elsewhere") with bdpt on ``--sampler`` (``independent`` unless named) at SPP with
``bdpt_strategies`` (each strategy's image, paths of up to DEPTH segments; without caustic
merging, as the strategy images are), and prints for each
strategy ``(s, t)`` the variance of its image over the seeds as a share of the relMSE
(per pixel ``var / (ref^2 + 0.01)``, averaged over the channels, summed over the pixels and
divided by their count), split between the pixels seen through the glass sphere
(:func:`bdpt_glass_floor.glass_mask`) and the rest, with its mean (the same measure of the
mean image), then the sums by kind: ``t = 1`` splats, ``s = 0`` emitter hits, ``s = 1``
next-event estimation, connections. The strategies' covariances are left out (the whole
image's variance is printed beside them). The reference is ``bdpt_equal_time.py``'s
(``--reference`` shares it).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_strategy_variance.py [--seeds 8] [--spp 64]
[--depth 8] [--scene glass] [--sampler independent] [--reference PATH]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bdpt_equal_time as eq  # noqa: E402 (the sibling benchmarks: the scene and its reference)
import bdpt_glass_floor as gf  # noqa: E402


def main() -> None:
    import numpy as np

    import drpt.render.renderer as renderer_module
    from drpt.options import PathOptions, RenderOptions
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--ref-spp", type=int, default=2048)
    p.add_argument("--reference", type=Path, default=None)
    p.add_argument("--scene", default="glass")
    p.add_argument("--sampler", default="independent")
    a = p.parse_args()
    a.size = 64
    renderer_module.STRATEGY_SEGMENTS = a.depth  # every strategy of the paths rendered
    scene = load_scene(eq.scene_files(Path(tempfile.mkdtemp()))[a.scene])
    base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth),
                         sampler=a.sampler)
    ref, _ = eq.reference(scene, base, a.scene, a)
    r0 = renderer_module.Renderer(scene, replace(base, integrator="bdpt", spp=1, seed=1, bdpt_strategies=True))
    r0.render()  # compiles the kernels
    mask = gf.glass_mask(r0, a.size) if a.scene == "glass" else np.zeros((a.size, a.size), bool)
    images, strategies = [], []
    for seed in range(2, a.seeds + 2):
        r = r0.derive(replace(r0.opt, spp=a.spp, seed=seed))
        images.append(r.render().image.astype(np.float64))
        strategies.append({k: v.astype(np.float64) for k, v in r.strategy_images(a.spp).items()})
    den = ref.astype(np.float64) ** 2 + 1e-2
    pixels = a.size * a.size

    def split(stack):  # (seeds, H, W, 3) -> (share through the glass, elsewhere, mean)
        e = (stack.var(0, ddof=1) / den).mean(-1) / pixels
        return e[mask].sum(), e[~mask].sum(), (stack.mean(0) / den).mean(-1).sum() / pixels

    g, e, _ = split(np.stack(images))
    print(f"whole image: variance through the glass {g:.3g}, elsewhere {e:.3g} ({a.seeds} seeds of {a.spp} spp)")
    rows = sorted(((split(np.stack([s[k] for s in strategies])), k) for k in strategies[0]),
                  key=lambda row: -row[0][1])
    for (g, e, m), (s, t) in rows:
        print(f"({s}, {t}): variance elsewhere {e:.3g}, through the glass {g:.3g}; mean {m:.3g}")
    kinds = (("t = 1 splats", lambda s, t: t == 1), ("s = 0 emitter hits", lambda s, t: s == 0),
             ("s = 1 next-event estimation", lambda s, t: s == 1),
             ("connections", lambda s, t: s >= 2 and t >= 2))
    for name, pick in kinds:
        g, e, _ = split(np.stack([sum(v for (s, t), v in d.items() if pick(s, t)) for d in strategies]))
        print(f"{name}: variance elsewhere {e:.3g}, through the glass {g:.3g}")


if __name__ == "__main__":
    main()
