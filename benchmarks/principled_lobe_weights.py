"""principled's lobe selection: Mitsuba's probabilities against albedo-proportional ones (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/principled_lobe_weights.py SCENE.xml [SPP ROUNDS]
        [--scale K] [--light-sampler NAME]

:mod:`drpt.render.bsdf.principled` picks its lobes as Mitsuba does, in proportion to
``brdf s_d`` (diffuse), ``s_s`` (main specular and transmission) and ``0.25 cc s_c``
(clearcoat): the diffuse lobe gets no less for a dark base colour and the specular no more
for a metal. The usual alternative (pbrt-v4's and Cycles' layered models pick by albedo
estimates) weighs each lobe by an estimate of its albedo, here at normal incidence (a
function of the material only, so that, as in Mitsuba's rule, the probabilities do not
depend on the sampled microfacet and the mixture stays a normalized density)::

    diffuse    brdf s_d max(lum(c), 0.02) + 0.1 sheen (1 - m) s_d   (0 where brdf s_d = 0)
    specular   s_s max((1 - m) F0 + m lum(c) + bsdf (1 - F0) lum(sqrt(c)), 0.02)
    clearcoat  0.04 cc s_c

(``F0`` the dielectric Fresnel at normal incidence; each weight is positive exactly where
Mitsuba's is, so both rules sample the same directions and the image's expectation is the
same). This script measures both on ``SCENE`` (a Mitsuba XML file rendered by drpt at its
own settings, ``--scale K`` times its film, ``SPP`` samples per pixel, default 27), in one
process, and prints:

* the furnace: the mean and variance of the BSDF sample weight's luminance (one sample,
  no light) for the scene's principled materials -- every combination of the two values of
  each checkerboard parameter -- at 10, 45 and 75 degrees, summed over them;
* the render: ``ROUNDS`` (default 24) rounds of seeds 0, 1, ... with each rule, the ratio of
  the mean per-pixel variance (albedo rule / Mitsuba's) with its jackknife error, the
  same outside the top 1% of pixels (by both rules' variance summed), and the ratio of the
  mean images (the same expectation: a bias check).

Variance ratios at equal spp: load-free (the two rules cost the same operations within a
few).
"""

from __future__ import annotations

import itertools
import sys
from dataclasses import replace
from pathlib import Path

import drjit as dr
import numpy as np
from drjit.auto import PCG32, Array2f, Array3f, Float, UInt32

from drpt.backend import ensure
from drpt.options import RenderOptions, with_scene_settings
from drpt.render.bsdf import principled as pr
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


def _options(argv: list[str]) -> tuple[list[str], dict]:
    pos, opts = [], {}
    it = iter(argv)
    for arg in it:
        if arg in ("--scale", "--light-sampler"):
            opts[arg[2:]] = next(it)
        else:
            pos.append(arg)
    return pos, opts


def albedo_probabilities(p, front, F, bsdf, brdf):
    """The albedo rule, with the signature and returns of ``principled._probabilities``."""
    lb = p.lobes
    zero = dr.zeros(Float, dr.width(F))
    one_m = 1.0 - (p.metallic if lb.metallic else 0.0)
    lum_c = pr._luminance(p.base_color)
    f0 = pr.fresnel(dr.full(Float, 1.0, dr.width(F)), p.eta)[0]
    spec = one_m * f0 + bsdf * (1.0 - f0) * pr._luminance(dr.sqrt(dr.maximum(p.base_color, 0.0)))
    if lb.metallic:
        spec += p.metallic * lum_c
    ws = p.rate_spec * dr.maximum(spec, 0.02)
    wd = p.rate_diffuse * brdf * dr.maximum(lum_c, 0.02)
    if lb.sheen:
        wd += dr.select(brdf * p.rate_diffuse > 0.0, p.rate_diffuse * 0.1 * p.sheen * one_m, 0.0)
    ps = dr.select(front, ws * (1.0 - bsdf * (1.0 - F)), F)
    pt = dr.select(front, ws * bsdf * (1.0 - F), 1.0 - F) if lb.spec_trans else zero
    pc = dr.select(front, 0.04 * p.clearcoat * p.rate_clearcoat, 0.0) if lb.clearcoat else zero
    pd = dr.select(front, wd, 0.0)
    tot = ps + pt + pc + pd
    ok = (tot > 0.0) & (front | (bsdf > 0.0))
    inv = dr.select(ok, dr.rcp(dr.select(ok, tot, 1.0)), 0.0)
    return pd * inv, pc * inv, pt * inv, ps * inv, ok


