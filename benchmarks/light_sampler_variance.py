"""Per-pixel variance of each light selection rule at the equal-time benchmark's settings (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/light_sampler_variance.py SCENE [ROUNDS] [RULES]

``SCENE``: a scene of ``equal_time_vs_mitsuba.py`` (its name or a word of it: ``veach``,
``living_room``, ``texturedprincipledthin``, ...), set up as that benchmark sets it up (size,
spp, the file's settings). drpt renders it ``ROUNDS`` times (default 16, seeds 0..) with each
rule of ``RULES`` (comma-separated ``--light-sampler`` values, default ``uniform,mixed,pilot``)
and prints, per rule, each emitter's probability (the pilot: also the candidate it took and
the candidates' measured second moments, relative and absolute), then the variance across
the rounds averaged over the pixels relative to ``uniform``'s (Mitsuba's rule), absolute (the
equal-time benchmark's measure) and relative (each pixel's divided by its squared mean, over
all the rules' rounds, plus 0.01: the relative error ``light_sampler.py`` measures). The
seeds are fixed: the same rule gives the same numbers.
"""

from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.equal_time_vs_mitsuba import cases, setup


def main(argv: list[str]) -> None:
    from drpt.backend import ensure
    from drpt.render.lights.pilot import units
    from drpt.render.renderer import Renderer

    ensure()
    if not argv:
        sys.exit("usage: light_sampler_variance.py SCENE [ROUNDS] [RULES]")
    name = argv[0]
    rounds = int(argv[1]) if len(argv) > 1 else 16
    rules = (argv[2] if len(argv) > 2 else "uniform,mixed,pilot").split(",")
    case = next(iter(cases([name], True, Path(tempfile.mkdtemp(prefix="drpt-lsv-")))), None)
    if case is None:
        sys.exit(f"light_sampler_variance.py: no scene of equal_time_vs_mitsuba.py is named like {name!r}")
    scene, opts, _ = setup(case, 192, 1_000_000)
    images = {}
    for rule in rules:
        r = Renderer(scene, replace(opts, light_sampler=rule))
        sel = r.scene.emitter_selection
        p = np.bincount(units(sel.families), weights=sel.probabilities)
        extra = ""
        if getattr(sel, "candidates", None):
            extra = f"; took {sel.choice!r} of " + ", ".join(
                f"{k} ({a:.4g}, {b:.4g})" for k, (a, b) in sel.candidates.items())
        print(f"{case.name} {rule}: emitters {[type(f).__name__ for f in sel.families]}, "
              f"probabilities {np.round(p, 3).tolist()}{extra}", flush=True)
        images[rule] = np.stack([np.asarray(r.derive(replace(r.opt, seed=k)).render().image, np.float64)
                                 for k in range(rounds)])
    ref = np.mean([a.mean(0) for a in images.values()], 0)
    var = {k: a.var(0, ddof=1) for k, a in images.items()}
    base = rules[0]
    print(f"{case.name}: {opts.width}x{opts.height}, {opts.spp} spp, {rounds} rounds; variance over {base}'s, "
          "absolute: " + ", ".join(f"{k} {v.mean() / var[base].mean():.3f}" for k, v in var.items())
          + "; relative: " + ", ".join(
              f"{k} {(v / (ref ** 2 + 1e-2)).mean() / (var[base] / (ref ** 2 + 1e-2)).mean():.3f}"
              for k, v in var.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
