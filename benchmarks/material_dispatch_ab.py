"""Render time of the material table's two dispatches, interleaved A/B (not a test).

``MaterialTable.dispatch`` ``"kinds"`` (each lobe kind's case in its own symbolic
``dr.if_stmt``, the default) against ``"masked"`` (every kind traced for every lane, merged
with ``select``) on scenes with several BSDF kinds, and on the one-kind Cornell box as the
control (its kernel is the same both ways: ratio 1 up to noise):

* Mitsuba's sphere grids (``bsdf_spheres/test_{arealight,constant,envmap,pointlight}_path.xml``
  of ``../shared/corpus``, skipped when absent): eleven materials of nine kinds;
* ``veach_mis.xml`` (``tests/data/xml``) and ``living_room``
  (:mod:`drpt.tools.scenegen.living_room`, generated into a temporary folder);
* ``materials_cornell`` (:mod:`drpt.tools.scenegen.materials_cornell`: four kinds) and
  ``cornellbox`` (diffuse only), both at ``--min-size`` square, 64 spp, unbounded depth.

An XML scene renders with its own settings, its film scaled as
``benchmarks/equal_time_vs_mitsuba.py`` scales it (the smallest integer factor that makes the
longer side at least ``--min-size``) and its spp cut to ``--max-samples`` per image. One
:class:`~drpt.render.renderer.Renderer` per scene renders once per dispatch to compile (the
operation count of each one's largest kernel is recorded then), then ``--rounds`` rounds of one
render each way, the order alternating (ABBA...) so that load from other processes falls on
both; round ``k`` uses seed ``k`` for both, and their images must be bit-identical (checked).
Seconds are the median wall time of ``Renderer.render`` (tracing included, as in a real
render); ``speedup`` is masked / kinds.

Run: PYTHONPATH=. .venv/bin/python benchmarks/material_dispatch_ab.py [--rounds 5]
[--min-size 192] [--max-samples 1000000] [--only WORD,...] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the sibling benchmark: the corpus's place, the CPU's name and the commit, as it prints them
from equal_time_vs_mitsuba import CORPUS, ROOT, VEACH, _commit, _cpu  # noqa: E402

GRIDS = [CORPUS / "bsdf_spheres" / f"test_{e}_path.xml" for e in ("arealight", "constant", "envmap", "pointlight")]
DISPATCHES = ("masked", "kinds")


def scale_for(width: int, height: int, min_size: int) -> int:
    """The smallest integer factor ``k >= 1`` with ``k * max(width, height) >= min_size``."""
    return max(1, math.ceil(min_size / max(width, height)))


def scenes(tmp: Path, only: list[str]) -> list[tuple[str, Path]]:
    """``(name, scene file)`` of the scenes this benchmark renders whose name contains a
    word of ``only`` (all when empty); generated ones are written into ``tmp``, corpus
    files only listed where the corpus is present."""
    from drpt.tools.scenegen import living_room, materials_cornell

    out = [(p.name, p) for p in GRIDS if p.is_file()]
    out += [("veach_mis.xml", VEACH), ("living_room", tmp / "living_room.xml"),
            ("materials_cornell", tmp / "materials_cornell.txt"),
            ("cornellbox", ROOT / "scenes" / "cornellbox" / "cornellbox.txt")]
    out = [(n, p) for n, p in out if not only or any(w in n for w in only)]
    names = {n for n, _ in out}
    if "living_room" in names:
        living_room.main(tmp)
    if "materials_cornell" in names:
        materials_cornell.main(tmp)
    return out


def options_for(scene, min_size: int, max_samples: int):
    """``(options, scene)``: an XML scene's own settings scaled, else ``min_size`` square at 64 spp."""
    from drpt.options import PathOptions, RenderOptions, with_scene_settings

    if getattr(scene, "settings", None) is None:
        opts = RenderOptions(width=min_size, height=min_size, spp=64, progress=False,
                             path=PathOptions(max_depth=-1))
    else:
        own, _ = with_scene_settings(RenderOptions(progress=False), scene)
        k = scale_for(own.width, own.height, min_size)
        opts, scene = with_scene_settings(RenderOptions(width=k * own.width, height=k * own.height,
                                                        progress=False), scene, given=frozenset({"size"}))
    spp = max(min(opts.spp, 4), min(opts.spp, max_samples // (opts.width * opts.height)))
    return replace(opts, spp=spp).validate(), scene


def largest_ops(render) -> int:
    """Render once with Dr.Jit's kernel history on; the largest JIT kernel's operation count."""
    import drjit as dr

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history_clear()
        render()
        return max((k.get("operation_count", 0) for k in dr.kernel_history([dr.KernelType.JIT])), default=0)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def measure(name: str, path: Path, rounds: int, min_size: int, max_samples: int) -> dict:
    from drpt.render.material import MaterialTable
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path)
    opts, scene = options_for(scene, min_size, max_samples)
    renderer = Renderer(scene, opts)

    def render(dispatch: str, seed: int):
        MaterialTable.dispatch = dispatch
        renderer.opt.seed = seed
        t0 = time.perf_counter()
        image = renderer.render().image
        return time.perf_counter() - t0, image

    try:
        ops = {d: largest_ops(lambda d=d: render(d, 0)) for d in DISPATCHES}  # (compiles)
        secs: dict[str, list[float]] = {d: [] for d in DISPATCHES}
        identical = True
        for k in range(rounds):
            order = DISPATCHES if k % 2 == 0 else DISPATCHES[::-1]
            images = {}
            for d in order:
                s, images[d] = render(d, k + 1)
                secs[d].append(s)
            identical &= bool(np.array_equal(images["masked"], images["kinds"]))
    finally:
        MaterialTable.dispatch = "kinds"
    med = {d: statistics.median(v) for d, v in secs.items()}
    return {"scene": name, "kinds": len(renderer.scene.materials.kinds), "width": opts.width,
            "height": opts.height, "spp": opts.spp, "integrator": opts.integrator,
            "ops_masked": ops["masked"], "ops_kinds": ops["kinds"],
            "s_masked": med["masked"], "s_kinds": med["kinds"], "speedup": med["masked"] / med["kinds"],
            "identical": identical, "seconds": secs}


def main(argv=None) -> list[dict]:
    from drpt.backend import ensure

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--min-size", type=int, default=192)
    ap.add_argument("--max-samples", type=int, default=1_000_000)
    ap.add_argument("--only", default="", help="comma-separated words: the scenes whose name contains one")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args(argv)
    ensure()
    only = [w for w in a.only.split(",") if w]
    load0 = os.getloadavg()[0]
    commit = _commit()  # (at the start: the checkout may move on while a long run goes on)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in scenes(Path(tmp), only):
            row = measure(name, path, a.rounds, a.min_size, a.max_samples)
            rows.append(row)
            print(f"{name}: masked {row['s_masked']:.2f} s, kinds {row['s_kinds']:.2f} s, "
                  f"speedup {row['speedup']:.2f}x, identical {row['identical']}", file=sys.stderr, flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    print(f"{_cpu()}, commit {commit}, {a.rounds} rounds, load average {load0:.1f} -> "
          f"{os.getloadavg()[0]:.1f}\n")
    print("| scene | kinds | size, spp | ops masked -> kinds | s masked | s kinds | speedup | identical |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['kinds']} | {r['width']}x{r['height']}, {r['spp']} | "
              f"{r['ops_masked']} -> {r['ops_kinds']} | {r['s_masked']:.2f} | {r['s_kinds']:.2f} | "
              f"{r['speedup']:.2f}x | {'yes' if r['identical'] else 'NO'} |")
    return rows


if __name__ == "__main__":
    main()
