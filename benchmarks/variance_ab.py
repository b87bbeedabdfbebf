"""Per-pixel variance of this checkout's drpt against another commit's, over the same seeds in one
process (not a test): does an estimator change keep the noise?

    PYTHONPATH=. .venv/bin/python benchmarks/variance_ab.py COMMIT SCENE [--rounds 48] [--size W H]
        [--spp N] [--bsdf MODE]

Each side (``COMMIT``'s ``drpt/`` unpacked as ``drpt_ab``, as :mod:`commit_ab` does, and this
checkout's) renders ``SCENE`` with seeds ``0 .. rounds-1`` at the given size, spp and material
mode (defaults: the scene's own). Prints each side's mean image value and mean per-pixel
variance per channel, and the ratio of the mean variances, this / ``COMMIT`` (two samples'
variance ratio: with 48 rounds its relative spread is about 0.2 where pixels are Gaussian,
more with fireflies).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import commit_ab as ab
import numpy as np


def main(argv=None) -> float:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("commit")
    ap.add_argument("scene", type=Path)
    ap.add_argument("--rounds", type=int, default=48)
    ap.add_argument("--size", type=int, nargs=2, default=None)
    ap.add_argument("--spp", type=int, default=None)
    ap.add_argument("--bsdf", default=None)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        short = ab.unpack(a.commit, Path(tmp))
        sys.path.insert(0, tmp)
        rs = {side: ab.renderer(pkg, a.scene, 1, a.spp, a.size, a.bsdf)
              for side, pkg in ((short, "drpt_ab"), ("this", "drpt"))}
        imgs: dict[str, list[np.ndarray]] = {side: [] for side in rs}
        for k in range(a.rounds):
            for side, r in rs.items():
                imgs[side].append(np.asarray(r.derive(replace(r.opt, seed=k)).render().image, np.float64))
    var = {}
    for side, xs in imgs.items():
        stack = np.stack(xs)
        var[side] = stack.var(axis=0, ddof=1)
        print(f"{side}: mean {stack.mean(axis=(0, 1, 2))}, variance {var[side].mean(axis=(0, 1))}")
    ratio = float(var["this"].mean() / var[short].mean())
    print(f"variance this / {short}: {ratio:.4f} ({a.rounds} rounds)")
    return ratio


if __name__ == "__main__":
    main()
