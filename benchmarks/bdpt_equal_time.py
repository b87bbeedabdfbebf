"""Equal-time error of bidirectional path tracing against the path tracer (not a test).

For each scene (the bundled Cornell box, and the caustic scene of
:mod:`drpt.tools.scenegen.caustic`: a glass sphere on a diffuse floor under a small
spherical area light, with a back wall), both
integrators render SIZE x SIZE at their spp after a warm-up render of 1 spp that
compiles the kernels; a bdpt render of REF_SPP spp and another seed is the reference.
Prints per integrator the seconds, the relMSE against the reference (minus the
reference's own estimated relMSE) and relMSE x seconds (lower is better: the relMSE at
equal time, up to a constant), then bdpt's relMSE x seconds over path's.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_equal_time.py [--size 64] [--depth 8]
[--path-spp 256] [--bdpt-spp 64] [--ref-spp 2048] [--scenes cornell,caustic]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from drpt.tools.scenegen.caustic import SCENE as CAUSTIC


def main() -> None:
    from drpt.metrics import rel_mse
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--path-spp", type=int, default=256)
    p.add_argument("--bdpt-spp", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=2048)
    p.add_argument("--scenes", default="cornell,caustic")
    a = p.parse_args()
    repo = Path(__file__).resolve().parents[1]
    tmp = Path(tempfile.mkdtemp())
    (tmp / "caustic.txt").write_text(CAUSTIC)
    files = {"cornell": repo / "scenes" / "cornellbox" / "cornellbox.txt", "caustic": tmp / "caustic.txt"}
    for name in a.scenes.split(","):
        scene = load_scene(files[name])
        base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth))
        ref = Renderer(scene, replace(base, integrator="bdpt", spp=a.ref_spp, seed=99)).render()
        rows = {}
        for integrator, spp in (("path", a.path_spp), ("bdpt", a.bdpt_spp)):
            r = Renderer(scene, replace(base, integrator=integrator, spp=1, seed=1))
            r.render()  # compiles the kernels
            r = r.derive(replace(r.opt, spp=spp, seed=2))
            t = time.perf_counter()
            img = r.render()
            seconds = time.perf_counter() - t
            err = rel_mse(img.image, ref.image) - ref.estimated_rel_mse
            rows[integrator] = err * seconds
            print(f"{name} {integrator}: {spp} spp, {seconds:.2f} s, relMSE {err:.4g}, "
                  f"relMSE x s {err * seconds:.4g}")
        print(f"{name}: bdpt / path relMSE at equal time {rows['bdpt'] / rows['path']:.3f} "
              f"(reference: bdpt {a.ref_spp} spp, its estimated relMSE {ref.estimated_rel_mse:.3g})")


if __name__ == "__main__":
    main()
