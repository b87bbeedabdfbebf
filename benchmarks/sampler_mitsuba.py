"""drpt's samplers against Mitsuba's same samplers: per-pixel variance at equal spp.

    PYTHONPATH=. .venv/bin/python benchmarks/sampler_mitsuba.py SCENE.xml [SPP SEEDS]

Renders the Mitsuba XML ``SCENE.xml`` (a perspective sensor; its film size and filter) with
drpt and with Mitsuba, ``SPP`` samples per pixel (default 64), ``SEEDS`` seeds each (default
16), with each sampler of ``DRPT_SAMPLERS`` (comma-separated; default independent,
stratified, multijitter, orthogonal, ldsampler; Mitsuba's sensor is rebuilt with that
sampler plugin and the file's camera, film and filter; drpt selects emitters as Mitsuba does,
``--light-sampler uniform``), and prints per sampler the mean over
pixels of each pixel's variance across the seeds for drpt and for Mitsuba, their ratio (1:
the same variance as Mitsuba's), the *gain*, each renderer's variance against its own
independent sampler's at equal spp (``var n / (var_independent n_independent)``, as an
independent render's variance falls as ``1 / n``), the two gains' ratio (1: drpt's sampler
removes as much noise as Mitsuba's same sampler, whatever else differs between the two
renderers' estimators), and the median seconds of a render of each. ``SPP`` is what both get:
Mitsuba rounds it (a square, a prime's square) and drpt takes the rounded count too.
"""

import os
import sys
import time
from dataclasses import replace

import numpy as np

from drpt.backend import mitsuba_variant
from drpt.options import RenderOptions, with_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.scene.model import mitsuba_sample_count

SAMPLERS = tuple(os.environ.get("DRPT_SAMPLERS", "independent,stratified,multijitter,orthogonal,"
                                                  "ldsampler").split(","))


def mitsuba_sensor(mi, scene, kind: str, spp: int):
    """The scene's first (perspective) sensor with Mitsuba's sampler plugin ``kind``."""
    s = scene.sensors()[0]
    p = mi.traverse(s)
    return mi.load_dict({"type": "perspective", "fov": float(p["x_fov"][0]), "fov_axis": "x",
                         "near_clip": float(p["near_clip"]), "far_clip": float(p["far_clip"]),
                         "to_world": mi.ScalarTransform4f(np.array(s.world_transform().matrix)[..., 0]),
                         "film": s.film(),
                         "sampler": {"type": kind, "sample_count": spp}})


def main(argv: list[str]) -> int:
    import mitsuba as mi

    path = argv[0]
    spp = int(argv[1]) if len(argv) > 1 else 64
    seeds = int(argv[2]) if len(argv) > 2 else 16
    mi.set_variant(mitsuba_variant())
    ms = mi.load_file(path)
    scene = load_scene(path)
    # Mitsuba's light selection (each emitter alike), so that only the samplers differ
    base, scene = with_scene_settings(RenderOptions(progress=False, light_sampler="uniform"), scene)
    rows = {}
    for kind in SAMPLERS:
        n = mitsuba_sample_count(kind, spp)
        r = Renderer(scene, replace(base, spp=n, sampler=kind).validate())
        r.derive(replace(r.opt, seed=999)).render()  # compile
        sensor = mitsuba_sensor(mi, ms, kind, n)
        mi.render(ms, sensor=sensor, seed=999)
        ours, theirs, t_ours, t_theirs = [], [], [], []
        for seed in range(seeds):
            t0 = time.perf_counter()
            ours.append(r.derive(replace(r.opt, seed=seed)).render().image.astype(np.float64))
            t1 = time.perf_counter()
            theirs.append(np.asarray(mi.render(ms, sensor=sensor, seed=seed + 1), np.float64)[..., :3])
            t_ours.append(t1 - t0)
            t_theirs.append(time.perf_counter() - t1)
        rows[kind] = (n, float(np.var(np.stack(ours), 0, ddof=1).mean()),
                      float(np.var(np.stack(theirs), 0, ddof=1).mean()),
                      float(np.median(t_ours)), float(np.median(t_theirs)))
    ind = rows.get("independent")
    print(f"{path} {base.width}x{base.height} {spp} spp, {seeds} seeds, filter {base.filter}")
    for kind, (n, vo, vt, to, tt) in rows.items():
        gain = ""
        if ind:  # the variance against the renderer's own independent sampler's, at equal spp
            go, gt = vo * n / (ind[1] * ind[0]), vt * n / (ind[2] * ind[0])
            gain = f"  gain drpt {go:.3f} mitsuba {gt:.3f} ratio {go / gt:.3f}"
        print(f"  {kind:12s} {n:4d} spp  variance drpt {vo:.4g} mitsuba {vt:.4g} ratio {vo / vt:.3f}{gain}"
              f"  time drpt {to:.3f} s mitsuba {tt:.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
