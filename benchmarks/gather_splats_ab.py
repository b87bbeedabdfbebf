"""``gather_splats`` of this checkout against an earlier commit's, interleaved in one process (not a test).

The earlier ``drpt/render/film.py`` is read with ``git show REV:drpt/render/film.py`` and loaded
as a module of ``drpt.render`` (default REV ``ac033c8``: float64 sums per sample). Both gather
one pass of ``K`` samples per pixel of a ``SIZE x SIZE`` image through a Gaussian filter
(stddev 0.5) with the moment products (Mitsuba's ``moment`` integrator, as the corpus scenes
have it) and without, ``ROUNDS`` times each, taking turns. Prints the median seconds, their
ratio (earlier / now) and the largest relative difference of the sums.

Run: PYTHONPATH=. .venv/bin/python benchmarks/gather_splats_ab.py [REV] [SIZE] [K] [ROUNDS]
(defaults ac033c8, 192, 16, 7)
"""

from __future__ import annotations

import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def earlier_film(rev: str):
    """The module ``drpt/render/film.py`` of commit ``rev``."""
    text = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:drpt/render/film.py"],
                          capture_output=True, text=True, check=True).stdout
    path = Path(tempfile.mkdtemp(prefix="drpt-film-")) / "film.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("drpt.render._earlier_film", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv: list[str]) -> None:
    import drjit as dr
    from drjit.auto import PCG32, Array3f, Float, UInt32

    from drpt.backend import ensure
    from drpt.filters import PixelFilter
    from drpt.render import film

    rev = argv[0] if argv else "ac033c8"
    size, k, rounds = (int(a) for a in (argv[1:4] + ["192", "16", "7"][len(argv[1:4]):]))
    ensure()
    old = earlier_film(rev)
    flt = PixelFilter("gaussian", 0.5)
    n = size * size * k
    rng = PCG32(n, initstate=7)
    pix = dr.arange(UInt32, n) // k
    x = Float(pix % size) + rng.next_float32()
    y = Float(pix // size) + rng.next_float32()
    L = Array3f(rng.next_float32(), rng.next_float32() * 2.0, 1.0)
    ok = rng.next_float32() < 0.9
    dr.eval(x, y, L, ok)
    print(f"{size}x{size}, {k} samples per pixel, gaussian 0.5; {rev} against the checkout, {rounds} rounds")
    for moment in (True, False):
        times = {"earlier": [], "now": []}
        outs = {}
        for rnd in range(rounds + 1):
            for name, mod in (("earlier", old), ("now", film)):
                t0 = time.perf_counter()
                outs[name] = mod.gather_splats(flt, size, size, 0, size, k, x, y, L, ok, moment=moment)
                if rnd > 0:  # (round 0 compiles)
                    times[name].append(time.perf_counter() - t0)
        a, b = statistics.median(times["earlier"]), statistics.median(times["now"])
        diff = max(float(np.max(np.abs(p - q) / np.maximum(np.abs(p), 1e-12)))
                   for p, q in zip(outs["earlier"][1:], outs["now"][1:]))
        print(f"moment {moment}: earlier {a:.3f} s, now {b:.3f} s, earlier / now {a / b:.2f}; "
              f"largest relative difference {diff:.1e}")


if __name__ == "__main__":
    main(sys.argv[1:])
