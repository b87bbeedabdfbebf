"""What bdpt's connections (``s, t >= 2``) evaluate, counted (not a test; load-free).

Wraps :meth:`~drpt.render.integrators.bdpt.BDPTIntegrator._connect` (a camera vertex joined
to a light vertex) to count, over a render of SCENE (``bdpt_equal_time.py``'s scenes), per
camera sample:

* the pairs evaluated (both BSDFs, the MIS weight: ``_connect``'s ``active`` lanes);
* those whose light vertex lies on the other side of the camera vertex's geometric plane from
  the camera vertex's incoming direction, or the camera vertex on the other side of the light
  vertex's plane from its incoming direction (``apart``: two dot products of data both ends
  already hold; in a scene of reflecting materials such a pair contributes nothing);
* the pairs that contribute (a nonzero value after roulette and the shadow ray).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_connection_pairs.py [--scenes glass,cornell]
[--size 64] [--spp 16] [--depth 8]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bdpt_equal_time as eq  # noqa: E402 (the sibling benchmark: its scenes)


def main() -> None:
    import drjit as dr
    from drjit.auto import UInt32

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.integrators import bdpt as B
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--scenes", default="glass,cornell")
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--depth", type=int, default=8)
    a = p.parse_args()
    files = eq.scene_files(Path(tempfile.mkdtemp()))
    connect = B.BDPTIntegrator._connect
    counts = {}

    def counted(self, si, beta, dvcm, dvc, lv, beta_l, dvcm_l, dvc_l, active, *rest, **kw):
        value = connect(self, si, beta, dvcm, dvc, lv, beta_l, dvcm_l, dvc_l, active, *rest, **kw)
        to = lv.p - si.p
        apart = ((dr.dot(si.ng, to) * dr.dot(si.ng, si.wi) <= 0.0)
                 | (dr.dot(lv.ng, -to) * dr.dot(lv.ng, lv.wi) <= 0.0))
        for i, mask in enumerate((active, active & apart, active & (dr.max(value) > 0.0))):
            dr.scatter_reduce(dr.ReduceOp.Add, counts["sums"], UInt32(1), UInt32(i), mask)
        return value

    B.BDPTIntegrator._connect = counted
    for name in a.scenes.split(","):
        counts["sums"] = dr.zeros(UInt32, 3)
        opt = RenderOptions(width=a.size, height=a.size, spp=a.spp, seed=3, progress=False,
                            path=PathOptions(max_depth=a.depth), integrator="bdpt")
        Renderer(load_scene(files[name]), opt).render()
        samples = a.size * a.size * a.spp
        pairs, apart, kept = (int(v) / samples for v in counts["sums"].numpy())
        print(f"{name}: per camera sample {pairs:.3f} pairs evaluated, {apart:.3f} of them apart "
              f"({apart / pairs:.1%}), {kept:.3f} contribute ({a.size}x{a.size}, {a.spp} spp, depth {a.depth})",
              flush=True)


if __name__ == "__main__":
    main()
