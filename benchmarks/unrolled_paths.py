"""Short paths traced unrolled against the bounce loop, in one process (not a test).

For each Mitsuba render-test scene whose name contains one of the ``--only`` words (default:
the depth-2 scenes of issue 27's table and ``infinite_mirrors``), drpt renders the file as
``benchmarks/equal_time_vs_mitsuba.py`` does (its settings, the film scaled to ``--min-size``,
the spp cut to ``--max-samples``), once each way to compile, then ``--rounds`` rounds in which
the two ways take turns (:attr:`drpt.render.integrators.path.PathIntegrator.unrolled` True,
then False; round ``k`` with seed ``k``). Prints per scene the median render seconds of each
way, their ratio (loop / unrolled: above 1, the unrolled path is faster), whether the scene
is unrolled at all (``0 < max_depth <= UNROLLED_MAX_DEPTH``) and the relative difference of
the two ways' mean pixel values over all rounds (the same expectation: noise only).
``--max-depth N`` renders every scene with that depth instead of its own.

Run: PYTHONPATH=. .venv/bin/python benchmarks/unrolled_paths.py [--rounds 5] [--only WORD,...]
[--min-size 192] [--max-samples 1000000] [--max-depth N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings
from dataclasses import replace

import equal_time_vs_mitsuba as eq
import numpy as np

DEFAULT_ONLY = "mesh_attributes,projector,instancing,texture_interp,spot_light,floating_sphere,infinite_mirrors"


def renderer_for(path, min_size: int, max_samples: int, max_depth: int | None = None):
    """drpt's renderer of the XML file ``path`` at the equal-time benchmark's size and spp
    (and ``max_depth``, if given, in place of the file's)."""
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path)
    own, _ = with_scene_settings(RenderOptions(progress=False), scene)
    k = eq.scale_for(own.width, own.height, min_size)
    opts, scene = with_scene_settings(RenderOptions(width=k * own.width, height=k * own.height, progress=False),
                                      scene, given=frozenset({"size"}))
    opts = replace(opts, spp=eq.spp_for(opts.spp, opts.width * opts.height, max_samples))
    if max_depth is not None:
        opts = replace(opts, path=replace(opts.path, max_depth=max_depth))
    return Renderer(scene, opts)


def main(argv=None) -> None:
    from drpt.backend import ensure
    from drpt.render.integrators.path import PathIntegrator

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--only", default=DEFAULT_ONLY)
    ap.add_argument("--min-size", type=int, default=192)
    ap.add_argument("--max-samples", type=int, default=1_000_000)
    ap.add_argument("--max-depth", type=int, default=None)
    a = ap.parse_args(argv)
    ensure()
    only = [w for w in a.only.split(",") if w]
    print(f"commit {eq._commit()}, {eq._cpu()}; {a.rounds} rounds; load average {os.getloadavg()[0]:.1f}")
    print("\n| scene | size, spp | unrolled | loop s | unrolled s | loop s / unrolled s | mean difference |")
    print("|---|---|---|---|---|---|---|")
    for path in eq.corpus_files():
        name = str(path.relative_to(eq.CORPUS))
        if not any(w in name for w in only):
            continue
        r = renderer_for(path, a.min_size, a.max_samples, a.max_depth)
        if not isinstance(r.integrator, PathIntegrator):
            continue
        ways = {True: [], False: []}
        means = {True: [], False: []}
        for rnd in range(a.rounds + 1):
            for way in (True, False):
                PathIntegrator.unrolled = way
                r.opt.seed = rnd
                t0 = time.perf_counter()
                img = r.render().image
                if rnd > 0:  # (round 0 compiles)
                    ways[way].append(time.perf_counter() - t0)
                    means[way].append(float(np.mean(img)))
        PathIntegrator.unrolled = True
        loop, unrolled = statistics.median(ways[False]), statistics.median(ways[True])
        diff = (np.mean(means[True]) - np.mean(means[False])) / max(np.mean(means[False]), 1e-30)
        print(f"| {name} | {r.opt.width}x{r.opt.height}, {r.opt.spp} | {'yes' if r.integrator.straight else 'no'} "
              f"| {loop:.3f} | {unrolled:.3f} | {loop / unrolled:.2f} | {diff:+.4f} |", flush=True)


if __name__ == "__main__":
    main()
