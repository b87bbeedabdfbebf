"""Render time of this checkout's drpt against another commit's, interleaved in one process (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/commit_ab.py COMMIT SCENE... [--rounds 30] [--scale 4] [--spp N]
        [--size W H] [--bsdf MODE] [--integrator NAME]

``COMMIT``'s ``drpt/`` (``git archive``) is unpacked into a temporary folder as the package
``drpt_ab`` and imported beside this checkout's ``drpt``; each ``SCENE`` (an XML file or a
drpt scene) gets one :class:`~drpt.render.renderer.Renderer` from each package (its film
scaled ``--scale`` times, or ``--size``; an XML's ``spp`` define and the render's spp ``--spp``,
default the scene's own; ``--bsdf``, the material mode of drpt's own format, e.g. ``cook-torrance``
as the gallery renders the dining room; ``--integrator``, e.g. ``ptracer``), which renders once to
compile, then ``--rounds`` rounds of one render each, the
order alternating (AB, BA, ...) so that load from other processes falls on both. Round ``k``
uses seed ``k`` for both, set on the same renderer (as ``drpt.tools.converge.make_drpt``
renders: a pass traced before replays its recorded kernels, :mod:`drpt.render.frozen`); the
script says whether every pair of images (with their variance and second moments) was
bit-identical (a pure speed change must keep them so). It prints each side's median
seconds (``Renderer.render``, tracing included; the variance and moments read after it) and
the median and quartiles of the per-round ratios ``COMMIT / this``
(above 1: this checkout is faster), the measure to quote on a loaded machine, and the same
ratios of the process's CPU seconds (all its threads: the kernels' too), which waiting for a
core that another process holds does not inflate, and of the main thread's CPU seconds
(``time.thread_time``: the Python, the tracing, the host's numpy work and the main thread's
share of the kernels).

The commit's package resolves its relative imports inside itself; the few absolute ``drpt``
imports in it (the Mitsuba exporter) reach this checkout's, which rendering does not use.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import replace
from io import BytesIO
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def unpack(commit: str, into: Path) -> str:
    """``commit``'s ``drpt/`` as the package ``drpt_ab`` under ``into`` (put on ``sys.path``);
    returns the commit's short hash."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "drpt"], check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(into, filter="data")
    (into / "drpt").rename(into / "drpt_ab")
    return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", commit], check=True,
                          capture_output=True, text=True).stdout.strip()


def renderer(pkg: str, path: Path, scale: int, spp: int | None, size: list[int] | None = None,
             bsdf: str | None = None, integrator: str | None = None):
    """A renderer of ``path`` from package ``pkg`` (``drpt`` or ``drpt_ab``)."""
    opts = importlib.import_module(f"{pkg}.options")
    rend = importlib.import_module(f"{pkg}.render.renderer")
    sc = importlib.import_module(f"{pkg}.scene")
    defines = {"spp": str(spp)} if (spp and path.suffix == ".xml") else None
    scene = sc.load_scene(path, defines=defines) if defines else sc.load_scene(path)
    opt, scene = opts.with_scene_settings(opts.RenderOptions(progress=False), scene)
    if bsdf:
        opt = replace(opt, bsdf=bsdf)
    if size:
        opt, scene = opts.with_scene_settings(
            opts.RenderOptions(width=size[0], height=size[1], progress=False, bsdf=opt.bsdf),
            scene, given=frozenset({"size"}))
    elif scale != 1:
        opt, scene = opts.with_scene_settings(
            opts.RenderOptions(width=scale * opt.width, height=scale * opt.height, progress=False),
            scene, given=frozenset({"size"}))
    if spp:
        opt = replace(opt, spp=spp)
    if integrator:
        opt = replace(opt, integrator=integrator)
    return rend.Renderer(scene, opt)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("commit")
    ap.add_argument("scenes", nargs="+", type=Path)
    ap.add_argument("--rounds", type=int, default=30)
    ap.add_argument("--scale", type=int, default=4)
    ap.add_argument("--spp", type=int, default=None)
    ap.add_argument("--size", type=int, nargs=2, default=None)
    ap.add_argument("--bsdf", default=None)
    ap.add_argument("--integrator", default=None)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        short = unpack(a.commit, Path(tmp))
        sys.path.insert(0, tmp)
        from drpt.backend import ensure

        ensure()
        film = f"film {a.size[0]}x{a.size[1]}" if a.size else f"film x{a.scale}"
        print(f"{short} (A) against this checkout (B), {a.rounds} rounds alternating, {film}")
        for path in a.scenes:
            rs = {"A": renderer("drpt_ab", path, a.scale, a.spp, a.size, a.bsdf, a.integrator),
                  "B": renderer("drpt", path, a.scale, a.spp, a.size, a.bsdf, a.integrator)}
            for r in rs.values():
                r.render()
            ts: dict[str, list[float]] = {"A": [], "B": []}
            cpu: dict[str, list[float]] = {"A": [], "B": []}
            main: dict[str, list[float]] = {"A": [], "B": []}
            same = True
            for k in range(a.rounds):
                imgs = {}
                for side in ("A", "B") if k % 2 == 0 else ("B", "A"):
                    r = rs[side]
                    t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
                    r.opt = replace(r.opt, seed=k)  # the same renderer, as make_drpt renders
                    res = r.render()
                    ts[side].append(time.perf_counter() - t0)
                    cpu[side].append(time.process_time() - c0)
                    main[side].append(time.thread_time() - m0)
                    # (read after the clock: a result computes its variance and moments when
                    # first read, drpt.render.deferred)
                    imgs[side] = (res.image, res.variance, res.moment2)
                same &= all(x is None and y is None or x is not None and y is not None
                            and np.array_equal(x, y, equal_nan=True) for x, y in zip(imgs["A"], imgs["B"]))
            ta, tb = np.array(ts["A"]), np.array(ts["B"])
            ratio = ta / tb
            q1, q3 = np.quantile(ratio, [0.25, 0.75])
            cr = np.array(cpu["A"]) / np.array(cpu["B"])
            c1, c3 = np.quantile(cr, [0.25, 0.75])
            mr = np.array(main["A"]) / np.array(main["B"])
            m1, m3 = np.quantile(mr, [0.25, 0.75])
            ma, mb = (np.median(main[s]) * 1e3 for s in ("A", "B"))
            print(f"{path.name}: A {np.median(ta):.3f} s, B {np.median(tb):.3f} s; A / B per round: median "
                  f"{np.median(ratio):.3f} (quartiles {q1:.3f}-{q3:.3f}); process CPU A / B: median "
                  f"{np.median(cr):.3f} (quartiles {c1:.3f}-{c3:.3f}); main-thread CPU A "
                  f"{ma:.1f} ms, B {mb:.1f} ms, A / B: median {np.median(mr):.3f} (quartiles "
                  f"{m1:.3f}-{m3:.3f}); images bit-identical: {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
