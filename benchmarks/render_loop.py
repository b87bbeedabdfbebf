"""One scene rendered in a loop, for a profiler (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/render_loop.py WORD [--rounds 300] [--mitsuba] [--dump DIR]
    perf record -F 4000 -o drpt.data -- env PYTHONPATH=. .venv/bin/python benchmarks/render_loop.py \
        test_directional --dump /tmp/jit
    perf report -i drpt.data --no-children --sort dso --stdio

The first scene of ``benchmarks/equal_time_vs_mitsuba.py`` whose name contains ``WORD`` is set
up as that benchmark sets it up (its :func:`prepare`: the file's settings, the film scaled to
at least 192 pixels, at most 1e6 samples), rendered twice to compile, then ``--rounds`` times
by drpt, or with ``--mitsuba`` by Mitsuba (``mi.render`` of the file), each round another seed;
it prints the mean wall and process CPU seconds of a render. A profile of the process is then
mostly the loop's: ``perf report --sort dso`` splits it into the JIT-compiled kernels
(``[JIT]``), Embree, Dr.Jit's thread pool (``libnanothread``: its workers wait for work by
spinning, so their share is CPU time, not wall time, on an idle machine), Python and numpy.

The kernels have no symbols. ``--dump DIR`` writes, after the loop, each executable anonymous
mapping of the process (the JIT's code) to ``DIR/<start address in hex>.bin``; then
``objdump -D -b binary -mi386:x86-64 --adjust-vma=0x<start> DIR/<start>.bin`` disassembles it
at the addresses ``perf report --sort sym`` gives for ``[JIT]`` samples (which kernel is which:
its gathers, its ``call``s into Embree).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the sibling benchmark: its scenes and their setup
from equal_time_vs_mitsuba import cases, prepare  # noqa: E402


def dump_jit(out: Path) -> list[tuple[int, int]]:
    """The process's executable anonymous mappings to ``out``; returns their (start, size)."""
    out.mkdir(parents=True, exist_ok=True)
    done = []
    with open("/proc/self/maps") as maps, open("/proc/self/mem", "rb") as mem:
        for line in maps:
            parts = line.split()
            if "x" not in parts[1] or len(parts) >= 6:  # executable, no file behind it
                continue
            a, b = (int(v, 16) for v in parts[0].split("-"))
            try:
                mem.seek(a)
                data = mem.read(b - a)
            except OSError:
                continue
            (out / f"{a:x}.bin").write_bytes(data)
            done.append((a, b - a))
    return done


def main(argv=None) -> int:
    from drpt.backend import ensure, set_mitsuba_variant

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("word")
    ap.add_argument("--rounds", type=int, default=300)
    ap.add_argument("--mitsuba", action="store_true")
    ap.add_argument("--dump", type=Path, default=None)
    a = ap.parse_args(argv)
    ensure()
    set_mitsuba_variant()
    with tempfile.TemporaryDirectory(prefix="drpt-loop-") as tmp:
        case = next(c for c in cases([a.word], True, Path(tmp)) if a.word in c.name)
        ways, info = prepare(case, 192, 1_000_000)
    render = ways["mitsuba" if a.mitsuba else "drpt"]
    render(0)
    render(1)
    t, c = time.perf_counter(), time.process_time()
    for i in range(a.rounds):
        render(i + 2)
    wall, cpu = (time.perf_counter() - t) / a.rounds, (time.process_time() - c) / a.rounds
    print(f"{'mitsuba' if a.mitsuba else 'drpt'} {case.name} {info['width']}x{info['height']} "
          f"{info['spp']} spp: {wall * 1e3:.1f} ms wall, {cpu * 1e3:.1f} ms CPU per render "
          f"(load {os.getloadavg()[0]:.1f})")
    if a.dump:
        for start, size in dump_jit(a.dump):
            print(f"{a.dump / f'{start:x}.bin'}: {size} bytes at {start:#x}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
