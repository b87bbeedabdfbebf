"""Beckmann's visible-slope sampler alone: drpt's (:meth:`Distribution._slopes11_beckmann`:
three Halley steps, :mod:`drpt.render.erf32`) against Mitsuba 3's routine with Dr.Jit's
``erf``/``erfinv``/``exp``/``log`` (three Newton steps, written out below as
``include/mitsuba/render/microfacet.h`` has it), in turns in one process (not a test).

    PYTHONPATH=.:tests .venv/bin/python benchmarks/beckmann_sampler_ab.py [--rounds 20] [--samples 2097152]

Prints each side's kernel operation count, the median process CPU seconds of one kernel
over ``--samples`` random ``(cos theta, u)`` (both slopes), the median per-round ratio
Mitsuba's / drpt's (above 1: drpt's is faster), and the largest distance over a dense
grid between ``u`` and the exact (float64) CDF at the sampled slope.
"""

from __future__ import annotations

import argparse
import time

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Float

from drpt.render.bsdf import microfacet as mf
from support.beckmann import slope_cdf_error

_ERF_MAX = mf._ERF_MAX


def mitsuba_slopes(cos_i: Float, u: Array2f):
    """Mitsuba 3's ``sample_visible_11`` for Beckmann: both slopes."""
    tan_i = dr.safe_sqrt(1.0 - dr.square(cos_i)) / cos_i
    cot_i = dr.rcp(tan_i)
    maxval = dr.erf(cot_i)
    ux = dr.clip(u.x, 1e-6, 1.0 - 1e-6)
    uy = dr.clip(u.y, 1e-6, 1.0 - 1e-6)
    isp = 1.0 / dr.sqrt(dr.pi)
    x = maxval - (maxval + 1.0) * dr.erf(dr.sqrt(-dr.log(ux)))
    ux = ux * (1.0 + maxval + isp * tan_i * dr.exp(-dr.square(cot_i)))
    for _ in range(3):
        slope = dr.erfinv(dr.clip(x, -_ERF_MAX, _ERF_MAX))
        value = 1.0 + x + isp * tan_i * dr.exp(-dr.square(slope)) - ux
        x = x - value / (1.0 - slope * tan_i)
    return dr.erfinv(dr.clip(x, -_ERF_MAX, _ERF_MAX)), dr.erfinv(2.0 * uy - 1.0)


def drpt_slopes(cos_i: Float, u: Array2f):
    n = mf.Distribution(True, 1.0)._slopes11_beckmann(cos_i, u)
    return -n.x, n.y


def ops(f, cos_i, u) -> int:
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history_clear()
    dr.eval(f(cos_i, u))
    h = [k.get("operation_count", 0) for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    return max(h)


def cdf_error(f) -> float:
    """The first slope's CDF error over :func:`support.beckmann.grid`."""
    return slope_cdf_error(f)[0]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--samples", type=int, default=1 << 21)
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    cos_i = Float((rng.random(a.samples) * 0.999 + 0.001).astype(np.float32))
    u = Array2f(Float(rng.random(a.samples).astype(np.float32)), Float(rng.random(a.samples).astype(np.float32)))
    dr.eval(cos_i, u)
    sides = {"mitsuba": mitsuba_slopes, "drpt": drpt_slopes}
    for name, f in sides.items():
        print(f"{name}: {ops(f, cos_i, u)} operations, CDF error {cdf_error(f):.3g}")
    t = {k: [] for k in sides}
    for r in range(a.rounds + 2):
        for name in (sides if r % 2 == 0 else list(sides)[::-1]):
            sx, sy = sides[name](cos_i, u)
            t0 = time.process_time()
            dr.eval(sx, sy)
            dr.sync_thread()
            if r >= 2:  # the first two rounds compile
                t[name].append(time.process_time() - t0)
    ratio = np.array(t["mitsuba"]) / np.array(t["drpt"])
    print(f"CPU s per kernel: mitsuba {np.median(t['mitsuba']):.4f}, drpt {np.median(t['drpt']):.4f}; "
          f"mitsuba / drpt median {np.median(ratio):.3f} (quartiles {np.quantile(ratio, 0.25):.3f}-"
          f"{np.quantile(ratio, 0.75):.3f}), {a.rounds} rounds")


if __name__ == "__main__":
    main()
