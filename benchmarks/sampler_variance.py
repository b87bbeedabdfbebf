"""Per-pixel variance at equal spp and equal-time efficiency of the samplers.

    PYTHONPATH=. .venv/bin/python benchmarks/sampler_variance.py SCENE [SIZE SPP SEEDS [FILTER]]

Renders ``SCENE`` at ``SIZE`` x ``SIZE`` with ``SPP`` samples per pixel and ``SEEDS`` seeds
(and the ``--filter`` ``FILTER``, default the scene's) with each ``--sampler``
(independent, ldsampler, zsobol, stratified, multijitter, orthogonal, or the comma-separated
list ``DRPT_SAMPLERS``, independent first; ``DRPT_BSDF`` sets ``--bsdf``, ``DRPT_INTEGRATOR``
``--integrator``), interleaved in one
process, and prints per
sampler the mean over pixels of the variance of a pixel's value across seeds (a
low-discrepancy sampler's samples are not independent, so the variance comes from
independent renders, not from one render's samples), its ratio to the independent
sampler's (and the same of the median over the pixels that vary, which a few fireflies do not
sway) and of the means of 4x4 pixel blocks (where an error spread as blue noise averages
out), the median render time, and the efficiency ratio ``1 / (variance x time)``
relative to the independent sampler's (above 1: less noise in the same time).
"""

import os
import sys
import time
from dataclasses import replace

import numpy as np

from drpt.options import RenderOptions, with_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

SAMPLERS = tuple(os.environ.get("DRPT_SAMPLERS", "independent,ldsampler,zsobol,stratified,multijitter,"
                                                  "orthogonal").split(","))


def main(argv: list[str]) -> int:
    scene_file = argv[0]
    size = int(argv[1]) if len(argv) > 1 else 64
    spp = int(argv[2]) if len(argv) > 2 else 16
    seeds = int(argv[3]) if len(argv) > 3 else 8
    scene = load_scene(scene_file)
    base = RenderOptions(width=size, height=size, spp=spp, progress=False,
                         bsdf=os.environ.get("DRPT_BSDF", "auto"))
    base, scene = with_scene_settings(base, scene)
    base = replace(base, width=size, height=size, spp=spp,
                   integrator=os.environ.get("DRPT_INTEGRATOR", base.integrator)).validate()
    if len(argv) > 4:
        base = replace(base, filter=argv[4]).validate()
    renderers = {s: Renderer(scene, replace(base, sampler=s)) for s in SAMPLERS}
    for r in renderers.values():  # compile
        r.derive(replace(r.opt, seed=999)).render()
    images = {s: [] for s in SAMPLERS}
    times = {s: [] for s in SAMPLERS}
    for seed in range(seeds):
        for s, r in renderers.items():
            t0 = time.perf_counter()
            images[s].append(r.derive(replace(r.opt, seed=seed)).render().image.astype(np.float64))
            times[s].append(time.perf_counter() - t0)
    pixel_var = {s: np.var(np.stack(images[s]), axis=0, ddof=1) for s in SAMPLERS}
    var = {s: float(pixel_var[s].mean()) for s in SAMPLERS}
    def blocks(im):  # 4x4 pixel blocks' means: how the error averages out over neighbours
        h, w = im.shape[0] // 4 * 4, im.shape[1] // 4 * 4
        return im[:h, :w].reshape(h // 4, 4, w // 4, 4, -1).mean((1, 3))

    block_var = {s: float(np.var(np.stack([blocks(im) for im in images[s]]), axis=0, ddof=1).mean())
                 for s in SAMPLERS}
    seen = pixel_var[SAMPLERS[0]] > 0  # the median over pixels that vary
    med = {s: float(np.median(pixel_var[s][seen])) if seen.any() else 0.0 for s in SAMPLERS}
    t = {s: float(np.median(times[s])) for s in SAMPLERS}
    ref = SAMPLERS[0]
    print(f"{scene_file} {size}x{size} {spp} spp, {seeds} seeds, filter {base.filter}")
    for s in SAMPLERS:
        print(f"  {s:12s} variance {var[s]:.4g} ({var[s] / var[ref]:.3f}x, median pixel "
              f"{med[s] / max(med[ref], 1e-300):.3g}x, 4x4 blocks {block_var[s] / block_var[ref]:.3f}x)"
              f"  time {t[s]:.3f} s "
              f"({t[s] / t[ref]:.3f}x)  efficiency {var[ref] * t[ref] / (var[s] * t[s]):.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
