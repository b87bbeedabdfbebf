"""Where ``--target-error`` lands against a measured relMSE (not a test).

For each SCENE: a render at SIZE x SIZE stopped at the target error E (chunks of 4 spp,
at most 65536 spp), and a 4096-spp render of another seed as the reference; prints the spp
spent, the render's estimated relMSE, the measured relMSE against the reference minus the
reference's own estimated relMSE, and that over E.

Run: PYTHONPATH=. .venv/bin/python benchmarks/target_error.py SCENE... [--size N] [--target E]
(defaults 128, 1e-3).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace


def main() -> None:
    from drpt.metrics import rel_mse
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("scenes", nargs="+")
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--target", type=float, default=1e-3)
    a = p.parse_args()
    for path in a.scenes:
        scene = load_scene(path)
        base = RenderOptions(width=a.size, height=a.size, spp=65536, chunk_spp=4, progress=False)
        t = time.perf_counter()
        r = Renderer(scene, replace(base, target_error=a.target)).render()
        seconds = time.perf_counter() - t
        ref = Renderer(scene, replace(base, spp=4096, seed=7, chunk_spp=None)).render()
        measured = rel_mse(r.image, ref.image) - ref.estimated_rel_mse
        print(f"{path}: {r.spp} spp, estimate {r.estimated_rel_mse:.3g}, measured {measured:.3g}, "
              f"measured / target {measured / a.target:.2f}, {seconds:.2f} s")


if __name__ == "__main__":
    main()
