"""Where a small render's time goes outside its kernel (not a test).

Renders each scene as ``benchmarks/equal_time_vs_mitsuba.py`` does (its :func:`setup`: the
file's own settings, the film scaled to at least 192 pixels, at most 1e6 samples; through
:func:`drpt.tools.converge.make_drpt`), once to compile, then ``--rounds`` times, and splits
each render into phases, with a ``dr.sync_thread()`` inserted after the path kernel's launch so
that the kernel's execution is a phase of its own:

* ``trace``: the Python tracing of the symbolic loops: the outermost calls of every
  ``loops_once`` function (:mod:`drpt.render.loops`: the integrator's, the splatting film's
  gather, ray queries outside them), wherever in the render they fall (each phase below is
  given without them);
* ``setup``: the rest before the launch (the pass's lanes, the sampler, the camera rays);
* ``launch``: ``dr.eval`` of the kernel (code generation, the kernel cache's look-up, the
  launch); where the pass is frozen (:mod:`drpt.render.frozen`: every render after the
  first), the replay's call: its inputs' traversal and the recorded kernels' launches;
* ``kernel``: its execution, to the ``dr.sync_thread()``;
* ``readback``: the pixel sums to numpy (``Renderer._trace_pass`` after the kernel: where a
  pixel has several lanes, mostly the block sums that add them, :func:`drpt.render.film.lane_sums`;
  in a frozen pass they are among the replayed launches, so in ``kernel``; with a tent or
  gaussian filter ``Renderer._trace_splat_pass``'s film gather, its kernel too);
* ``finish``: the image, its variance and moments from the merged sums
  (:func:`drpt.render.renderer.finish`);
* ``rest``: the render less all of the above (the plan, the chunk merge, the checks).

Each phase is given as the main thread's CPU time (``time.thread_time``, which load from
other processes does not inflate) and as wall time, medians over the rounds. The main thread
also works inside the kernel, so the ``kernel`` CPU column is not the kernel's cost.

Run: PYTHONPATH=. .venv/bin/python benchmarks/render_overhead.py [--rounds 15]
[--only WORD,...] [--integrator NAME] [--sampler NAME] [--filter NAME] (default scenes:
directional, mesh_attributes, texturedprincipledthin; ``--only`` keeps the scenes whose name
contains a word, and a word that is a scene's whole name, such as ``cornellbox``, that scene
alone; the three flags replace the scene's own settings). To compare two checkouts, run this
script with the other's root first on ``PYTHONPATH`` (the first line names the drpt imported).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys
import tempfile
import time
from dataclasses import replace
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
        from drpt.render.loops import decorated

        #: the clock of the next render: ``time.thread_time`` or ``time.perf_counter``
        self.clock = time.thread_time
        self.t: dict[str, float] = {}
        #: ``(start, end)`` of each outermost ``loops_once`` call of the render
        self.traced: list[tuple[float, float]] = []
        self.depth = 0

        def clock():
            return self.clock()

        blocks_for = R.llvm_tuning.blocks_for
        t = self.t
        # what __init__ replaces, put back by close() (tests run main() in their process)
        self._saved = [(R, "llvm_tuning", R.llvm_tuning), (R, "finish", R.finish),
                       (R.Renderer, "_trace_pass", R.Renderer._trace_pass),
                       (R.Renderer, "_trace_splat_pass", R.Renderer._trace_splat_pass),
                       (R.FrozenPass, "__call__", R.FrozenPass.__call__)]
        self._saved += [(owner, name, owner.__dict__[name]) for owner, name in decorated()]

        @contextlib.contextmanager
        def launch():  # the render's first launch: its start, its return, its kernel's end
            first = "enter" not in t
            if first:
                t["enter"] = clock()
            yield
            if first:
                t["launched"] = clock()
                dr.sync_thread()
                t["done"] = clock()

        @contextlib.contextmanager
        def stamped(n):
            with launch(), blocks_for(n):
                yield

        R.llvm_tuning = type("Tuning", (), {"blocks_for": staticmethod(stamped)})
        replay = R.FrozenPass.__call__

        def stamped_replay(self_, *a, **kw):  # a frozen pass: its replay is the launch
            with launch():
                return replay(self_, *a, **kw)

        R.FrozenPass.__call__ = stamped_replay

        def read_stamped(fn):  # a pass's kernel and readback (the splatting film's gather too)
            def call(*a, **kw):
                out = fn(*a, **kw)
                t.setdefault("read", clock())
                return out
            return call

        R.Renderer._trace_pass = read_stamped(R.Renderer._trace_pass)
        R.Renderer._trace_splat_pass = read_stamped(R.Renderer._trace_splat_pass)
        finish = R.finish

        def timed_finish(*a, **kw):
            t["finish0"] = clock()
            out = finish(*a, **kw)
            t["finish1"] = clock()
            return out

        R.finish = timed_finish
        for owner, name in decorated():  # every integrator's, the film's, the ray queries'
            setattr(owner, name, self._timed(owner.__dict__[name]))

    def close(self) -> None:
        """Put back what :meth:`__init__` replaced."""
        for owner, name, value in self._saved:
            setattr(owner, name, value)

    def _timed(self, fn):
        """``fn`` with its outermost calls' intervals kept in :attr:`traced`."""
        def call(*a, **kw):
            self.depth += 1
            t0 = self.clock() if self.depth == 1 else 0.0
            try:
                return fn(*a, **kw)
            finally:
                self.depth -= 1
                if self.depth == 0:
                    self.traced.append((t0, self.clock()))
        return call

    def render(self, render, spp: int, seed: int) -> dict[str, float]:
        t = self.t
        t.clear()
        self.traced.clear()
        t0 = self.clock()
        render(spp, seed)
        end = self.clock()
        spans = {"setup": (t0, t["enter"]), "launch": (t["enter"], t["launched"]),
                 "kernel": (t["launched"], t["done"]), "readback": (t["done"], t["read"]),
                 "finish": (t["finish0"], t["finish1"])}

        def traced_in(a, b):  # the tracing inside [a, b)
            return sum(max(0.0, min(b, e) - max(a, s)) for s, e in self.traced)

        out = {"trace": sum(e - s for s, e in self.traced)}
        out |= {p: b - a - traced_in(a, b) for p, (a, b) in spans.items()}
        out["rest"] = end - t0 - sum(out.values())
        out["total"] = end - t0
        return out


def main(argv=None) -> int:
    from drpt.tools.converge import make_drpt

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--only", default=DEFAULT)
    for flag in ("--integrator", "--sampler", "--filter"):
        ap.add_argument(flag, help="instead of the scene's own (default: the scene's)")
    a = ap.parse_args(argv)
    only = [w for w in a.only.split(",") if w]
    given = {k: v for k, v in (("integrator", a.integrator), ("sampler", a.sampler), ("filter", a.filter)) if v}
    timer = Clock()
    import drpt

    print(f"commit {_commit()}, drpt {Path(drpt.__file__).parent.parent}, {_cpu()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; {a.rounds} renders each; ms, main-thread CPU (wall); {given or ''}")
    print("\n| scene | " + " | ".join(PHASES) + " | total |\n|---|" + "---|" * (len(PHASES) + 1))
    try:
        with tempfile.TemporaryDirectory() as tmp:
            found = cases(only, True, Path(tmp))
            names = {c.name for c in found}
            exact = [w for w in only if w in names]  # a word that names a case picks that case alone
            for case in found:
                if any(w in case.name and w != case.name and w in exact for w in only):
                    continue
                scene, opts, _ = setup(case, 192, 1_000_000)
                if given:
                    opts = replace(opts, **given).validate()
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
    finally:
        timer.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
