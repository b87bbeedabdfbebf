"""The unrolled path's branches and lane layout against the straight-line, one-lane-per-pixel
way, in one process (not a test).

For each Mitsuba render-test scene whose name contains one of the ``--only`` words (default:
the depth-2 scenes of issue 27's table), drpt renders the file as
``benchmarks/equal_time_vs_mitsuba.py`` does (its settings, the film scaled to ``--min-size``,
the spp cut to ``--max-samples``), once each way to compile, then ``--rounds`` rounds in which
the ways take turns (round ``k`` with seed ``k``):

* ``now``: as committed (vertices and last segment in symbolic ``if`` statements on the live
  lanes, :attr:`~drpt.render.integrators.path.PathIntegrator.branched`; ``ceil(k / 3)`` lanes per
  pixel, :data:`~drpt.render.renderer.STRAIGHT_PATHS_PER_LANE`);
* ``masked``: ``branched`` False (straight-line code, every lane masked; the same image);
* ``closest``: ``emitter_first`` False (the last segment by the closest hit, where the scene's
  emitters are a few triangles and nothing else is seen; the same image to float rounding);
* ``one-lane``: all three off and ``min_lanes``' lanes per pixel (one at 192x192): the
  layout and code before them;
* ``eager``: :attr:`~drpt.render.integrators.path.PathIntegrator.deferred` False (the vertex's
  draws and interaction before its branch, on every lane; the same image);
* ``unculled``: :attr:`~drpt.render.integrators.path.PathIntegrator.cull` False (every camera
  ray queries the accelerator; the same image).

Prints per scene the median render seconds of ``now``, the median over rounds of the
per-round ratio way / ``now`` (the ways of a round run back to back, so load from other
processes falls on them alike: read these), and whether ``masked``'s, ``eager``'s and
``unculled``'s images are ``now``'s bit for bit (they must be).
Run: PYTHONPATH=. .venv/bin/python benchmarks/straight_paths_ab.py [--rounds 6] [--only WORD,...]
[--min-size 192] [--max-samples 1000000]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the sibling benchmarks: the corpus, its scenes' settings at the equal-time sizes
import equal_time_vs_mitsuba as eq  # noqa: E402
from unrolled_paths import renderer_for  # noqa: E402

DEFAULT_ONLY = ("test_arealight,test_envmap,test_constant,test_textured_diffuse,test_bumpmap,"
                "test_normalmap_path,directional,mesh_attributes_1,instancing")


def main(argv=None) -> list[dict]:
    from drpt.backend import ensure
    from drpt.render import renderer
    from drpt.render.integrators.path import PathIntegrator

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--only", default=DEFAULT_ONLY)
    ap.add_argument("--min-size", type=int, default=192)
    ap.add_argument("--max-samples", type=int, default=1_000_000)
    a = ap.parse_args(argv)
    ensure()
    only = [w for w in a.only.split(",") if w]
    per_lane = renderer.STRAIGHT_PATHS_PER_LANE
    ways = {"now": (True, True, per_lane, True, True), "masked": (False, True, per_lane, True, True),
            "closest": (True, False, per_lane, True, True), "one-lane": (False, False, 1 << 30, True, True),
            "eager": (True, True, per_lane, False, True), "unculled": (True, True, per_lane, True, False)}
    same_image = ("masked", "eager", "unculled")
    print(f"commit {eq._commit()}, {eq._cpu()}; {a.rounds} rounds; load average {os.getloadavg()[0]:.1f}")
    print("\n| scene | size, spp | now s | masked / now | closest / now | one-lane / now "
          "| eager / now | unculled / now | masked, eager, unculled images = now's |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for path in eq.corpus_files():
        name = str(path.relative_to(eq.CORPUS))
        if not any(w in name for w in only):
            continue
        r = renderer_for(path, a.min_size, a.max_samples)
        if not getattr(r.integrator, "straight", False):
            continue
        secs = {w: [] for w in ways}
        same = True
        for rnd in range(a.rounds + 1):
            images = {}
            for w, (branched, first, lanes, deferred, cull) in ways.items():
                PathIntegrator.branched, PathIntegrator.emitter_first = branched, first
                PathIntegrator.deferred, PathIntegrator.cull = deferred, cull
                renderer.STRAIGHT_PATHS_PER_LANE = lanes
                r.opt.seed = rnd
                t0 = time.perf_counter()
                images[w] = r.render().image
                if rnd > 0:  # (round 0 compiles)
                    secs[w].append(time.perf_counter() - t0)
            same &= all(np.array_equal(images["now"], images[w]) for w in same_image)
        PathIntegrator.branched = PathIntegrator.emitter_first = True
        PathIntegrator.deferred = PathIntegrator.cull = True
        renderer.STRAIGHT_PATHS_PER_LANE = per_lane

        ratio = {w: statistics.median(t / n for t, n in zip(secs[w], secs["now"])) for w in ways}
        med = {w: statistics.median(secs[w]) for w in ways}
        print(f"| {name} | {r.opt.width}x{r.opt.height}, {r.opt.spp} | {med['now']:.3f} | {ratio['masked']:.2f} "
              f"| {ratio['closest']:.2f} | {ratio['one-lane']:.2f} | {ratio['eager']:.2f} "
              f"| {ratio['unculled']:.2f} | {'yes' if same else 'NO'} |", flush=True)
        rows.append({"scene": name, "seconds": secs, "ratio": ratio, "identical": same})
    return rows


if __name__ == "__main__":
    main()
