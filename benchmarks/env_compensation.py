"""MIS compensation of the sky's next-event density, on against off (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/env_compensation.py [--rounds 32] [--min-size 96]
        [--max-samples 250000] [--only WORD,...] [--json FILE] [--agree SPP]

The scenes are those of ``equal_time_vs_mitsuba.py`` (``--only`` keeps those whose name has one
of its words) that have an environment map and that drpt path traces, at that benchmark's
settings (:func:`equal_time_vs_mitsuba.setup`: the file's film scaled to ``--min-size``, its spp
cut to ``--max-samples`` per image). Each renders with ``--env-compensation off`` and ``on``
(:meth:`drpt.render.lights.envmap.EnvironmentLight.compensated`), once each to compile, then in
turns for ``--rounds`` rounds, round ``k`` with seed ``k``
(:func:`drpt.tools.converge.efficiency_rounds`). Per scene it prints the per-pixel variance
ratio on / off (the mean over pixels of each pixel's variance across the rounds) with its
jackknife standard error over the rounds, the median seconds' ratio, the efficiency ratio
(``1 / (seconds x variance)``) and the ratio of the mean images (a bias check: 1 within the
noise). Both settings render the same estimand; the ratio is what to read, the rounds
interleave so that load from other processes slows both. Ends with the geometric means.

``--agree SPP`` instead renders each scene once per setting at its authored size with ``SPP``
samples per pixel (seeds 11 and 12: independent images) and prints the largest 4x4-block
|z| of the two images (:func:`drpt.testing.block_z`) and the ratio of their means: the
unbiasedness check across the BSDFs and media of these scenes (|z| of ~3.5 is what that many
block channels of two images of the same expectation reach).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import equal_time_vs_mitsuba as eq  # noqa: E402 (the sibling benchmark: its scenes and settings)
from variance_vs_mitsuba import _jackknife, _ratio  # noqa: E402 (the variance ratio and its error, paired by seed)


def measure(scene, opts, rounds: int) -> dict:
    """The on / off ratios of one scene (see the module docs)."""
    import time

    from drpt.render.renderer import Renderer

    renderers = {c: Renderer(scene, replace(opts, env_compensation=c)) for c in ("off", "on")}
    sky = renderers["on"].scene.sky
    env = getattr(sky, "env", None)
    if not getattr(getattr(env, "env", env), "offset", 0.0) > 0.0:  # (through a rotation)
        return {}  # no sky, or a nearly constant one: nothing compensated
    for r in renderers.values():
        r.derive(replace(r.opt, seed=999_999)).render()
    images = {c: [] for c in renderers}
    times = {c: [] for c in renderers}
    for k in range(rounds):
        for c in ("off", "on") if k % 2 == 0 else ("on", "off"):  # in turns: load falls on both alike
            r = renderers[c]
            t = time.perf_counter()
            images[c].append(r.derive(replace(r.opt, seed=k)).render().image.astype(np.float64))
            times[c].append(time.perf_counter() - t)
    on, off = np.stack(images["on"]), np.stack(images["off"])
    var = _ratio(on, off)
    sec = float(np.median(times["on"]) / np.median(times["off"]))
    return {"variance_ratio": var, "variance_error": _jackknife(on, off), "seconds_ratio": sec,
            "efficiency_ratio": 1.0 / (var * sec), "mean_ratio": float(on.mean() / off.mean()),
            "seconds_off": float(np.median(times["off"]))}


def agree(scene, spp: int, opts=None) -> dict:
    """``--agree``: the two settings' images of ``scene`` at its own size (a bundled scene's:
    ``opts``), compared by block."""
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.testing import block_z

    if opts is None:
        opts, scene = with_scene_settings(RenderOptions(progress=False), scene)
    res = {c: Renderer(scene, replace(opts, spp=spp, seed=seed, env_compensation=c)).render()
           for c, seed in (("on", 11), ("off", 12))}
    z = block_z(res["on"].image, res["on"].variance, res["off"].image, res["off"].variance, block=4)
    return {"width": opts.width, "height": opts.height, "max_z": float(np.abs(z).max()), "blocks": int(z.size),
            "mean_ratio": float(res["on"].image.mean() / res["off"].image.mean())}


def main(argv=None) -> list[dict]:
    from drpt.backend import ensure
    from drpt.errors import DrptError
    from drpt.scene import load_scene
    from drpt.scene.model import Skybox

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=32)
    ap.add_argument("--min-size", type=int, default=96)
    ap.add_argument("--max-samples", type=int, default=250_000)
    ap.add_argument("--only", default="envmap,bumpmap,normalmap,textured,living_room,showcase",
                    help="comma-separated words; keep scenes whose name has one")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--agree", type=int, default=0, metavar="SPP",
                    help="compare the two settings' images by block z at the scenes' own sizes instead")
    a = ap.parse_args(argv)
    ensure()
    load0 = os.getloadavg()[0]
    rows = []
    print(f"commit {eq._commit()}, {eq._cpu()}, {os.cpu_count()} cores; {a.rounds} rounds, min size "
          f"{a.min_size}, max samples {a.max_samples}; load average {load0:.1f} at the start")
    if not a.agree:
        print("\n| scene | size | spp | variance on / off | seconds on / off | efficiency on / off "
              "| mean on / off |\n|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="drpt-envcomp-") as tmp:
        for case in eq.cases([w for w in a.only.split(",") if w], True, Path(tmp)):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    scene, opts, _ = eq.setup(case, a.min_size, a.max_samples)
            except DrptError as e:
                print(f"{case.name}: skipped: {str(e).splitlines()[0]}", file=sys.stderr)
                continue
            if not any(isinstance(light, Skybox) for light in scene.lights):
                continue
            if a.agree:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    g = (agree(load_scene(case.path), a.agree) if case.bundled is None
                         else agree(scene, a.agree, opts))
                print(f"{case.name}: {g['width']}x{g['height']}, {a.agree} spp: max |z| {g['max_z']:.2f} over "
                      f"{g['blocks']} block channels, mean on / off {g['mean_ratio']:.4f}", flush=True)
                continue
            r = measure(scene, opts, a.rounds)
            if not r:
                continue
            row = {"scene": case.name, "width": opts.width, "height": opts.height, "spp": opts.spp,
                   **r, "load": os.getloadavg()[0]}
            rows.append(row)
            print(f"| {case.name} | {opts.width}x{opts.height} | {opts.spp} | {r['variance_ratio']:.3f} +- "
                  f"{r['variance_error']:.3f} | {r['seconds_ratio']:.3f} | {r['efficiency_ratio']:.2f} "
                  f"| {r['mean_ratio']:.4f} |", flush=True)
            if a.json is not None:
                a.json.write_text(json.dumps({"commit": eq._commit(), "cpu": eq._cpu(), "load_at_start": load0,
                                              "args": {**vars(a), "json": str(a.json)}, "rows": rows}, indent=1))
    if rows:
        g = {k: math.exp(np.mean([math.log(r[k]) for r in rows]))
             for k in ("variance_ratio", "seconds_ratio", "efficiency_ratio")}
        print(f"\ngeometric means: variance {g['variance_ratio']:.3f}, seconds {g['seconds_ratio']:.3f}, "
              f"efficiency {g['efficiency_ratio']:.3f}; load average {os.getloadavg()[0]:.1f} at the end")
    return rows


if __name__ == "__main__":
    main()
