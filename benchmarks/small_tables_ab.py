"""What reading small tables as literals saves: renders with ``drpt.render.tables.RUNS`` at several
values, in turns in one process (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/small_tables_ab.py SCENE_WORD [--rounds 10] [--runs 0,4,8,16]

``SCENE_WORD`` picks a scene of ``benchmarks/equal_time_vs_mitsuba.py`` (its setup: the file's
settings, the film scaled to at least 192 pixels). ``RUNS`` is read when a kernel is traced, so each
value traces its own kernel (0: every table gathered, 8: the default of :mod:`drpt.render.tables`); each
renders once to compile, then ``--rounds`` rounds of one render each, the values' order
alternating, round ``k`` with seed ``k``. Printed per value: the path kernel's operation count, the
median render's wall and process-CPU seconds, the medians of the per-round ratios ``RUNS=0 / this``
(above 1: faster than every table gathered) and whether every image equals the ``RUNS=0`` image
bit for bit.
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
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from equal_time_vs_mitsuba import _commit, _cpu, cases, setup  # noqa: E402

from drpt.render import tables  # noqa: E402
from drpt.tools.converge import make_drpt  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--runs", default="0,4,8,16")
    a = ap.parse_args(argv)
    values = sorted({0, *(int(x) for x in a.runs.split(",") if x)})
    default = tables.RUNS
    print(f"commit {_commit()}, {_cpu()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{a.rounds} rounds; RUNS values {values}")
    with tempfile.TemporaryDirectory() as tmp:
        case = next(iter(cases([a.scene], True, Path(tmp))))
        scene, opts, _ = setup(case, 192, 1_000_000)
        renders, ops = {}, {}
        try:
            for v in values:
                tables.RUNS = v
                renders[v] = make_drpt(scene, opts)[1]
                dr.set_flag(dr.JitFlag.KernelHistory, True)
                dr.kernel_history_clear()
                renders[v](opts.spp, 0)
                ops[v] = max((k.get("operation_count", 0) for k in dr.kernel_history()
                              if k.get("type") == dr.KernelType.JIT), default=0)
                dr.set_flag(dr.JitFlag.KernelHistory, False)
            wall = {v: [] for v in values}
            cpu = {v: [] for v in values}
            same = {v: True for v in values}
            for k in range(a.rounds):
                images = {}
                for v in (values if k % 2 == 0 else values[::-1]):
                    tables.RUNS = v
                    t0, c0 = time.perf_counter(), time.process_time()
                    images[v] = renders[v](opts.spp, k + 1).image
                    wall[v].append(time.perf_counter() - t0)
                    cpu[v].append(time.process_time() - c0)
                for v in values:
                    same[v] &= bool(np.array_equal(images[v], images[0]))
        finally:
            tables.RUNS = default
        print(f"{case.name}, {opts.width}x{opts.height}, {opts.spp} spp, load {os.getloadavg()[0]:.1f} at the end")
        print("| RUNS | kernel operations | wall s | CPU s | RUNS=0 / this, wall | RUNS=0 / this, CPU | "
              "images = RUNS=0's |\n|---|---|---|---|---|---|---|")
        for v in values:
            rw = statistics.median(x / y for x, y in zip(wall[0], wall[v], strict=True))
            rc = statistics.median(x / y for x, y in zip(cpu[0], cpu[v], strict=True))
            print(f"| {v} | {ops[v]} | {statistics.median(wall[v]):.3f} | {statistics.median(cpu[v]):.3f} | "
                  f"{rw:.3f} | {rc:.3f} | {same[v]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
