"""Per-pixel variance at equal spp, drpt's path tracer against Mitsuba's (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/variance_vs_mitsuba.py SCENE [FILTER SIZE SPP ROUNDS [MAX_DEPTH]]
        [--scale K] [--grid COLSxROWS] [--light-sampler NAME] [--bsdf MODE] [--env-compensation on|off]
        [--sampler NAME] [--mitsuba-sampler NAME] [--blocks N]

Renders ``SCENE`` (drpt's format: at ``SIZE`` (``N`` for N x N or ``WxH``) with ``--filter
FILTER``, default gaussian 128; a Mitsuba XML file: its own film, filter and integrator) with ``SPP`` samples
per pixel (default 64) ``ROUNDS`` times (default 32, seeds 0, 1, ...) with drpt's default
path tracer and with Mitsuba (the exported scene, or the XML file itself), interleaved in
one process, and prints:

* the ratio of the mean over pixels of each pixel's variance across the rounds, drpt's to
  Mitsuba's, with its jackknife standard error over the rounds (the statistic the
  efficiency comparisons use; at a bright emitter's edge a few pixels can carry most of the
  variance, and the error says how far 8 rounds can be trusted);
* the share of the variance in the top 1% of pixels (by drpt's and Mitsuba's variance
  summed, so that the choice favours neither), and the ratio outside them;
* the ratio of the mean images (a bias check, not a test).

The jackknife error is itself an estimate from the rounds: on heavy-tailed scenes (a sun
through glass, a sub-pixel highlight) a few rounds can read far from the ratio and from
each other, so run many (``showcase_day``: 0.98 +- 0.13 over 200 rounds; the corpus's
``test_arealight_path``: 1.00 +- 0.03 over 48) before reading a ratio above 1 as an excess.

``MAX_DEPTH`` (drpt's format only) sets both renderers' ``max_depth`` (1: the emitters the
camera sees, 2: direct light). ``filter_efficiency.py`` compares the filters' ways and
times; this compares the estimators' noise.

Options (anywhere on the line): ``--scale K`` renders a Mitsuba XML file's film ``K`` times
its authored size (both renderers; ``equal_time_vs_mitsuba.py`` scales the corpus films to
192 pixels); ``--grid COLSxROWS`` also prints the ratio, its jackknife error and the share of
Mitsuba's variance in each cell of a ``COLS`` x ``ROWS`` grid over the image (the corpus's
``bsdf_spheres`` grid is ``5x3``: one BSDF a cell), to find the region that holds an excess,
with the ratio of the cell's mean images and the z of their difference (the rounds' cell
sums; a cell without noise is listed only where that z exceeds 4);
``--blocks N`` also prints the ratio of each run of ``N`` consecutive rounds (seeds 0 to
``N - 1``, ``N`` to ``2N - 1``, ...): how far an ``N``-round figure, such as
``equal_time_vs_mitsuba.py --rounds 8``'s, scatters from one set of seeds to the next;
``--light-sampler NAME`` sets drpt's (default: drpt's default), ``--env-compensation on|off``
drpt's MIS compensation of the sky (default: drpt's default); ``--bsdf MODE`` how drpt
and the exported scene read a drpt-format scene's MTL materials (``drpt render --bsdf``);
``--sampler NAME`` drpt's ``--sampler`` on a drpt-format scene (default ``auto``, drpt's
default), whose export names the sampler drpt draws with, as ``equal_time_vs_mitsuba.py``'s
does: both renderers draw from the same kind of sampler (Mitsuba's ``ldsampler`` takes a
power of 4 samples per pixel and rounds any other count up, so give it one);
``--mitsuba-sampler NAME`` names another Mitsuba plugin for the export of a drpt-format scene
(drpt keeps its ``--sampler``), as ``equal_time_vs_mitsuba.py``'s does.

Every statistic is taken over the pixels finite in every round of both renderers
(:func:`drpt.tools.converge.finite_in_every_round`, as ``efficiency_rounds`` scores); the
count of the others is printed where there are any.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from drpt.tools.converge import finite_in_every_round


def _ratio(a: np.ndarray, b: np.ndarray, mask=None) -> float:
    va, vb = a.var(0, ddof=1), b.var(0, ddof=1)
    if mask is not None:
        va, vb = va[mask], vb[mask]
    return float(va.mean() / vb.mean())


def _jackknife(a: np.ndarray, b: np.ndarray, mask=None) -> float:
    """The leave-one-round-out standard error of ``_ratio``."""
    rounds = a.shape[0]
    keep = np.ones(rounds, bool)
    jack = []
    for k in range(rounds):
        keep[k] = False
        jack.append(_ratio(a[keep], b[keep], mask))
        keep[k] = True
    return float(np.sqrt((rounds - 1) / rounds * np.sum((np.array(jack) - np.mean(jack)) ** 2)))


def _options(argv: list[str]) -> tuple[list[str], dict]:
    """The positional arguments, and the ``--name value`` options."""
    pos, opts = [], {}
    it = iter(argv)
    for arg in it:
        if arg in ("--scale", "--grid", "--light-sampler", "--bsdf", "--env-compensation", "--sampler",
                   "--mitsuba-sampler", "--blocks"):
            opts[arg[2:]] = next(it)
        else:
            pos.append(arg)
    return pos, opts


def _size(text: str) -> tuple[int, int]:
    """``SIZE``: ``N`` (N x N) or ``WxH``."""
    size = text.lower().split("x")
    return int(size[0]), int(size[-1])


def _scored(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The ``(H, W)`` mask of the pixels finite in every round of both ``a`` and ``b``."""
    return finite_in_every_round(a) & finite_in_every_round(b)


