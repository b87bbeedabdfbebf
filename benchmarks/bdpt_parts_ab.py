"""What each of bdpt's cheaper estimators buys, A/B in one process (not a test).

Each PART is rendered with it (B) and without it (A), in turns (ABAB over the seeds, the
same load for both), from one renderer per variant whose kernels are compiled by a
1-spp render first:

* ``variance``: ``RenderOptions.variance`` off (B) against on (A, the squared splats
  summed);
* ``occluded``: the connections', splats' and next-event estimation's shadow rays inside a
  symbolic ``if`` (B, :func:`~drpt.render.integrators.bdpt.occluded_where`) against masked
  rays for every packet (A);
* ``roulette``: the light subpath's roulette relative to its emitted power (B,
  :func:`~drpt.render.integrators.bdpt.light_survival`) against the path tracer's rule on
  ``max(beta)`` (A);
* ``reverse``: the MIS weights' reverse densities from the evaluation or the sample that
  needs them, in one dispatch over the material kinds (B,
  :func:`~drpt.render.integrators.bdpt.eval_both`, :func:`~drpt.render.integrators.bdpt.sample_both`)
  against a second ``eval_bsdf`` with the directions swapped (A);
* ``smooth``: the connections', splats', next-event estimation's and merging's BSDF
  evaluations on a view of the non-Dirac material kinds (B,
  :func:`~drpt.render.integrators.bdpt.smooth_view`) against the whole table (A);
* ``prepare``: the camera vertex's fields and shading frame gathered and built once for
  all its connections (B, :func:`~drpt.render.integrators.bdpt.prepare_both`) against once
  per connection (A, :func:`~drpt.render.integrators.bdpt.eval_both`);
* ``sampler``: ``--sampler ldsampler`` (B) against ``independent`` (A);
* ``photons``: caustic merging's photon subpaths traced once per pass (B: the grid evaluates
  them in the kernel that counts them, :class:`~drpt.render.photons.PhotonGrid`) against twice
  (A: their validity evaluated in a kernel of its own first, which traces them, then the grid,
  which traces them again, as the grid's two kernels each did before).

Prints per part the CPU seconds (the process's, summed over the seeds; steadier than wall
seconds on a loaded machine), the relMSE (summed, against the reference of
``bdpt_equal_time.py``, minus its estimated relMSE) and B / A of the seconds, of the error
and of their product (the error at equal time: below 1, B is better), and the median over the
seeds of B / A of one seed's seconds (the two renders of a seed run one after the other) and of
its error (where a rare firefly decides a seed's error, as on the caustic scene, the sums are a
lottery and the median is the typical seed). Images are the same for ``variance``,
``reverse``, ``smooth`` and ``prepare`` (checked) and equal in expectation for the others
(``photons``: the same photons, but A's counting kernel may give a bucket's photons other
places, so merging sums them in another order: equal up to rounding).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_parts_ab.py [--scenes cornell,glass]
[--parts variance,occluded,roulette,reverse,smooth,prepare,sampler,photons] [--size 64] [--depth 8]
[--spp 64] [--ref-spp 2048] [--seeds 4] [--reference PATH]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bdpt_equal_time as eq  # noqa: E402 (the sibling benchmark: its scenes and references)

PARTS = ("variance", "occluded", "roulette", "reverse", "smooth", "prepare", "sampler", "photons")
SAME_IMAGES = ("variance", "reverse", "smooth", "prepare")  # the parts whose images are compared


def _old_survival(beta, power, eta):
    """The path tracer's rule: ``min(max(beta) eta^2, 0.95)`` in the light's units."""
    import drjit as dr

    return dr.minimum(dr.max(beta) * dr.square(eta), 0.95)


def _masked_occluded(scene, o, d, tmax, active):
    """Every packet traces the shadow ray, masked."""
    return scene.occluded(o, d, tmax, active)


def _with_wi(si, wi):
    """``si`` seen from direction ``wi``."""
    import copy

    out = copy.copy(si)
    out.wi = wi
    return out


def _two_evaluations(scene, si, wo):
    """``(f, pdf, pdf_rev)`` by two ``eval_bsdf``: the second with the directions swapped."""
    f, pdf = scene.eval_bsdf(si, wo)
    return f, pdf, scene.eval_bsdf(_with_wi(si, wo), si.wi)[1]


def _prepared_two_evaluations(scene, si):
    """:func:`_two_evaluations` of ``si`` as a function of ``wo``."""
    return lambda wo: _two_evaluations(scene, si, wo)


def _sample_then_evaluate(scene, si, u_lobe, u_bsdf):
    """``(wo, bs, pdf_rev)``: the sample, then ``eval_bsdf`` seen from it toward ``si.wi``."""
    wo, bs = scene.sample_bsdf(si, u_lobe, u_bsdf)
    return wo, bs, scene.eval_bsdf(_with_wi(si, wo), si.wi)[1]


def _per_connection(scene, si):
    """The camera vertex evaluated whole at each connection."""
    from drpt.render.integrators import bdpt

    return lambda wo: bdpt.eval_both(scene, si, wo)


def _whole_table(scene):
    """bdpt's evaluations on the scene's whole material table."""
    return scene


def _traced_twice():
    """A :class:`~drpt.render.photons.PhotonGrid` whose photons are traced twice: their
    validity evaluated alone first (a kernel that traces the photon subpaths), then the grid
    (which traces them again)."""
    import drjit as dr

    from drpt.render.photons import PhotonGrid

    class TracedTwice(PhotonGrid):
        def __init__(self, p, valid, radius, fields=None):
            dr.eval(valid)
            super().__init__(p, valid, radius, fields)

    return TracedTwice


def main() -> None:
    import numpy as np

    from drpt.metrics import rel_mse
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.integrators import bdpt as B
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--scenes", default="cornell,glass")
    p.add_argument("--parts", default=",".join(PARTS))
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=2048)
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--reference", type=Path, default=None)
    a = p.parse_args()
    a.sampler = "independent"
    files = eq.scene_files(Path(tempfile.mkdtemp()))
    patches = {"occluded": [("occluded_where", _masked_occluded)], "roulette": [("light_survival", _old_survival)],
               "reverse": [("eval_both", _two_evaluations), ("sample_both", _sample_then_evaluate),
                           ("prepare_both", _prepared_two_evaluations)],
               "smooth": [("smooth_view", _whole_table)], "prepare": [("prepare_both", _per_connection)],
               "photons": [("PhotonGrid", _traced_twice())]}
    for name in a.scenes.split(","):
        scene = load_scene(files[name])
        base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth),
                             integrator="bdpt")
        ref_image, ref_err = eq.reference(scene, base, name, a)
        for part in a.parts.split(","):
            new = [getattr(B, fn) for fn, _ in patches[part]] if part in patches else None

            def variant(which: str, part=part, new=new, base=base):
                """Set the module's functions (A: the old ones) and the options of ``which``."""
                for (fn, old), current in zip(patches.get(part, []), new or []):
                    setattr(B, fn, old if which == "A" else current)
                if part == "sampler":
                    return replace(base, sampler="independent" if which == "A" else "ldsampler")
                return replace(base, variance=(which == "A")) if part == "variance" else base

            renderers = {}
            for which in "AB":
                opt = variant(which)
                r = Renderer(scene, replace(opt, spp=1, seed=1))
                r.render()  # compiles the kernels
                renderers[which] = r
            totals = {w: [0.0, 0.0] for w in "AB"}
            images, ratios, err_ratios = {}, [], []
            for seed in range(2, a.seeds + 2):
                seconds, errors = {}, {}
                for which in "AB":
                    opt = variant(which)
                    r = renderers[which].derive(replace(opt, spp=a.spp, seed=seed))
                    c = time.process_time()
                    img = r.render()
                    seconds[which] = time.process_time() - c
                    totals[which][0] += seconds[which]
                    errors[which] = rel_mse(img.image, ref_image) - ref_err
                    totals[which][1] += errors[which]
                    images[which] = img.image
                ratios.append(seconds["B"] / seconds["A"])
                err_ratios.append(errors["B"] / errors["A"])
                if part in SAME_IMAGES and not np.array_equal(images["A"], images["B"]):
                    print(f"{name} {part}: the images of seed {seed} differ", flush=True)
            for (fn, _), current in zip(patches.get(part, []), new or []):
                setattr(B, fn, current)
            (ca, ea), (cb, eb) = totals["A"], totals["B"]
            print(f"{name} {part}: A {ca:.2f} s CPU, relMSE {ea / a.seeds:.4g}; B {cb:.2f} s CPU, relMSE "
                  f"{eb / a.seeds:.4g}; B / A: seconds {cb / ca:.3f}, error {eb / ea:.3f}, error x seconds "
                  f"{eb * cb / (ea * ca):.3f} ({a.seeds} seeds, {a.spp} spp); B / A of each seed's seconds: median "
                  f"{statistics.median(ratios):.3f}, of each seed's error: median {statistics.median(err_ratios):.3f}",
                  flush=True)
            if not math.isfinite(eb / ea):
                print(f"{name} {part}: no error to compare", flush=True)


if __name__ == "__main__":
    main()
