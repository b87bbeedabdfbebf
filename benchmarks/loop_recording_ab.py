"""Loops recorded once against twice: Python tracing and CPU seconds per render, A/B in one
process (not a test). Passes are not frozen here (:mod:`drpt.render.frozen`): every render
traces them.

drpt traces its loops under :func:`drpt.render.loops.loops_once` (``OptimizeLoops`` off, each
body recorded once). Variant ``twice`` traces the same methods with the flag on, as Dr.Jit does
by default (it records each loop body a second time to drop unchanged state). For each scene,
one :class:`~drpt.render.renderer.Renderer` renders once per variant to compile, then
``--rounds`` rounds of one render each way, the order alternating (ABBA...) so that load from
other processes falls on both; round ``k`` renders seed ``k`` both ways and the two images must
be bit-identical (checked). Per render: ``trace ms``, the wall time inside the outermost
``loops_once`` method (the Python tracing of the integrator's loops and all they call; nothing
is evaluated there), the render's wall and CPU seconds (``time.process_time``: every thread of
the process). Medians; ``once / twice`` is the ratio of the medians.

Scenes (``--only`` keeps those whose name contains one of its words), at the sizes and spp of
``benchmarks/equal_time_vs_mitsuba.py`` (:func:`setup`; corpus scenes skipped when
``../shared/corpus`` is absent): ``cornellbox``, ``cornellbox_media`` (volpath),
``bsdf_spheres/test_arealight_path.xml``, ``bsdf_spheres/test_texturedprincipledthin_path.xml``,
``floating_sphere/test_directional_direct.xml``,
``participating_media/test_hetero_sigmat_volpath.xml``.

Run: PYTHONPATH=. .venv/bin/python benchmarks/loop_recording_ab.py [--rounds 8] [--only WORD,...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the sibling benchmark: its scenes, their sizes and spp, the CPU's name and the commit
from equal_time_vs_mitsuba import _commit, _cpu, cases, setup  # noqa: E402

SCENES = ("cornellbox", "cornellbox_media", "bsdf_spheres/test_arealight_path.xml",
          "bsdf_spheres/test_texturedprincipledthin_path.xml",
          "floating_sphere/test_directional_direct.xml",
          "participating_media/test_hetero_sigmat_volpath.xml")


class Variants:
    """Switches the ``loops_once`` functions between ``once`` (as drpt has them) and
    ``twice`` (``OptimizeLoops`` on), and times the outermost call of them."""

    def __init__(self):
        import drjit as dr

        self.traced = 0.0
        self.depth = 0
        self.variant = "once"
        self.original = {}
        from drpt.render.loops import decorated
        from drpt.render.renderer import Renderer  # noqa: F401 (every integrator: their loops_once functions)

        for owner, name in decorated():
            once = owner.__dict__[name]
            self.original[(owner, name)] = once

            def timed(*a, once=once, **kw):
                if self.variant == "twice":
                    inner = once.__wrapped__

                    def call():
                        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, True):
                            return inner(*a, **kw)
                else:
                    def call():
                        return once(*a, **kw)
                self.depth += 1
                t0 = time.perf_counter()
                try:
                    return call()
                finally:
                    self.depth -= 1
                    if self.depth == 0:
                        self.traced += time.perf_counter() - t0

            setattr(owner, name, timed)

    def render(self, renderer, variant: str, seed: int):
        renderer.opt.seed = seed
        self.variant, self.traced = variant, 0.0
        c0, t0 = time.process_time(), time.perf_counter()
        image = renderer.render().image
        return image, {"trace": self.traced, "wall": time.perf_counter() - t0,
                       "cpu": time.process_time() - c0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--only", default="")
    a = ap.parse_args(argv)
    from drpt.render import frozen

    enabled, frozen.ENABLED = frozen.ENABLED, False  # every render traces its passes: the
    # tracing is what is measured (put back at the end: tests run main() in their process)
    try:
        return _run(a)
    finally:
        frozen.ENABLED = enabled


def _run(a) -> int:
    from drpt.errors import DrptError
    from drpt.render.renderer import Renderer

    only = [w for w in a.only.split(",") if w]
    variants = Variants()
    print(f"commit {_commit()}, {_cpu()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{a.rounds} rounds each way, ABBA")
    print("\n| scene | size | spp | trace ms twice | once | wall s twice | once | CPU s twice | once "
          "| once / twice: trace | wall | CPU |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases(list(SCENES), True, Path(tmp)):
            if case.name not in SCENES or (only and not any(w in case.name for w in only)):
                continue
            try:
                scene, opts, _ = setup(case, 192, 1_000_000)
            except DrptError as e:
                print(f"{case.name}: skipped: {e}", file=sys.stderr)
                continue
            r = Renderer(scene, opts)
            for v in ("twice", "once"):
                variants.render(r, v, 0)  # compile
            got = {"twice": [], "once": []}
            for k in range(a.rounds):
                order = ("twice", "once") if k % 2 == 0 else ("once", "twice")
                images = {}
                for v in order:
                    images[v], m = variants.render(r, v, k + 1)
                    got[v].append(m)
                assert np.array_equal(images["twice"], images["once"]), case.name
            med = {v: {q: statistics.median(m[q] for m in got[v]) for q in ("trace", "wall", "cpu")}
                   for v in got}
            t, o = med["twice"], med["once"]
            print(f"| {case.name} | {opts.width}x{opts.height} | {opts.spp} | {t['trace'] * 1e3:.1f} | "
                  f"{o['trace'] * 1e3:.1f} | {t['wall']:.3f} | {o['wall']:.3f} | {t['cpu']:.3f} | "
                  f"{o['cpu']:.3f} | {o['trace'] / t['trace']:.2f} | {o['wall'] / t['wall']:.2f} | "
                  f"{o['cpu'] / t['cpu']:.2f} |", flush=True)
    print(f"\nload {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
