"""Build time of the sky's alias tables (``envmap.alias_tables``) on random maps, this
tree's against another commit's, in turns (ABAB) in one process.

    PYTHONPATH=. .venv/bin/python benchmarks/alias_build.py [REV] [ROUNDS] [SIZES...]

``REV`` (default ``HEAD~1``): the commit whose ``drpt/render/lights/envmap.py`` is timed
as "old"; ``SIZES``: map widths (default 1024 2048 4096 8192; height = width / 2). Each
round times the column tables of the ``(H - 1, W)`` cells and the row table, as an
``EnvironmentLight`` builds them, on lognormal weights with 10% zero cells; prints the
median seconds per size, the peak RSS, and how far the two sets of thresholds differ
(float64 sums in another order: float32 rounding).
"""

from __future__ import annotations

import importlib.util
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from drpt.render.lights import envmap as new


def load_old(rev: str):
    src = subprocess.run(["git", "show", f"{rev}:drpt/render/lights/envmap.py"], check=True,
                         capture_output=True, text=True).stdout
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "old_envmap.py"
        path.write_text(src)
        spec = importlib.util.spec_from_file_location("drpt.render.lights._old_envmap", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    return mod


def build(mod, w):
    t0 = time.perf_counter()
    q, _a, _p = mod.alias_tables(w)
    mod.alias_tables(mod._floored(w.sum(axis=1)[None, :]))
    return time.perf_counter() - t0, q


def main():
    rev = sys.argv[1] if len(sys.argv) > 1 else "HEAD~1"
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    sizes = [int(s) for s in sys.argv[3:]] or [1024, 2048, 4096, 8192]
    old = load_old(rev)
    rng = np.random.default_rng(0)
    for W in sizes:
        H = W // 2
        w = rng.lognormal(0.0, 2.0, (H - 1, W))
        w[rng.random(w.shape) < 0.1] = 0.0
        w = old._floored(w)
        times = {"old": [], "new": []}
        for _ in range(rounds):
            for name, mod in (("old", old), ("new", new)):
                t, q = build(mod, w)
                times[name].append(t)
                if name == "old":
                    q_old = q
                else:
                    diff = np.abs(q.astype(np.float64) - q_old)
                    used = np.minimum(q, q_old) < 1.0
        to, tn = (float(np.median(times[k])) for k in ("old", "new"))
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
        print(f"{W}x{H}: old {to:.3f} s, new {tn:.3f} s, ratio {to / tn:.1f} "
              f"(rounds {rounds}; peak RSS so far {rss:.1f} GiB); thresholds differ in "
              f"{(diff > 0).mean():.1e} of the cells, by at most {diff.max():.1e} "
              f"({used.mean():.2f} of the cells below 1)", flush=True)


if __name__ == "__main__":
    main()
