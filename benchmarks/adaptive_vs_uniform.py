"""Adaptive sampling (``--adaptive``) against uniform sampling at equal time.

For each scene: a uniform drpt reference at ``--ref-spp`` (its own seed), then at each
``--spp`` level a uniform and an adaptive render (each after a discarded warm-up render
that compiles its kernels), ``--repeats`` seeds each. Time is the process's CPU time
(all of Dr.Jit's threads), which other work on a shared machine disturbs less than wall
time. Error is excess relMSE against the
reference (relMSE minus the reference's own noise floor ``mean(var_ref / (ref^2 +
0.01))``). Error falls as 1 / time for both, so the **equal-time error ratio** is
``(err_adaptive * t_adaptive) / (err_uniform * t_uniform)`` (below 1: adaptive wins),
the geometric mean over the levels and repeats.

The **mean** ratio, ``(sum err_adaptive / sum err_uniform) x (sum t_adaptive / sum
t_uniform)`` over the same renders, is the ratio of the expected errors at equal time:
where a few rare paths carry a render's error (a caustic), single renders' ratios scatter
over decades and their geometric mean says little.

A scene ``caustic`` is :mod:`drpt.tools.scenegen.caustic`, written into a temporary folder.

With ``--oracle N`` also the best any per-pixel allocation of the same work could do
(:func:`oracle`), from two independent uniform renders of ``N`` spp.

With ``--threshold`` also a Cycles-style noise-threshold scheme at the same budget
(:func:`noise_threshold`): rounds of samples to the pixels whose estimated error is
above a threshold (each round's median), every sample averaged into its pixel. Its
allocation depends on the samples it averages, so it is biased; it is the comparison.

    python benchmarks/adaptive_vs_uniform.py scenes/newscene/newscene_hard.txt \
        --size 64 64 --spp 16 64 --ref-spp 2048
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drpt.metrics import rel_mse  # noqa: E402
from drpt.options import RenderOptions  # noqa: E402
from drpt.render.renderer import Renderer  # noqa: E402
from drpt.scene import load_scene  # noqa: E402


def noise_threshold(renderer, spp: int, rounds: int = 8):
    """A Cycles-style adaptive render of ``spp`` samples per pixel on average: ``spp /
    rounds`` in every pixel, then each round ``2 spp / rounds`` more in the half of the
    pixels whose estimated relative error of the mean, ``var / (n (mean^2 + 0.01))``,
    is above the median (Cycles stops a pixel once its error is below a fixed
    threshold; here the threshold is each round's median, so the budget is ``spp``).
    Returns the image ``(H, W, 3)``."""
    from drpt.render.adaptive import trace_counts

    W, H = renderer.opt.width, renderer.opt.height
    P = W * H
    step = max(1, spp // rounds)
    s, q, _, _ = trace_counts(renderer, 10, np.full(P, step, np.int64), P)
    n = np.full(P, step, np.float64)
    for r in range(1, rounds):
        m = s / n[:, None]
        var = np.maximum(q / n[:, None] - m * m, 0.0)
        err = (var / (n[:, None] * (m * m + 0.01))).sum(-1)
        counts = np.where(err > np.median(err), 2 * step, 0).astype(np.int64)
        if counts.sum() == 0:
            counts[:] = step
        s2, q2, _, _ = trace_counts(renderer, 10 + r, counts, P)
        s, q, n = s + s2, q + q2, n + counts
    return (s / n[:, None]).reshape(H, W, 3).astype(np.float32)


def oracle(renderer, spp: int) -> tuple[float, float, int]:
    """The expected error, relative to uniform sampling of the same work, of per-pixel
    Neyman allocation with the per-pixel variance and cost known: ``n_p`` in proportion to
    ``sqrt(v_p / c_p)`` (``v_p`` a pixel's relative per-sample variance ``sum_c var_c /
    (mean_c^2 + 0.01)``, ``c_p`` its bounces per sample) gives ``(sum sqrt(v c))^2 /
    (sum v sum c)`` of uniform's error (Cauchy-Schwarz: at most 1). Two independent
    renders of ``spp`` samples per pixel: the **self** bound allocates by render 1's
    estimate and scores it on render 1 (optimistic: an estimate's noise looks like
    structure worth sampling), the **cross-validated** one allocates by render 1's
    estimate averaged over ``k x k`` pixels and mixed with a uniform share ``u`` and scores
    it on render 2's (the best ``k`` of 1, 3, 5, 9, 15 and ``u`` of 0, 0.1, 0.3, 0.5), as a
    pilot of ``spp`` samples per pixel, at no cost, could. Returns ``(self,
    cross-validated, k, u)``."""
    from drpt.render.adaptive import _smooth, trace_counts

    W, H = renderer.opt.width, renderer.opt.height
    P = W * H
    est = []
    for k in range(2):
        s, q, _, work = trace_counts(renderer.derive(dataclasses.replace(renderer.opt, seed=1001 + k)),
                                     20, np.full(P, spp, np.int64), P)
        m = s / spp
        var = np.maximum(q / spp - m * m, 0.0) * spp / (spp - 1)
        est.append(((var / (m * m + 0.01)).sum(-1).reshape(H, W), (work / spp).reshape(H, W)))
    (v1, c1), (v2, c2) = est
    self_bound = float(np.mean(np.sqrt(v1 * c1)) ** 2 / (np.mean(v1) * np.mean(c1)))
    best = (math.inf, 1, 0.0)
    for k in (1, 3, 5, 9, 15):
        s = np.sqrt(np.maximum(_smooth(v1, k), 0.0) / _smooth(c1, k))
        for u in (0.0, 0.1, 0.3, 0.5):
            n = (1.0 - u) * s / s.mean() + u
            n *= c2.sum() / (n * c2).sum()  # the work of one sample per pixel, on render 2's costs
            best = min(best, (float((v2 / np.maximum(n, 1e-30)).sum() / v2.sum()), k, u))
    return (self_bound, *best)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--size", type=int, nargs=2, default=(64, 64))
    ap.add_argument("--spp", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--threshold", action="store_true", help="also the Cycles-style scheme")
    ap.add_argument("--oracle", type=int, default=0, metavar="N",
                    help="also the per-pixel allocation bound from two renders of N spp")
    a = ap.parse_args()
    W, H = a.size
    tmp = Path(tempfile.mkdtemp())
    for path in a.scenes:
        if path == "caustic":
            from drpt.tools.scenegen import caustic

            path = str(caustic.main(tmp)[0])
        scene = load_scene(path)
        base = Renderer(scene, RenderOptions(width=W, height=H, spp=a.ref_spp, seed=999, progress=False))
        ref = base.render()
        floor = float(np.mean(ref.variance / (ref.image.astype(np.float64) ** 2 + 0.01)))
        if a.oracle:
            sb, cv, k, u = oracle(base, a.oracle)
            print(f"{Path(path).name}: per-pixel allocation bound at equal work, from {a.oracle} spp: "
                  f"self {sb:.3f}, cross-validated {cv:.3f} ({k}x{k} pixels, uniform share {u})", flush=True)
        ratios, per_sample, cycles, sums = [], [], [], np.zeros(4)
        for spp in a.spp:
            for adaptive in (False, True, True):  # warm-up: compile the kernels
                base.derive(dataclasses.replace(base.opt, spp=max(spp, 8), seed=1, adaptive=adaptive)).render()
            if a.threshold:
                noise_threshold(base.derive(dataclasses.replace(base.opt, spp=spp, seed=1)), spp)
            for rep in range(a.repeats):
                row = {}
                for adaptive in (False, True):
                    r = base.derive(dataclasses.replace(base.opt, spp=spp, seed=10 + rep, adaptive=adaptive))
                    t0 = time.process_time()
                    res = r.render()
                    t = time.process_time() - t0
                    err = max(rel_mse(res.image, ref.image) - floor, 1e-12)
                    row[adaptive] = (err, t)
                (eu, tu), (ea, ta) = row[False], row[True]
                ratios.append(ea * ta / (eu * tu))
                sums += (eu, tu, ea, ta)
                per_sample.append(ea / eu)
                extra = ""
                if a.threshold:
                    r = base.derive(dataclasses.replace(base.opt, spp=spp, seed=10 + rep))
                    t0 = time.process_time()
                    img = noise_threshold(r, spp)
                    tc = time.process_time() - t0
                    ec = max(rel_mse(img, ref.image) - floor, 1e-12)
                    cycles.append(ec * tc / (eu * tu))
                    extra = f", noise-threshold {ec:.4g} in {tc:.2f} s, ratio {cycles[-1]:.3f}"
                print(f"{Path(path).name} spp {spp} seed {10 + rep}: uniform {eu:.4g} in {tu:.2f} s, "
                      f"adaptive {ea:.4g} in {ta:.2f} s, equal-time error ratio {ratios[-1]:.3f}{extra}",
                      flush=True)
        g = math.exp(sum(math.log(x) for x in ratios) / len(ratios))
        gs = math.exp(sum(math.log(x) for x in per_sample) / len(per_sample))
        print(f"{Path(path).name}: equal-time error ratio (adaptive / uniform) {g:.3f}, at equal spp "
              f"{gs:.3f}; mean ratio at equal time {sums[2] * sums[3] / (sums[0] * sums[1]):.3f}, at "
              f"equal spp {sums[2] / sums[0]:.3f} (reference floor {floor:.3g})", flush=True)
        if cycles:
            gc = math.exp(sum(math.log(x) for x in cycles) / len(cycles))
            print(f"{Path(path).name}: noise-threshold (biased) equal-time error ratio {gc:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
