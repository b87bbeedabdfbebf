"""A low-discrepancy sampler's ``step`` as one value for all lanes against one per lane:
Python tracing and time per render, A/B in one process (not a test).

Every symbolic loop that draws from a sampler carries it as loop state, and Dr.Jit records
a loop's body again for a loop variable that the body reads but does not change and whose
width is not the loop's (docs/architecture.md, "A loop body may be recorded twice").
:class:`~drpt.render.sampler.LDSampler` broadcasts a ``step`` given as one value to the
lanes' width (variant ``wide``); variant ``narrow`` makes it as it was made before, one
value for all lanes, so Whitted's loop and the splatted path and volpath loops are recorded
twice (the integrators that widened the sampler themselves, ``sample_sequence``, ptracer and
bdpt, would be too: use this script on whitted and on tent or gaussian filters). For each
scene one renderer renders once per variant to compile, then ``--rounds`` rounds of one
render each way, the order alternating (ABBA...) so that load from other processes falls on
both; round ``k`` renders seed ``k`` both ways and the two images must be bit-identical
(checked). Per render: ``trace``, the time inside the outermost ``loops_once`` calls (the
Python tracing of the loops and all they call), as the main thread's CPU time
(``time.thread_time``) and wall time; the render's wall time and main-thread CPU time.
Medians; ``wide / narrow`` is the ratio of the medians.

Scenes as ``benchmarks/render_overhead.py`` takes them (its ``--only``, ``--integrator``,
``--sampler``, ``--filter``; the sizes and spp of ``benchmarks/equal_time_vs_mitsuba.py``).

Run: PYTHONPATH=. .venv/bin/python benchmarks/sampler_step_ab.py --only cornellbox
--integrator whitted [--rounds 12]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the sibling benchmark: its scenes, their sizes and spp, the CPU's name and the commit
from equal_time_vs_mitsuba import _commit, _cpu, cases, setup  # noqa: E402


def _narrow_init(self, key=None, index=None, step=None):
    """``LDSampler.__init__`` keeping ``step`` and ``key`` as given (one value for all lanes)."""
    import drjit as dr
    from drjit.auto import UInt32

    self.key = UInt32(0) if key is None else UInt32(key)
    self.index = UInt32(0) if index is None else UInt32(index)
    self.step = UInt32(1) if step is None else UInt32(step)
    self.dim = dr.zeros(UInt32, dr.width(self.index))


class Variants:
    """Switches ``LDSampler.__init__`` between ``wide`` (drpt's) and ``narrow``, and times the
    outermost calls of the ``loops_once`` functions."""

    def __init__(self):
        from drpt.render.loops import decorated
        from drpt.render.renderer import Renderer  # noqa: F401 (every integrator: their loops_once functions)
        from drpt.render.sampler import LDSampler

        self.sampler, self.wide = LDSampler, LDSampler.__init__
        self.cpu = self.wall = 0.0
        self.depth = 0
        for owner, name in decorated():
            fn = owner.__dict__[name]

            def timed(*a, fn=fn, **kw):
                self.depth += 1
                c0, t0 = time.thread_time(), time.perf_counter()
                try:
                    return fn(*a, **kw)
                finally:
                    self.depth -= 1
                    if self.depth == 0:
                        self.cpu += time.thread_time() - c0
                        self.wall += time.perf_counter() - t0

            setattr(owner, name, timed)

    def render(self, renderer, variant: str, seed: int):
        self.sampler.__init__ = self.wide if variant == "wide" else _narrow_init
        renderer.opt.seed = seed
        self.cpu = self.wall = 0.0
        c0, t0 = time.thread_time(), time.perf_counter()
        image = renderer.render().image
        out = {"trace cpu": self.cpu, "trace wall": self.wall, "cpu": time.thread_time() - c0,
               "wall": time.perf_counter() - t0}
        self.sampler.__init__ = self.wide
        return image, out


QUANTITIES = ("trace cpu", "trace wall", "cpu", "wall")


def main(argv=None) -> int:
    from drpt.render.renderer import Renderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=12)
    ap.add_argument("--only", default="cornellbox")
    for flag in ("--integrator", "--sampler", "--filter"):
        ap.add_argument(flag, help="instead of the scene's own (default: the scene's)")
    a = ap.parse_args(argv)
    only = [w for w in a.only.split(",") if w]
    given = {k: v for k, v in (("integrator", a.integrator), ("sampler", a.sampler), ("filter", a.filter)) if v}
    variants = Variants()
    print(f"commit {_commit()}, {_cpu()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{a.rounds} rounds each way, ABBA; {given or ''}; ms (trace), s (render), medians")
    print("\n| scene | size, spp | trace CPU narrow -> wide | trace wall | render CPU | render wall "
          "| wide / narrow: trace CPU, wall, render CPU, wall |\n|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        found = cases(only, True, Path(tmp))
        names = {c.name for c in found}
        exact = [w for w in only if w in names]  # a word that names a case picks that case alone
        for case in found:
            if any(w in case.name and w != case.name for w in exact):
                continue
            scene, opts, _ = setup(case, 192, 1_000_000)
            if given:
                opts = replace(opts, **given).validate()
            r = Renderer(scene, opts)
            for v in ("narrow", "wide"):
                variants.render(r, v, 0)  # compile
            got = {"narrow": [], "wide": []}
            for k in range(a.rounds):
                order = ("narrow", "wide") if k % 2 == 0 else ("wide", "narrow")
                images = {}
                for v in order:
                    images[v], m = variants.render(r, v, k + 1)
                    got[v].append(m)
                assert np.array_equal(images["narrow"], images["wide"], equal_nan=True), case.name
            med = {v: {q: statistics.median(m[q] for m in got[v]) for q in QUANTITIES} for v in got}
            n, w = med["narrow"], med["wide"]
            print(f"| {case.name} | {opts.width}x{opts.height}, {opts.spp} | "
                  f"{n['trace cpu'] * 1e3:.1f} -> {w['trace cpu'] * 1e3:.1f} | "
                  f"{n['trace wall'] * 1e3:.1f} -> {w['trace wall'] * 1e3:.1f} | "
                  f"{n['cpu']:.3f} -> {w['cpu']:.3f} | {n['wall']:.3f} -> {w['wall']:.3f} | "
                  + ", ".join(f"{w[q] / n[q]:.2f}" for q in QUANTITIES) + " |", flush=True)
    print(f"\nload {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