def _material_cases(scene) -> list[dict]:
    """Every combination of the two values of each checkerboard parameter of the scene's
    principled materials (other parameters as they are; other textures at their fallback)."""
    cases = []
    for m in scene.materials:
        if m.bsdf is not None and m.bsdf.kind == "principled":
            cases += _combinations(m.bsdf.params)
    return cases


def _combinations(params: dict) -> list[dict]:
    fixed, varied = {}, {}
    for k, v in params.items():
        if hasattr(v, "color0") and hasattr(v, "color1"):  # a checkerboard: its two values
            two = [v.color0, v.color1]
            varied[k] = two if k == "base_color" else [float(c[0]) for c in two]
        elif hasattr(v, "fallback"):
            fixed[k] = v.fallback
        else:
            fixed[k] = v
    return [{**fixed, **dict(zip(varied, combo))} for combo in itertools.product(*varied.values())]


def furnace(cases: list[dict], count: int = 200_000) -> tuple[float, float]:
    """Summed mean and variance of the sample weight's luminance over ``cases`` x 3 angles."""
    mean = var = 0.0
    for prm, theta in itertools.product(cases, (10.0, 45.0, 75.0)):
        p = pr.from_params(prm)
        rng = PCG32(count, UInt32(7))
        u1, u2 = rng.next_float32(), Array2f(rng.next_float32(), rng.next_float32())
        t = np.radians(theta)
        w = pr.sample(p, Array3f(float(np.sin(t)), 0.0, float(np.cos(t))), u1, u2).weight
        dr.eval(w)
        lum = sum(c * np.asarray(x, np.float64) for c, x in zip(pr.LUMINANCE, (w.x, w.y, w.z)))
        mean += float(lum.mean())
        var += float(lum.var())
    return mean, var


def _jackknife(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    n = len(a)
    js = []
    for k in range(n):
        keep = np.arange(n) != k
        js.append(a[keep].var(0, ddof=1)[mask].mean() / b[keep].var(0, ddof=1)[mask].mean())
    js = np.array(js)
    return float(np.sqrt((n - 1) / n * np.sum((js - js.mean()) ** 2)))


def main(argv: list[str]) -> None:
    argv, extra = _options(argv)
    path = Path(argv[0])
    spp = int(argv[1]) if len(argv) > 1 else 27
    rounds = int(argv[2]) if len(argv) > 2 else 24
    ensure()
    scene = load_scene(path, defines={"spp": str(spp)})
    opt, scene = with_scene_settings(RenderOptions(progress=False), scene)
    k = int(extra.get("scale", 1))
    if k != 1:
        opt, scene = with_scene_settings(RenderOptions(width=k * opt.width, height=k * opt.height,
                                                       progress=False), scene, given=frozenset({"size"}))
    opt = replace(opt, spp=spp)
    if "light-sampler" in extra:
        opt = replace(opt, light_sampler=extra["light-sampler"])
    mitsubas = pr._probabilities
    rules = {"Mitsuba's": mitsubas, "albedo": albedo_probabilities}
    cases = _material_cases(scene)
    images = {}
    print(f"{path.name}: {opt.width}x{opt.height}, {spp} spp, light sampler {opt.light_sampler}, "
          f"{rounds} rounds, {len(cases)} principled parameter combinations")
    try:
        for name, rule in rules.items():
            pr._probabilities = rule
            if cases:
                m, v = furnace(cases)
                print(f"  furnace, {name} rule: summed mean {m:.3f}, summed variance {v:.4f}")
            renderer = Renderer(scene, opt)
            images[name] = np.stack([renderer.derive(replace(renderer.opt, seed=s)).render().image
                                     .astype(np.float64) for s in range(rounds)])
    finally:
        pr._probabilities = mitsubas
    a, b = images["albedo"], images["Mitsuba's"]
    va, vb = a.var(0, ddof=1), b.var(0, ddof=1)
    both = (va + vb).sum(-1)
    top = both >= np.quantile(both, 0.99)
    every = np.ones(both.shape, bool)
    print(f"  render variance albedo / Mitsuba's rule {va.mean() / vb.mean():.3f} +- "
          f"{_jackknife(a, b, every):.3f}; outside the top 1% of pixels "
          f"{va[~top].mean() / vb[~top].mean():.3f} +- {_jackknife(a, b, ~top):.3f}; "
          f"mean image {a.mean() / b.mean():.5f}")


if __name__ == "__main__":
    main(sys.argv[1:])
