"""CPU seconds of a render with Embree's robust triangle test and without it (not a test).

drpt builds its Embree scene with ``RTC_SCENE_FLAG_ROBUST`` (watertight: no ray slips between
neighbouring triangles, ``embree_robust_leak.py``) for its own format and where a Mitsuba XML
sets ``embree_use_robust_intersections`` (:func:`drpt.scene.model.embree_robust`), as Mitsuba
3.9 does. This renders one scene of
``equal_time_vs_mitsuba.py`` (its name or a word of it, the same size, spp and settings)
with two renderers in one process, one built each way, taking turns for ``ROUNDS`` rounds
(seed ``k`` in round ``k``), and prints the median CPU seconds of the process per render
(``time.process_time``: other processes' load moves wall time more than it) and their
ratio, and the largest pixel difference of round 0 (the two tests round differently).

Run: PYTHONPATH=. .venv/bin/python benchmarks/embree_robust_ab.py SCENE [ROUNDS]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.equal_time_vs_mitsuba import cases, setup


def main(argv: list[str]) -> None:
    from drpt.backend import ensure
    from drpt.scene.model import RenderSettings
    from drpt.tools.converge import make_drpt

    if not argv:
        sys.exit("usage: embree_robust_ab.py SCENE [ROUNDS]")
    ensure()
    name, rounds = argv[0], int(argv[1]) if len(argv) > 1 else 6
    case = next(iter(cases([name], True, Path(tempfile.mkdtemp(prefix="drpt-robust-")))), None)
    if case is None:
        sys.exit(f"embree_robust_ab.py: no scene of equal_time_vs_mitsuba.py is named like {name!r}")
    scene, opts, _ = setup(case, 192, 1_000_000)
    if scene.settings is None:
        scene.settings = RenderSettings()
    renders = {}
    for label, robust in (("robust", True), ("plain", False)):
        scene.settings.embree_robust = robust  # read when the accelerator is built
        _, renders[label] = make_drpt(scene, opts)
        renders[label](opts.spp, 999_999)  # compiles
    seconds: dict = {label: [] for label in renders}
    first = {}
    for k in range(rounds):
        for label, render in renders.items():
            t = time.process_time()
            img = np.asarray(render(opts.spp, k).image, np.float64)
            seconds[label].append(time.process_time() - t)
            if k == 0:
                first[label] = img
    med = {label: float(np.median(s)) for label, s in seconds.items()}
    print(f"{case.name}: {opts.width}x{opts.height}, {opts.spp} spp, {rounds} rounds; CPU s per render "
          f"robust {med['robust']:.3f}, plain {med['plain']:.3f}, plain / robust {med['plain'] / med['robust']:.3f}; "
          f"round 0 max pixel difference {np.abs(first['robust'] - first['plain']).max():.3g}")


if __name__ == "__main__":
    main(sys.argv[1:])
