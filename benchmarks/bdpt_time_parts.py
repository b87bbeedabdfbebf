"""Where a bdpt render's time goes: the render with one part left out, in turns in one process (not a test).

Each VARIANT renders SIZE x SIZE at SPP (the path tracer at 4 x SPP: the equal-time
benchmark's pair) from a renderer of its own whose kernels a 1-spp render compiled first,
round after round (seeds ``2 .. ROUNDS + 1``, the variants in turns, so that load from
other processes falls on all of them):

* ``full``: bdpt as it is;
* ``nosplat``: without the ``t = 1`` splats (:meth:`BDPTIntegrator._splat` does nothing);
* ``noconn``: without the connections (``s, t >= 2``: :meth:`BDPTIntegrator._connect` gives 0;
  the loop over the light vertices still runs);
* ``nonee``: without next-event estimation at area lights (``s = 1``);
* ``nolight``: without the light subpath (no lane leaves a light: no stores, splats or
  connections; caustic merging's photons are still traced);
* ``path``: the path tracer.

Left-out parts make the image wrong: only the seconds mean anything. Prints per variant the
median and the smallest of its CPU seconds (the process's) and the median over the rounds
of its seconds over ``full``'s in the same round.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_time_parts.py [--scene glass]
[--variants full,nosplat,noconn,nonee,nolight,path] [--rounds 8] [--size 64] [--depth 8] [--spp 64]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bdpt_equal_time as eq  # noqa: E402 (the sibling benchmark: its scenes)

VARIANTS = ("full", "nosplat", "noconn", "nonee", "nolight", "path")


def main() -> None:
    import drjit as dr
    from drjit.auto import Array3f

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.integrators import bdpt as B
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--scene", default="glass", help="cornell, caustic or glass (bdpt_equal_time.py's)")
    p.add_argument("--variants", default=",".join(VARIANTS))
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--spp", type=int, default=64)
    a = p.parse_args()
    variants = a.variants.split(",")
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        raise SystemExit(f"unknown variants {unknown}: choose from {', '.join(VARIANTS)}")
    scene = load_scene(eq.scene_files(Path(tempfile.mkdtemp()))[a.scene])
    base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth),
                         integrator="bdpt")
    cls = B.BDPTIntegrator
    kept = {name: getattr(cls, name) for name in ("_splat", "_connect", "_nee_area", "_emit")}

    def nothing(self, *args, **kwargs):
        return None

    def zero(self, si, *args, **kwargs):
        return dr.zeros(Array3f, dr.width(si.valid))

    def no_light(self, rng, active, area_only=False):
        *start, valid = kept["_emit"](self, rng, active, area_only)
        return (*start, valid & area_only)  # (the photons, area_only, still leave the lights)

    left_out = {"nosplat": ("_splat", nothing), "noconn": ("_connect", zero), "nonee": ("_nee_area", zero),
                "nolight": ("_emit", no_light)}

    def setup(variant: str) -> RenderOptions:
        """The integrator's methods and the options of ``variant``."""
        for name, method in kept.items():
            setattr(cls, name, method)
        if variant in left_out:
            setattr(cls, *left_out[variant])
        return replace(base, integrator="path", spp=4 * a.spp) if variant == "path" else replace(base, spp=a.spp)

    try:
        renderers = {}
        for v in variants:
            opt = setup(v)
            r = Renderer(scene, replace(opt, spp=1, seed=1))
            r.render()  # compiles the kernels
            renderers[v] = r
        seconds: dict[str, list[float]] = {v: [] for v in variants}
        for seed in range(2, a.rounds + 2):
            for v in variants:
                r = renderers[v].derive(replace(setup(v), seed=seed))
                c = time.process_time()
                r.render()
                seconds[v].append(time.process_time() - c)
    finally:
        setup("full")
    first = variants[0]
    for v in variants:
        s = seconds[v]
        ratio = statistics.median(x / y for x, y in zip(s, seconds[first]))
        print(f"{a.scene} {v}: CPU seconds median {statistics.median(s):.3f}, least {min(s):.3f}; "
              f"over {first} (median of the rounds) {ratio:.3f} ({a.rounds} rounds, {a.spp} spp"
              f"{', path x4' if v == 'path' else ''})", flush=True)


if __name__ == "__main__":
    main()
