"""drpt's estimator choices on one scene of the equal-time benchmark, against each other (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/estimator_variants.py SCENE ROUNDS VARIANT [VARIANT ...]
        [--npz FILE]

``SCENE`` is a row name of ``equal_time_vs_mitsuba.py`` (``diningroom``, ``showcase_day``, a
corpus file's relative path, ...), set up exactly as that benchmark sets it up for drpt
(size, spp, depth, material mode). Each ``VARIANT`` is ``base`` (those options) or
``;``-separated ``field=value`` changes of :class:`~drpt.options.RenderOptions`, with ``path.``
for :class:`~drpt.options.PathOptions` fields: ``sampler=ldsampler``, ``light_sampler=pilot``,
``path.rr_depth=3``, ``path.max_depth=2;sampler=ldsampler``. Every variant renders once to
compile, then the variants take turns for ``ROUNDS`` rounds, round ``k`` with seed ``k``, in
one process; a render's time is the process's CPU seconds (``time.process_time``), so that
other processes' load drops out.

Printed per variant, relative to the first: the mean over pixels of each pixel's variance
across the rounds (with its jackknife standard error over the rounds), the median CPU
seconds, the efficiency ``1 / (seconds x variance)``, the share of the variance in the top
1% of pixels (by the first variant's variance) and the ratio of the mean images.
``path.max_depth=N`` variants split the variance by path length: depth 2 is the emitters
the camera sees and direct light, depth 3 adds one indirect bounce. ``--npz FILE`` keeps
every round's image. (``render_variants.py`` compares render times alone, on corpus files.)
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def apply(opts, variant: str):
    """``opts`` with ``variant``'s ``field=value`` changes (``base``: unchanged)."""
    if variant == "base":
        return opts
    for item in variant.split(";"):
        key, _, text = item.partition("=")
        if key.startswith("path."):
            opts = replace(opts, path=replace(opts.path, **{key[5:]: _value(text)}))
        else:
            opts = replace(opts, **{key: _value(text)})
    return opts.validate()


def _jackknife(a: np.ndarray, b: np.ndarray) -> float:
    rounds = a.shape[0]
    ratios = []
    for k in range(rounds):
        keep = np.arange(rounds) != k
        ratios.append(a[keep].var(0, ddof=1).mean() / b[keep].var(0, ddof=1).mean())
    ratios = np.array(ratios)
    return float(np.sqrt((rounds - 1) / rounds * ((ratios - ratios.mean()) ** 2).sum()))


def main(argv=None) -> dict:
    import equal_time_vs_mitsuba as et

    from drpt.backend import ensure
    from drpt.tools.converge import image_room, make_drpt

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("rounds", type=int)
    ap.add_argument("variants", nargs="+")
    ap.add_argument("--npz", type=Path, default=None)
    a = ap.parse_args(argv)
    ensure()
    import tempfile

    with tempfile.TemporaryDirectory(prefix="drpt-variants-") as tmp:
        found = [c for c in et.cases([a.scene], True, Path(tmp)) if c.name == a.scene]
        if not found:
            raise SystemExit(f"no scene named {a.scene!r} in equal_time_vs_mitsuba.py")
        scene, opts, _ = et.setup(found[0], 192, 1_000_000)
        renders = {v: make_drpt(scene, apply(opts, v))[1] for v in a.variants}
        for render in renders.values():
            shape = render(opts.spp, 999_999).image.shape  # compile
        stacks: dict = {v: image_room(a.rounds, shape) for v in renders}  # (paged in before timing)
        seconds: dict = {v: [] for v in renders}
        for k in range(a.rounds):
            for v, render in renders.items():
                t = time.process_time()
                img = render(opts.spp, k).image
                seconds[v].append(time.process_time() - t)
                stacks[v][k] = img
                del img
    if a.npz is not None:
        np.savez_compressed(a.npz, **{v: s.astype(np.float32) for v, s in stacks.items()})
    base = a.variants[0]
    vb, tb = stacks[base].var(0, ddof=1), float(np.median(seconds[base]))
    top = np.argsort(vb.mean(-1).ravel())[::-1][: max(1, vb[..., 0].size // 100)]
    print(f"{a.scene}: {opts.width}x{opts.height}, {opts.spp} spp, {a.rounds} rounds; relative to {base!r}")
    print("| variant | variance | +- | CPU s | time | efficiency | top 1% share | mean |")
    print("|---|---|---|---|---|---|---|---|")
    out = {}
    for v, s in stacks.items():
        va, t = s.var(0, ddof=1), float(np.median(seconds[v]))
        pix = va.mean(-1).ravel()
        row = {"variance": float(va.mean() / vb.mean()), "se": _jackknife(s, stacks[base]) if v != base else 0.0,
               "seconds": t, "time": t / tb, "efficiency": float(vb.mean() * tb / (va.mean() * t)),
               "top": float(pix[top].sum() / pix.sum()), "mean": float(s.mean() / stacks[base].mean())}
        out[v] = row
        print(f"| {v} | {row['variance']:.3f} | {row['se']:.3f} | {t:.3f} | {row['time']:.3f} "
              f"| {row['efficiency']:.2f} | {row['top']:.2f} | {row['mean']:.4f} |")
    return out


if __name__ == "__main__":
    main()
