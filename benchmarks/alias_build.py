"""Build time of the sky's alias tables (``envmap.alias_tables``) on random maps, this
tree's against another commit's and against the float32 CDFs (one cumsum per row) that the
tables replaced, in turns in one process.

    PYTHONPATH=. .venv/bin/python benchmarks/alias_build.py [REV] [ROUNDS] [SIZES...]

``REV`` (default ``HEAD~1``): the commit whose ``drpt/render/lights/envmap.py`` is timed
as "old"; ``SIZES``: map widths (default 1024 2048 4096 8192; height = width / 2). Each
round times, in turn, the old and the new column tables of the ``(H - 1, W)`` cells and
the row table, as an ``EnvironmentLight`` builds them, and the CDF sampler's build
(``_float32_cdf`` of ``c111f36``, the last commit with it) of the same weights, on
lognormal weights with 10% zero cells; prints the median seconds per size, the peak RSS,
and how far the probabilities the new tables realise are from the normalised weights
(``max |N prob - N w / total|``: float32 rounding of the thresholds, about 1e-7).
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

#: the last commit whose envmap sampled by float32 CDFs
CDF_REV = "c111f36"


def load_old(rev: str, name: str = "old"):
    src = subprocess.run(["git", "show", f"{rev}:drpt/render/lights/envmap.py"], check=True,
                         capture_output=True, text=True).stdout
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}_envmap.py"
        path.write_text(src)
        spec = importlib.util.spec_from_file_location(f"drpt.render.lights._{name}_envmap", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    return mod


def build(mod, w):
    t0 = time.perf_counter()
    q, a, p = mod.alias_tables(w)
    mod.alias_tables(mod._floored(w.sum(axis=1)[None, :]))
    return time.perf_counter() - t0, (q, a, p)


def build_cdf(mod, w):
    """The CDF sampler's build from the same float32 weights (copied first, outside the
    timing: it overwrites them)."""
    w32 = w.astype(np.float32)
    t0 = time.perf_counter()
    row_sum = w32.sum(axis=1, dtype=np.float64)
    mod._float32_cdf(w32, row_sum[:, None])
    mod._float32_cdf(row_sum[None, :].astype(np.float32), row_sum.sum())
    return time.perf_counter() - t0, None


def main():
    rev = sys.argv[1] if len(sys.argv) > 1 else "HEAD~1"
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    sizes = [int(s) for s in sys.argv[3:]] or [1024, 2048, 4096, 8192]
    old = load_old(rev)
    cdf = load_old(CDF_REV, "cdf")
    rng = np.random.default_rng(0)
    for W in sizes:
        H = W // 2
        w = rng.lognormal(0.0, 2.0, (H - 1, W))
        w[rng.random(w.shape) < 0.1] = 0.0
        w = new._floored(w)
        times = {"old": [], "new": [], "cdf": []}
        for _ in range(rounds):
            for name, mod, fn in (("old", old, build), ("new", new, build), ("cdf", cdf, build_cdf)):
                t, out = fn(mod, w)
                times[name].append(t)
                if name == "new":
                    _q, _a, prob = out
                    out = None
        err = float(np.abs(prob - w / w.sum(axis=1, keepdims=True)).max() * W)
        to, tn, tc = (float(np.median(times[k])) for k in ("old", "new", "cdf"))
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
        print(f"{W}x{H}: old {to:.3f} s, new {tn:.3f} s, cdf {tc:.3f} s; old / new {to / tn:.1f}, "
              f"new / cdf {tn / tc:.1f} (rounds {rounds}; peak RSS so far {rss:.1f} GiB); "
              f"new tables' max |N prob - N w / total| {err:.1e}", flush=True)


if __name__ == "__main__":
    main()
