"""drpt and Mitsuba 3 with and without drpt's tuning of Dr.Jit's LLVM backend (not a test).

:mod:`drpt.llvm_tuning` adds LLVM's ``+fast-gather`` to Dr.Jit's target (AVX2
gather instructions instead of scalarized gathers), and the renderer launches
its path kernel in blocks sized for the pass (``llvm_tuning.blocks_for``:
blocks of 4096 lanes instead of 16384 at 256x256). This script renders SCENE six ways,
interleaved in one process for ROUNDS rounds: drpt with Dr.Jit's own settings,
with each of the two changes alone and with both; Mitsuba with Dr.Jit's own
settings (as it ships) and with the gather tuning (the block sizes are the
renderer's). It prints each one's median seconds and
medians of per-round ratios, and checks that drpt's images are bitwise equal.
The gather tuning is forced on (``DRPT_FAST_GATHER=1``), so the script also
measures CPUs where drpt does not turn it on by itself.

Run: PYTHONPATH=. .venv/bin/python benchmarks/codegen_ab.py SCENE [BSDF] [ACCEL] [SIZE] [SPP] [ROUNDS]
(defaults phong, auto, 256, 64, 6; unbounded depth, box filter).
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import drjit as dr
import numpy as np

os.environ["DRPT_FAST_GATHER"] = "1"


def main(argv: list[str]) -> None:
    from drpt import llvm_tuning
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene_path = argv[0]
    bsdf = argv[1] if len(argv) > 1 else "phong"
    accel = argv[2] if len(argv) > 2 else "auto"
    size, spp, rounds = (int(a) for a in (argv[3:6] + ["256", "64", "6"][len(argv[3:6]):]))
    ensure()
    llvm_tuning.apply()
    if not llvm_tuning.fast_gather():
        sys.exit("this CPU or Dr.Jit has no AVX2 gather to tune (drpt.llvm_tuning)")
    tuned = llvm_tuning.current()
    default = llvm_tuning._default
    per_launch = llvm_tuning.block_size_for
    # name -> (target, block size rule of the renderer's path kernel)
    settings = {
        "default": (default, lambda n, threads, width: default.block_size),
        "gather": (tuned, lambda n, threads, width: default.block_size),
        "block": (default, per_launch),
        "tuned": (tuned, per_launch),
    }
    print(f"target: {tuned.cpu}, load average: {os.getloadavg()[0]:.2f}")
    scene = load_scene(scene_path)
    opts = RenderOptions(width=size, height=size, spp=spp, bsdf=bsdf, accel=accel, progress=False,
                         path=PathOptions(max_depth=-1)).validate()
    r = Renderer(scene, opts)
    mi = set_mitsuba_variant()
    ms = mi.load_dict(to_mitsuba_dict(scene, size, size, spp, max_depth=-1, bsdf=bsdf,
                                      rfilter=opts.filter))
    images = {}

    def run(name: str, i: int) -> float:
        who, how = name.split()
        target, rule = settings[how]
        llvm_tuning._set(target)
        llvm_tuning.block_size_for = rule
        try:
            if who == "drpt":
                res = r.render()
                images[name] = res.image
                return res.seconds
            dr.sync_thread()
            t0 = time.perf_counter()
            dr.eval(mi.render(ms, spp=spp, seed=i + 1))
            dr.sync_thread()
            return time.perf_counter() - t0
        finally:
            llvm_tuning._set(tuned)
            llvm_tuning.block_size_for = per_launch

    names = ["drpt default", "drpt gather", "drpt block", "drpt tuned",
             "mitsuba default", "mitsuba tuned"]
    for n in names:
        run(n, 0)  # compile
    times = {n: [] for n in names}
    for i in range(rounds):
        for n in (names if i % 2 == 0 else names[::-1]):
            times[n].append(run(n, i))
    same = all(np.array_equal(images["drpt default"], images[n]) for n in names[1:4])
    for n in names:
        print(f"{n:16s} median {statistics.median(times[n]):.3f} s")

    def ratio(a: str, b: str) -> float:  # how many times faster a is than b
        return statistics.median(tb / ta for ta, tb in zip(times[a], times[b]))

    for n in names[1:4]:
        print(f"{n} vs drpt default: {ratio(n, 'drpt default'):.2f}x")
    print(f"drpt images bitwise equal: {same}")
    print(f"mitsuba tuned vs mitsuba default: {ratio('mitsuba tuned', 'mitsuba default'):.2f}x")
    print(f"drpt tuned vs mitsuba default: {ratio('drpt tuned', 'mitsuba default'):.2f}x")
    print(f"drpt tuned vs mitsuba tuned: {ratio('drpt tuned', 'mitsuba tuned'):.2f}x")
    print(f"drpt default vs mitsuba default: {ratio('drpt default', 'mitsuba default'):.2f}x")


if __name__ == "__main__":
    main(sys.argv[1:])
