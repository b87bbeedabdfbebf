"""Emissive triangles sampled by area against by solid angle, in one process (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/triangle_sampling_ab.py [--rounds 8] [--only WORD,...]
        [--skip WORD,...] [--no-corpus] [--min-size 192] [--max-samples 1000000] [--ways area,solid-angle]

The scenes, sizes, spp and settings are ``equal_time_vs_mitsuba.py``'s (its ``cases`` and
``setup``: the bundled scenes, Veach's, the living room, the corpus). drpt renders each with
``--triangle-sampling area`` and ``solid-angle`` (``--ways``) in turns,
:func:`drpt.tools.converge.efficiency_rounds`: each once to compile, then ``--rounds`` rounds
(seed ``k`` in round ``k``); seconds are the median render, the variance is the per-pixel
variance across the rounds' images, averaged over pixels and channels. Prints per scene
whether ``auto`` picks solid angle (:func:`drpt.render.lights.area.triangle_sampling_rule`),
each way's variance and seconds relative to the first way's, and the efficiency ratio
``(1 / (s var))`` of each way over the first.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from equal_time_vs_mitsuba import _commit, _cpu, cases, setup  # noqa: E402


def main(argv=None) -> None:
    from drpt.backend import ensure
    from drpt.errors import DrptError
    from drpt.render.renderer import Renderer
    from drpt.tools.converge import efficiency_rounds

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--min-size", type=int, default=192)
    ap.add_argument("--max-samples", type=int, default=1_000_000)
    ap.add_argument("--only", default="")
    ap.add_argument("--skip", default="")
    ap.add_argument("--no-corpus", action="store_true")
    ap.add_argument("--ways", default="area,solid-angle")
    a = ap.parse_args(argv)
    ensure()
    ways_names = a.ways.split(",")
    print(f"commit {_commit()}, {_cpu()}, {os.cpu_count()} cores; {a.rounds} rounds; "
          f"load average {os.getloadavg()[0]:.1f} at the start")
    print()
    head = " | ".join(f"{w} var / {ways_names[0]} | {w} s / {ways_names[0]} | efficiency {w} / {ways_names[0]}"
                      for w in ways_names[1:])
    print(f"| scene | size | spp | auto | {head} | load |")
    print("|---" * (5 + 3 * (len(ways_names) - 1)) + "|")
    with tempfile.TemporaryDirectory(prefix="drpt-tri-ab-") as tmp:
        for case in cases([w for w in a.only.split(",") if w], not a.no_corpus, Path(tmp),
                          [w for w in a.skip.split(",") if w]):
            try:
                scene, opts, _ = setup(case, a.min_size, a.max_samples)
            except DrptError as e:
                print(f"{case.name}: skipped: {str(e).splitlines()[0]}", file=sys.stderr, flush=True)
                continue
            renderers = {w: Renderer(scene, replace(opts, triangle_sampling=w)) for w in ways_names}
            auto = Renderer(scene, replace(opts, triangle_sampling="auto")).scene.area_lights.spherical

            def way(r):
                def render(seed):
                    r.opt.seed = int(seed)
                    return r.render().image
                return render

            res = efficiency_rounds({w: way(r) for w, r in renderers.items()}, a.rounds)
            base = res[ways_names[0]]
            cells = " | ".join(f"{res[w]['variance'] / base['variance']:.3f} "
                               f"| {res[w]['seconds'] / base['seconds']:.3f} "
                               f"| {res[w]['efficiency'] / base['efficiency']:.3f}" for w in ways_names[1:])
            print(f"| {case.name} | {opts.width}x{opts.height} | {opts.spp} | {'solid' if auto else 'area'} | "
                  f"{cells} | {os.getloadavg()[0]:.1f} |", flush=True)


if __name__ == "__main__":
    main()
