"""Where a render's CPU time goes inside Dr.Jit's compiled kernel, by machine instruction
(not a test; Linux, ``perf``).

    PYTHONPATH=. .venv/bin/python benchmarks/jit_hotspots.py render FILE [--seconds 14] [--out DIR]
        [--renderer drpt|mitsuba]
    perf record -F 999 -p PID -o DIR/perf.data -- sleep 8      # once DIR/ready holds PID
    PYTHONPATH=. .venv/bin/python benchmarks/jit_hotspots.py report DIR [--top 20]

``render`` renders the corpus file ``FILE`` (a path under
``../shared/corpus/mitsuba-data/tests/scenes``) as ``benchmarks/equal_time_vs_mitsuba.py``
renders it (its settings, the film scaled to 192 pixels; ``--renderer mitsuba``: Mitsuba's
render of the file instead of drpt's), twice to compile, then copies every
anonymous executable mapping of the process (the LLVM backend's kernels) to ``DIR/code_ADDR.bin``,
writes its process id to ``DIR/ready`` and renders in a loop for ``--seconds``: attach ``perf``
then, so that loading and compiling are not in the samples. ``report`` reads
``perf report --sort dso`` (each library's share of the samples: the JIT kernels, Embree,
Python) and attributes the kernel's samples to the instruction before each sampled address
(``objdump`` of the copied code; a sample lands after the instruction that stalled): the
shares by instruction kind (``vgatherdps``, ``vgatherqps``: 32- and 64-bit index gathers;
``vinsertf128``/``vmovaps`` of 16-byte rows: packet gathers) and the hottest instructions.
"""

from __future__ import annotations

import argparse
import bisect
import collections
import os
import re
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def render(file: str, seconds: float, out: Path, renderer: str = "drpt") -> None:
    import equal_time_vs_mitsuba as eq

    from drpt.backend import ensure, set_mitsuba_variant

    ensure()
    set_mitsuba_variant()  # the variant the equal-time benchmark renders Mitsuba with
    out.mkdir(parents=True, exist_ok=True)
    ways, info = eq.prepare(eq.Case(file, 2.0, eq.CORPUS / file), 192, 1_000_000)
    f = ways[renderer]
    f(0)
    f(1)
    for line in open("/proc/self/maps"):
        parts = line.split()
        if parts[1].startswith("r-x") and len(parts) < 6:  # executable, no file: JIT code
            lo, hi = (int(x, 16) for x in parts[0].split("-"))
            with open("/proc/self/mem", "rb") as mem:
                mem.seek(lo)
                (out / f"code_{lo:x}.bin").write_bytes(mem.read(hi - lo))
    (out / "ready").write_text(str(os.getpid()))
    t, n = time.perf_counter(), 0
    while time.perf_counter() - t < seconds:
        f(n)
        n += 1
    print(f"{file} ({renderer}): {info['width']}x{info['height']}, {info['spp']} spp, "
          f"{(time.perf_counter() - t) / n:.3f} s per render ({n} renders)")


def report(out: Path, top: int) -> None:
    data = str(out / "perf.data")
    dso = subprocess.run(["perf", "report", "-i", data, "--no-children", "--sort", "dso", "--stdio",
                          "-g", "none"], capture_output=True, text=True).stdout
    print("\n".join(x for x in dso.splitlines() if x.strip() and not x.startswith("#"))[:2000])
    asm: dict[int, str] = {}
    for code in sorted(out.glob("code_*.bin")):
        base = int(code.stem.split("_")[1], 16)
        dump = subprocess.run(["objdump", "-D", "-b", "binary", "-m", "i386:x86-64",
                               f"--adjust-vma={base:#x}", str(code)], capture_output=True, text=True).stdout
        for line in dump.splitlines():  # "ADDR:<tab>BYTES<tab>INSTRUCTION" (continuations: no instruction)
            parts = line.split("\t")
            if len(parts) >= 3 and parts[0].strip().endswith(":") and parts[2].strip():
                asm[int(parts[0].strip()[:-1], 16)] = parts[2].strip()
    addrs = sorted(asm)
    syms = subprocess.run(["perf", "report", "-i", data, "--no-children", "--sort", "sym", "--stdio",
                           "-g", "none"], capture_output=True, text=True).stdout
    kinds: collections.Counter = collections.Counter()
    hot = []
    for line in syms.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+\[\.\]\s+0x([0-9a-f]+)\s*$", line)
        if not m:
            continue
        share, a = float(m.group(1)), int(m.group(2), 16)
        i = bisect.bisect_right(addrs, a) - 1
        if i < 1 or a - addrs[i] > 16:
            continue  # not in the copied kernels
        ins = asm[addrs[i - 1]]
        kinds[ins.split()[0]] += share
        hot.append((share, addrs[i - 1], ins))
    print(f"\nJIT samples by instruction kind (% of all samples; {sum(kinds.values()):.1f}% in the kernels):")
    for k, v in kinds.most_common(12):
        print(f"  {v:6.2f}  {k}")
    print(f"\nhottest {top} instructions:")
    for share, a, ins in sorted(hot, reverse=True)[:top]:
        print(f"  {share:5.2f}  {a:x}  {ins}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("file")
    r.add_argument("--seconds", type=float, default=14.0)
    r.add_argument("--out", type=Path, default=Path("/tmp/jit_hotspots"))
    r.add_argument("--renderer", choices=("drpt", "mitsuba"), default="drpt")
    p = sub.add_parser("report")
    p.add_argument("out", type=Path)
    p.add_argument("--top", type=int, default=20)
    a = ap.parse_args(argv)
    if a.cmd == "render":
        render(a.file, a.seconds, a.out, a.renderer)
    else:
        report(a.out, a.top)


if __name__ == "__main__":
    main()
