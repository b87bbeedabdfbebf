"""Render time of one Mitsuba render-test file under variants of drpt's options, in turns in one
process (not a test): where a scene's time goes.

    PYTHONPATH=. .venv/bin/python benchmarks/render_variants.py FILE VARIANT... [--rounds 6]
        [--min-size 192] [--max-samples 1000000]

``FILE`` is a path under the corpus (``../shared/corpus/mitsuba-data/tests/scenes``), rendered
as ``benchmarks/equal_time_vs_mitsuba.py`` renders it (its settings, the film scaled to
``--min-size`` pixels, the spp cut to ``--max-samples`` per image). Each ``VARIANT`` is ``base`` (those options) or
comma-separated ``key=value`` changes: ``max_depth=N``, ``unroll=N`` (the deepest path traced
as straight-line code, :data:`drpt.render.integrators.path.UNROLLED_MAX_DEPTH`, set while that
variant traces; its default 3), or any string field of
:class:`~drpt.options.RenderOptions` (``mode=wavefront``, ``light_sampler=uniform``). Every
variant renders once to compile, then the variants take turns for ``--rounds`` rounds (the
order reversed every other round, so that load from other processes falls on all). Prints
each variant's median seconds and the median of the per-round ratios first variant / this
(above 1: this variant is faster), the measure to quote on a loaded machine; ``main`` returns
them (``{variant: (median seconds, median ratio)}``) and restores ``UNROLLED_MAX_DEPTH``.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import equal_time_vs_mitsuba as eq
import numpy as np

import drpt.render.integrators.path as path_module
from drpt.render.renderer import Renderer


def options_of(base, variant: str):
    """``(options, unroll)``: ``base`` changed as ``variant`` says (the module docstring)."""
    changes = dict(x.split("=", 1) for x in variant.split(",")) if variant != "base" else {}
    unroll = int(changes.pop("unroll", path_module.UNROLLED_MAX_DEPTH))
    opts = base
    for key, value in changes.items():
        if key == "max_depth":
            opts = replace(opts, path=replace(opts.path, max_depth=int(value)))
        else:
            opts = replace(opts, **{key: value})
    return opts, unroll


def main(argv=None) -> dict[str, tuple[float, float]]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("file")
    ap.add_argument("variants", nargs="+")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--min-size", type=int, default=192)
    ap.add_argument("--max-samples", type=int, default=1_000_000)
    a = ap.parse_args(argv)
    default_unroll = path_module.UNROLLED_MAX_DEPTH
    scene, base, _ = eq.setup(eq.Case(a.file, 2.0, eq.CORPUS / a.file), a.min_size, a.max_samples)
    print(f"{a.file}: {base.width}x{base.height}, {base.spp} spp, max_depth {base.path.max_depth}")
    renderers, unrolls = {}, {}
    try:
        for v in a.variants:
            opts, unrolls[v] = options_of(base, v)
            path_module.UNROLLED_MAX_DEPTH = unrolls[v]
            renderers[v] = Renderer(scene, opts)
            renderers[v].render()
    finally:
        path_module.UNROLLED_MAX_DEPTH = default_unroll
    seconds = {v: [] for v in a.variants}
    try:
        for k in range(a.rounds):
            for v in (a.variants if k % 2 == 0 else a.variants[::-1]):
                path_module.UNROLLED_MAX_DEPTH = unrolls[v]  # (read while the render traces)
                t = time.perf_counter()
                renderers[v].render()
                seconds[v].append(time.perf_counter() - t)
    finally:
        path_module.UNROLLED_MAX_DEPTH = default_unroll
    first = np.array(seconds[a.variants[0]])
    out = {}
    for v in a.variants:
        s = np.array(seconds[v])
        out[v] = (float(np.median(s)), float(np.median(first / s)))
        print(f"{v}: median {out[v][0]:.3f} s, {a.variants[0]} / this {out[v][1]:.3f}")
    return out


if __name__ == "__main__":
    main()
