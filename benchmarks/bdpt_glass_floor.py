"""Where bdpt's error on the seed's glass Cornell box lies, and the floor it sets (not a test).

The glass sphere of :func:`bdpt_equal_time.seed_glass_cornell` shows, through itself, the
caustic it casts on the floor: paths light -> glass -> floor -> glass -> camera (``L S+ D S+
E``). No connection strategy samples them (their one diffuse vertex has a Dirac vertex on
both sides: no light vertex can be joined to a camera vertex, and no vertex seen through
the glass can be splatted to the camera); without caustic merging (``--bdpt-merge off``) only
``s = 0``, the camera subpath hitting the light by BSDF sampling, does: the path tracer's own
way, so bdpt cannot do better than the path tracer on them per sample, and pays its dearer
samples there. With merging (the default) caustic photons estimate them.

The pixels that see the glass sphere (all 4x4 sub-pixel rays of the pixel's camera hit it
first) are split from the rest. Both integrators render SEEDS seeds in turns (path
PATH_SPP, bdpt BDPT_SPP, CPU seconds), scored against the reference of
``bdpt_equal_time.py`` (``--reference`` shares it); each pixel's share of the relMSE
(``(x - ref)^2 / (ref^2 + 0.01)`` over the pixel count) is summed over the two regions,
less the reference's own estimated relMSE (a few percent of bdpt's), spread over the
pixels as bdpt's error is. Prints per integrator the relMSE of
each region, bdpt's share of its error seen through the glass, bdpt / path at equal time
in each region and over the image, and the **floor**: bdpt / path at equal time if every
pixel not seen through the glass had no error at all, ``bdpt's error through the glass x
bdpt seconds / (path's error x path seconds)``, the best any change to the strategies that
can sample the rest could reach.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_glass_floor.py [--size 64] [--depth 8]
[--path-spp 256] [--bdpt-spp 64] [--ref-spp 2048] [--seeds 4] [--reference PATH]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bdpt_equal_time as eq  # noqa: E402 (the sibling benchmark: its scene and reference)

#: the glass sphere's material index in :func:`bdpt_equal_time.seed_glass_cornell`
GLASS = 4
SUB = 4  # sub-pixel rays per axis for the mask


def glass_mask(renderer, size: int):
    """``(H, W)`` bool: the pixels all of whose ``SUB x SUB`` camera rays hit the glass first."""
    import drjit as dr
    from drjit.auto import Bool, Float, UInt32

    n = size * size * SUB * SUB
    i = dr.arange(UInt32, n)
    pixel, sub = i // (SUB * SUB), i % (SUB * SUB)
    x = Float(pixel % size) + (Float(sub % SUB) + 0.5) / SUB
    y = Float(pixel // size) + (Float(sub // SUB) + 0.5) / SUB
    o, d = renderer.camera.ray(x, y)
    si = renderer.scene.intersect(o, d, dr.full(Bool, True, n))
    hit = (si.valid & (si.material == GLASS)).numpy().reshape(size, size, SUB * SUB)
    return hit.all(-1)


def main() -> None:
    import numpy as np

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--path-spp", type=int, default=256)
    p.add_argument("--bdpt-spp", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=2048)
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--reference", type=Path, default=None)
    a = p.parse_args()
    a.sampler = "independent"
    scene = load_scene(eq.scene_files(Path(tempfile.mkdtemp()))["glass"])
    base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth))
    ref, ref_err = eq.reference(scene, base, "glass", a)
    renderers = {}
    for integrator in ("path", "bdpt"):
        r = Renderer(scene, replace(base, integrator=integrator, spp=1, seed=1))
        r.render()  # compiles the kernels
        renderers[integrator] = r
    mask = glass_mask(renderers["path"], a.size)
    spp = {"path": a.path_spp, "bdpt": a.bdpt_spp}
    # each pixel's share of the relMSE, summed over the seeds; CPU seconds
    err = {k: np.zeros((a.size, a.size)) for k in renderers}
    cpu = {k: 0.0 for k in renderers}
    for seed in range(2, a.seeds + 2):
        for k, r in renderers.items():
            r = r.derive(replace(r.opt, spp=spp[k], seed=seed))
            c = time.process_time()
            img = r.render().image.astype(np.float64)
            cpu[k] += time.process_time() - c
            err[k] += ((img - ref) ** 2 / (ref * ref + 1e-2)).mean(-1) / ref.shape[0] / ref.shape[1]
    # the reference's own error, spread over the pixels as its share of the whole
    own = ref_err * err["bdpt"] / err["bdpt"].sum() * a.seeds
    region = {}
    for k in renderers:
        e = err[k] / a.seeds - own / a.seeds
        region[k] = (e[mask].sum(), e[~mask].sum(), e.sum())
        print(f"{k}: {a.seeds} seeds of {spp[k]} spp, {cpu[k]:.2f} s CPU; relMSE through the glass "
              f"{region[k][0]:.4g}, elsewhere {region[k][1]:.4g}, whole {region[k][2]:.4g}", flush=True)
    rb, rp = region["bdpt"], region["path"]
    cost = cpu["bdpt"] / cpu["path"]
    print(f"pixels through the glass: {mask.sum()} of {mask.size}; bdpt's error there: "
          f"{rb[0] / rb[2]:.1%} of its whole (path's: {rp[0] / rp[2]:.1%})")
    print(f"bdpt / path at equal CPU time: whole {rb[2] / rp[2] * cost:.3f}, through the glass "
          f"{rb[0] / rp[0] * cost:.3f}, elsewhere {rb[1] / rp[1] * cost:.3f}")
    print(f"floor (no error outside the glass): {rb[0] / rp[2] * cost:.3f}")


if __name__ == "__main__":
    main()
