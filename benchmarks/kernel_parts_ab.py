"""What a part of the path kernel costs: renders with that part taken out or doubled, in turns
with the render as it is, in one process (not a test; the images of the variants are not the
scene's, only their time is read).

    PYTHONPATH=. .venv/bin/python benchmarks/kernel_parts_ab.py SCENE_WORD [--rounds 10]
        [--parts shadows,closest,beckmann,spheres]

``SCENE_WORD`` picks a scene of ``benchmarks/equal_time_vs_mitsuba.py`` (its setup: the file's
settings, the film scaled to at least 192 pixels); each variant gets its own
:class:`~drpt.render.renderer.Renderer`, renders once to compile, then ``--rounds`` rounds of
one render each, the variants' order alternating (ABC, CBA, ...), round ``k`` with seed ``k``.
Printed per variant: the median render's wall and process-CPU seconds and the medians of the
per-round ratios ``as is / variant`` (above 1: the variant is faster, the part cost that
share). The parts (class attributes patched while the variant traces its kernel):

* ``shadows``: the inline accelerator's shadow test answers False (what the shadow rays cost);
* ``closest``: the inline accelerator's closest-hit query runs twice (what one more costs),
  the second on a direction multiplied by an opaque 1 so that Dr.Jit cannot share the two;
* ``beckmann``: Beckmann's visible-normal routine replaced by GGX's (what its Halley steps on
  ``erf``/``erfinv`` cost);
* ``spheres``: the inline accelerator leaves the spheres out (closest hit and shadow test);
* ``embree_shadows``, ``embree_camera``, ``embree_bounces``: Embree's any-hit queries, its
  closest-hit queries of coherent packets (camera rays) or of the others run twice (what each
  kind of query costs; the second on a direction times an opaque 1, its answer folded into
  the first's so that it is not dropped).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import drjit as dr
from drjit.auto import Bool, Float

sys.path.insert(0, str(Path(__file__).resolve().parent))
from equal_time_vs_mitsuba import _commit, _cpu, cases, setup  # noqa: E402

import drpt.accel.embree as embree  # noqa: E402
import drpt.accel.inline as inline  # noqa: E402
import drpt.render.bsdf.microfacet as microfacet  # noqa: E402
from drpt.tools.converge import make_drpt  # noqa: E402


def _no_shadows(self, o, d, tmax, active=True, coherent=False):
    return dr.zeros(Bool, dr.width(Float(tmax)))


_trace = inline.InlineList._trace


def _trace_twice(self, o, d, tmax, active):
    one = dr.opaque(Float, 1.0)
    a = _trace(self, o, d * one, tmax, active)
    b = _trace(self, o, d, tmax, active)
    return tuple(dr.select(a[0] < -1.0, x, y) for x, y in zip(a, b, strict=True))


_tests = inline.InlineList._tests


def _no_spheres(self, o, d):
    for test in _tests(self, o, d):
        j = test(Float(1.0))[4]  # the test's primitive (traced, unused: Dr.Jit drops it)
        if not (isinstance(j, int) and self.F <= j < self.F + self.S):
            yield test


_ggx = microfacet.Distribution._slopes11_ggx

_query = embree.EmbreeAccel._query


def _embree_twice(kind: str):
    """``EmbreeAccel._query`` tracing the queries of ``kind`` (``shadows``, ``camera``:
    coherent closest hits, ``bounces``: the other closest hits) a second time."""
    def query(self, o, d, tfar, active, shadow, coherent=False):
        out = _query(self, o, d, tfar, active, shadow, coherent)
        if shadow != (kind == "shadows"):
            return out
        lanes = Bool(active) if shadow else Bool(active) & (Bool(coherent) if kind == "camera" else ~Bool(coherent))
        again = _query(self, o, d * dr.opaque(Float, 1.0), tfar, lanes, shadow, coherent)
        if shadow:
            return (out[0] | (again[0] & ~again[0]),)
        return (out[0] | (again[0] & (again[1] < 0.0)), *out[1:])
    return query

PARTS = {
    "shadows": (inline.InlineList, "occluded", _no_shadows),
    "closest": (inline.InlineList, "_trace", _trace_twice),
    "beckmann": (microfacet.Distribution, "_slopes11_beckmann", lambda self, cos_i, u: _ggx(self, cos_i, u)),
    "spheres": (inline.InlineList, "_tests", _no_spheres),
    "embree_shadows": (embree.EmbreeAccel, "_query", _embree_twice("shadows")),
    "embree_camera": (embree.EmbreeAccel, "_query", _embree_twice("camera")),
    "embree_bounces": (embree.EmbreeAccel, "_query", _embree_twice("bounces")),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--parts", default="shadows,closest,beckmann,spheres")
    a = ap.parse_args(argv)
    parts = [p for p in a.parts.split(",") if p]
    for p in parts:
        if p not in PARTS:
            ap.error(f"unknown part {p!r} (one of {', '.join(PARTS)})")
    variants = ["as is", *parts]

    def patched(v):
        if v == "as is":
            return None
        cls, name, fn = PARTS[v]
        old = cls.__dict__[name]
        setattr(cls, name, fn)
        return cls, name, old

    def restore(saved):
        if saved is not None:
            setattr(saved[0], saved[1], saved[2])

    print(f"commit {_commit()}, {_cpu()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{a.rounds} rounds")
    with tempfile.TemporaryDirectory() as tmp:
        case = next(iter(cases([a.scene], True, Path(tmp))))
        scene, opts, _ = setup(case, 192, 1_000_000)
        renders = {}
        for v in variants:
            saved = patched(v)
            try:
                renders[v] = make_drpt(scene, opts)[1]
                renders[v](opts.spp, 0)
            finally:
                restore(saved)
        wall = {v: [] for v in variants}
        cpu = {v: [] for v in variants}
        for k in range(a.rounds):
            for v in (variants if k % 2 == 0 else variants[::-1]):
                saved = patched(v)
                try:
                    t0, c0 = time.perf_counter(), time.process_time()
                    renders[v](opts.spp, k + 1)
                    wall[v].append(time.perf_counter() - t0)
                    cpu[v].append(time.process_time() - c0)
                finally:
                    restore(saved)
        print(f"{case.name}, {opts.width}x{opts.height}, {opts.spp} spp, load {os.getloadavg()[0]:.1f} at the end")
        print("| variant | wall s | CPU s | as is / variant, wall | as is / variant, CPU |\n|---|---|---|---|---|")
        for v in variants:
            rw = statistics.median(x / y for x, y in zip(wall["as is"], wall[v], strict=True))
            rc = statistics.median(x / y for x, y in zip(cpu["as is"], cpu[v], strict=True))
            print(f"| {v} | {statistics.median(wall[v]):.3f} | {statistics.median(cpu[v]):.3f} | {rw:.3f} | {rc:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