def _blocks(a: np.ndarray, b: np.ndarray, n: int, mask=None) -> list[float]:
    """The variance ratio of each run of ``n`` consecutive rounds (seeds ``k n`` to ``k n +
    n - 1``): what an ``n``-round benchmark with those seeds reads."""
    return [_ratio(a[k:k + n], b[k:k + n], mask) for k in range(0, len(a) - n + 1, n)]


def _grid(a: np.ndarray, b: np.ndarray, spec: str, mask=None) -> None:
    cols, rows = (int(x) for x in spec.lower().split("x"))
    height, width = a.shape[1:3]
    mask = np.ones((height, width), bool) if mask is None else mask
    total = b[:, mask].var(0, ddof=1).sum()
    print(f"  per cell of a {cols}x{rows} grid (row, column from the top left): ratio +- error, "
          "share of Mitsuba's variance, mean image ratio and its z")
    for r in range(rows):
        for c in range(cols):
            cell = np.zeros((height, width), bool)
            cell[r * height // rows:(r + 1) * height // rows, c * width // cols:(c + 1) * width // cols] = True
            cell &= mask
            if not cell.any():
                continue
            ac, bc = a[:, cell], b[:, cell]
            vb = bc.var(0, ddof=1)
            z = _mean_z(ac, bc)
            if vb.sum() <= 1e-4 * total:
                if abs(z) > 4.0:  # a cell without noise whose mean differs: no ratio to read
                    print(f"    ({r}, {c}): -, {vb.sum() / total:.1%}, mean {ac.mean() / bc.mean():.4f} "
                          f"z {z:+.1f}")
                continue
            print(f"    ({r}, {c}): {_ratio(ac, bc):.3f} +- {_jackknife(ac, bc):.3f}, "
                  f"{vb.sum() / total:.1%}, mean {ac.mean() / bc.mean():.4f} z {z:+.1f}")


def _mean_z(a: np.ndarray, b: np.ndarray) -> float:
    """The z of the difference of two means over rounds (``a``, ``b``: rounds first): the
    rounds' sums of each, independent across rounds and renderers. Without noise (``se``
    0) it is +-inf where the means differ, 0 where they are equal."""
    sa, sb = a.reshape(len(a), -1).sum(1), b.reshape(len(b), -1).sum(1)
    se = np.sqrt(sa.var(ddof=1) / len(sa) + sb.var(ddof=1) / len(sb))
    d = sa.mean() - sb.mean()
    if se > 0:
        return float(d / se)
    return float(np.sign(d) * np.inf) if d != 0 else 0.0


def main(argv: list[str]) -> None:
    import mitsuba as mi

    from drpt import llvm_tuning
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.options import PathOptions, RenderOptions, resolve_sampler, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    argv, extra = _options(argv)
    path = Path(argv[0])
    flt = argv[1] if len(argv) > 1 else "gaussian"
    width, height = _size(argv[2] if len(argv) > 2 else "128")
    spp = int(argv[3]) if len(argv) > 3 else 64
    rounds = int(argv[4]) if len(argv) > 4 else 32
    depth = int(argv[5]) if len(argv) > 5 else -1
    ensure()
    xml = path.suffix == ".xml"
    if xml:
        scene = load_scene(path, defines={"spp": str(spp)})
        opt, scene = with_scene_settings(RenderOptions(progress=False), scene)
        k = int(extra.get("scale", 1))
        if k != 1:
            opt, scene = with_scene_settings(RenderOptions(width=k * opt.width, height=k * opt.height,
                                                           progress=False), scene, given=frozenset({"size"}))
        opt = replace(opt, spp=spp)
    else:
        scene = load_scene(path)
        opt = RenderOptions(width=width, height=height, spp=spp, filter=flt, progress=False,
                            path=PathOptions(max_depth=depth), bsdf=extra.get("bsdf", "auto"),
                            sampler=extra.get("sampler", "auto")).validate()
    if "light-sampler" in extra:
        opt = replace(opt, light_sampler=extra["light-sampler"])
    if "env-compensation" in extra:
        opt = replace(opt, env_compensation=extra["env-compensation"])
    renderer = Renderer(scene, opt)
    set_mitsuba_variant()
    integrator = None  # Mitsuba's, where the scaled film's file replaces it
    with llvm_tuning.dr_default():
        if xml and int(extra.get("scale", 1)) != 1:
            from drpt.tools.xmlref import MitsubaXML
            ms, integrator = MitsubaXML.for_scene(scene, opt).load()
        elif xml:
            ms = mi.load_file(str(path), spp=str(spp))
        else:
            ms = mi.load_dict(to_mitsuba_dict(scene, opt.width, opt.height, spp, max_depth=depth,
                                              rfilter=opt.filter, bsdf=opt.bsdf,
                                              sampler=extra.get("mitsuba-sampler") or resolve_sampler(opt).sampler))
    ours, theirs = [], []
    for k in range(rounds):
        ours.append(renderer.derive(replace(renderer.opt, seed=k)).render().image.astype(np.float64))
        with llvm_tuning.dr_default():
            theirs.append(np.asarray(mi.render(ms, spp=spp, seed=k, integrator=integrator),
                                     np.float64)[..., :3])
    a, b = np.stack(ours), np.stack(theirs)
    scored = _scored(a, b)
    print(f"{path.name}: {opt.width}x{opt.height}, {spp} spp, filter {opt.filter}, {rounds} rounds"
          + (f", max_depth {depth}" if depth >= 0 and not xml else "")
          + (f", Mitsuba's sampler {extra['mitsuba-sampler']}" if "mitsuba-sampler" in extra else ""))
    if not scored.all():
        print(f"  pixels not finite in some round (left out): drpt {int((~finite_in_every_round(a)).sum())}, "
              f"Mitsuba {int((~finite_in_every_round(b)).sum())} of {scored.size}")
    if not scored.any():
        return
    ratio = _ratio(a, b, scored)
    err = _jackknife(a, b, scored)
    both = (a.var(0, ddof=1) + b.var(0, ddof=1)).sum(-1)
    top = scored & (both >= np.quantile(both[scored], 0.99))
    share = float(both[top].sum() / both[scored].sum())
    print(f"  variance drpt / Mitsuba {ratio:.3f} +- {err:.3f}; the top 1% of pixels hold "
          f"{share:.0%} of the variance, outside them {_ratio(a, b, scored & ~top):.3f}; "
          f"mean image drpt / Mitsuba {a[:, scored].mean() / b[:, scored].mean():.4f}")
    if "blocks" in extra:
        n = int(extra["blocks"])
        blocks = _blocks(a, b, n, scored)
        print(f"  each {n} rounds (seeds 0-{n - 1}, {n}-{2 * n - 1}, ...): "
              + ", ".join(f"{r:.2f}" for r in blocks))
    if "grid" in extra:
        _grid(a, b, extra["grid"], scored)


if __name__ == "__main__":
    main(sys.argv[1:])
