"""Where a small render's time goes outside its kernel (not a test).

Renders each scene as ``benchmarks/equal_time_vs_mitsuba.py`` does (its :func:`setup`: the
file's own settings, the film scaled to at least 192 pixels, at most 1e6 samples; through
:func:`drpt.tools.converge.make_drpt`), once to compile, then ``--rounds`` times, and splits
each render into phases, with a ``dr.sync_thread()`` inserted after the path kernel's launch so
that the kernel's execution is a phase of its own:

* ``trace``: the Python tracing of the integrator (the outermost ``loops_once`` method:
  :mod:`drpt.render.loops`);
* ``setup``: the rest before the launch (the pass's lanes, the sampler, the camera rays);
* ``launch``: ``dr.eval`` of the kernel (code generation, the kernel cache's look-up, the
  launch);
* ``kernel``: its execution, to the ``dr.sync_thread()``;
* ``readback``: the pixel sums to numpy (``Renderer._trace_pass`` after the kernel);
* ``finish``: the image, its variance and moments from the merged sums
  (:func:`drpt.render.renderer.finish`);
* ``rest``: the render less all of the above (the plan, the chunk merge, the checks).

Each phase is given as the main thread's CPU time (``time.thread_time``, which load from
other processes does not inflate) and as wall time, medians over the rounds. The main thread
also works inside the kernel, so the ``kernel`` CPU column is not the kernel's cost.

Run: PYTHONPATH=. .venv/bin/python benchmarks/render_overhead.py [--rounds 15]
[--only WORD,...] (default scenes: directional, mesh_attributes, texturedprincipledthin)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the sibling benchmark: its scenes, their sizes and spp, the CPU's name and the commit
from equal_time_vs_mitsuba import _commit, _cpu, cases, setup  # noqa: E402

DEFAULT = "test_directional_direct,test_mesh_attributes_1_face_direct,texturedprincipledthin"
PHASES = ("trace", "setup", "launch", "kernel", "readback", "finish", "rest")


class Clock:
    """Patches the renderer to stamp its phases; :meth:`render` returns them (seconds)."""

    def __init__(self):
        import drjit as dr

        import drpt.render.renderer as R
        from drpt.render.integrators.path import PathIntegrator

        #: the clock of the next render: ``time.thread_time`` or ``time.perf_counter``
        self.clock = time.thread_time
        self.t: dict[str, float] = {}

        def clock():
            return self.clock()

        blocks_for = R.llvm_tuning.blocks_for
        t = self.t

        @contextlib.contextmanager
        def stamped(n):
            first = "enter" not in t
            if first:
                t["enter"] = clock()
            with blocks_for(n):
                yield
            if first:
                t["launched"] = clock()
                dr.sync_thread()
                t["done"] = clock()

        R.llvm_tuning = type("Tuning", (), {"blocks_for": staticmethod(stamped)})
        trace_pass = R.Renderer._trace_pass

        def timed_pass(*a, **kw):
            out = trace_pass(*a, **kw)
            t.setdefault("read", clock())
            return out

        R.Renderer._trace_pass = timed_pass

        def timed(key, fn):  # ``fn`` with its last call's duration kept as ``t[key]``
            def call(*a, **kw):
                t0 = clock()
                out = fn(*a, **kw)
                t[key] = clock() - t0
                return out
            return call

        R.finish = timed("finish", R.finish)
        PathIntegrator.sample_sequence = timed("trace", PathIntegrator.__dict__["sample_sequence"])

    def render(self, render, spp: int, seed: int) -> dict[str, float]:
        t = self.t
        t.clear()
        t0 = self.clock()
        render(spp, seed)
        total = self.clock() - t0
        out = {"trace": t["trace"], "setup": t["enter"] - t0 - t["trace"],
               "launch": t["launched"] - t["enter"], "kernel": t["done"] - t["launched"],
               "readback": t["read"] - t["done"], "finish": t["finish"]}
        out["rest"] = total - sum(out.values())
        out["total"] = total
        return out


def main(argv=None) -> int:
    from drpt.tools.converge import make_drpt

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--only", default=DEFAULT)
    a = ap.parse_args(argv)
    only = [w for w in a.only.split(",") if w]
    timer = Clock()
    print(f"commit {_commit()}, {_cpu()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{a.rounds} renders each; ms, main-thread CPU (wall)")
    print("\n| scene | " + " | ".join(PHASES) + " | total |\n|---|" + "---|" * (len(PHASES) + 1))
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases(only, True, Path(tmp)):
            scene, opts, _ = setup(case, 192, 1_000_000)
            _, render = make_drpt(scene, opts)
            render(opts.spp, 0)
            rows = {"cpu": [], "wall": []}
            for k in range(a.rounds):  # the two clocks in turns: each render timed by one
                clock = "cpu" if k % 2 == 0 else "wall"
                timer.clock = time.thread_time if clock == "cpu" else time.perf_counter
                rows[clock].append(timer.render(render, opts.spp, k + 1))
            med = {c: {p: statistics.median(r[p] for r in rows[c]) * 1e3 for p in (*PHASES, "total")}
                   for c in rows}
            print(f"| {case.name} | " + " | ".join(f"{med['cpu'][p]:.1f} ({med['wall'][p]:.1f})"
                                                  for p in (*PHASES, "total")) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
