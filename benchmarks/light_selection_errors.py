"""What a static light selection does to the absolute and the relative error, emitter by emitter (not a test).

    PYTHONPATH=. .venv/bin/python benchmarks/light_selection_errors.py ROWS [--shares] [--sweep P,P,...]
        [--seeds N] [--split]

``ROWS``: comma-separated names of the corpus's sphere grid (``bsdf_spheres/test_NAME_path.xml``:
a sphere lit by a rectangle area light, the museum envmap and a point light). For each row it
prints:

* the emitters' selection probabilities under ``mixed``, ``power`` and ``uniform``, with the
  power estimates of :mod:`drpt.render.lights.reach` and without them (the emitted powers: the
  scene's receivers set to none);
* with ``--shares``: each emitter's image alone (the other two removed from the scene; the
  file's 48x48, 1024 spp, ``uniform``), over the pixels the area light or the point light
  reach: its share of their light (``light``), the square root of the sum of its squared pixel
  values (``abs``: what a static selection's absolute variance weighs, ``sum_j M_j / p_j``
  being least for ``p_j`` proportional to ``sqrt(M_j)``), the same with each pixel divided by
  ``b^2 + 0.01`` for the pixel's whole brightness ``b`` (``rel``: the relative error's
  weighing, :mod:`drpt.render.lights.pilot`'s), and the selection each of the two would pick
  (``p ~ sqrt``);
* with ``--sweep``: for each given selection, written ``AREA/POINT/SKY`` (each emitter's
  probability; the area light's slots split by area), the absolute error that
  ``benchmarks/equal_time_vs_mitsuba.py`` measures (the mean per-pixel variance across
  ``--seeds`` renders, seeds 0.., at that benchmark's size and spp: 192x192, 27 spp) and the
  relative error that ``benchmarks/light_sampler.py`` measures (the mean relMSE of ``--seeds``
  renders at the file's 48x48 and 64 spp against the corpus's reference). One kernel per
  selection (the tables are literals), the seeds fixed: selections compare on the same random
  numbers;
* with ``--split``: what next-event estimation toward the point light at *every* vertex (its own
  shadow ray, outside the selection) and one selected emitter among the others would give, at
  the sweep's size and spp, emulated by two scenes: the point light alone (no selection: its
  estimate has no selection noise) and the area light with the sky (``mixed``); the sum of
  their variances (independent renders) against the whole scene's with ``mixed``, and the
  median seconds of each render (``--seeds`` renders each, after one to compile; the three
  scenes in turns, so that load from other processes spreads over them). The time of the
  point light's scene bounds from above what its shadow ray and BSDF evaluation would add to
  a vertex (it also traces the camera rays and the BSDF samples).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT.parent / "shared" / "corpus" / "mitsuba-data" / "tests" / "scenes" / "bsdf_spheres"
KINDS = {"AreaLights": "area", "DeltaLights": "point", "SkyEmitter": "sky"}


def _load(name: str, defines: dict | None = None):
    from drpt.scene import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(CORPUS / f"test_{name}_path.xml", defines=defines or {})


def unit_probabilities(selection) -> dict:
    """Each emitter's probability under ``selection``, by :data:`KINDS`."""
    out = {}
    for i, f in enumerate(selection.families):
        out[KINDS.get(type(f).__name__, type(f).__name__)] = float(selection.family_probabilities(i).sum())
    return out


def slot_weights(selection, p: dict) -> np.ndarray:
    """The slot weights that give each emitter of ``selection`` its probability in ``p``,
    its slots split as ``uniform`` splits them."""
    from drpt.render.lights.selection import LightSelection

    uni = LightSelection(selection.families, "uniform")
    w = []
    for i, f in enumerate(selection.families):
        q = uni.family_probabilities(i)
        w += list(p[KINDS[type(f).__name__]] * q / q.sum())
    return np.array(w)


def probabilities(name: str) -> None:
    import drpt.render.scene as device
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.lights.selection import LightSelection
    from drpt.render.renderer import Renderer

    for reach in (False, True):
        saved = device.receivers
        if not reach:
            device.receivers = lambda scene: None
        try:
            opts, scene = with_scene_settings(RenderOptions(progress=False), _load(name))
            sel = Renderer(scene, opts).scene.emitter_selection
        finally:
            device.receivers = saved
        rules = {r: unit_probabilities(LightSelection(sel.families, r)) for r in ("mixed", "power", "uniform")}
        text = "  ".join(f"{r}: " + " ".join(f"{k} {v:.3f}" for k, v in p.items()) for r, p in rules.items())
        print(f"{name:36s} {'reach  ' if reach else 'emitted'}  {text}", flush=True)


def shares(name: str) -> None:
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene.model import PointLight, Skybox

    images = {}
    for keep in ("area", "point", "sky"):
        scene = _load(name, {"spp": "1024"})
        scene.lights = [light for light in scene.lights
                        if (isinstance(light, PointLight) and keep == "point")
                        or (isinstance(light, Skybox) and keep == "sky")
                        or not isinstance(light, (PointLight, Skybox))]
        if keep != "area":
            for m in scene.materials:
                if m.is_emissive:
                    m.emission = (0.0, 0.0, 0.0)
        opts, scene = with_scene_settings(RenderOptions(progress=False, light_sampler="uniform"), scene)
        images[keep] = Renderer(scene, opts).render().image.astype(np.float64).mean(-1)
    total = sum(images.values())
    lit = (images["area"] + images["point"]) > 1e-6  # the sphere's pixels (the sky seen directly: not)
    w = 1.0 / (total[lit] ** 2 + 0.01)
    absolute = {k: float(np.sqrt((im[lit] ** 2).sum())) for k, im in images.items()}
    relative = {k: float(np.sqrt((w * im[lit] ** 2).sum())) for k, im in images.items()}
    parts = [f"{k}: light {im[lit].sum() / total[lit].sum():.3f} abs {absolute[k]:.3g} rel {relative[k]:.3g}"
             for k, im in images.items()]
    best = "  p ~ sqrt: abs " + "/".join(f"{v / sum(absolute.values()):.2f}" for v in absolute.values()) + \
        ", rel " + "/".join(f"{v / sum(relative.values()):.2f}" for v in relative.values())
    print(f"{name:36s} {int(lit.sum())} px  " + " | ".join(parts) + best, flush=True)


def sweep(name: str, selections: list[dict], seeds: int) -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import equal_time_vs_mitsuba as et

    from drpt.imageio import read_image
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.lights.selection import LightSelection
    from drpt.render.renderer import Renderer

    case = et.Case(name=name, target=2.0, path=CORPUS / f"test_{name}_path.xml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene, opts, _ = et.setup(case, 192, 10 ** 6)
        wide = Renderer(scene, replace(opts, light_sampler="mixed"))
        o2, s2 = with_scene_settings(RenderOptions(progress=False), _load(name, {"spp": "64"}))
        small = Renderer(s2, replace(o2, spp=64))
    ref = np.asarray(read_image(CORPUS / "refs" / f"test_{name}_ref_rgb.exr"), np.float64)[..., :3]
    for p in selections:
        for r in (wide, small):
            sel = r.scene.emitter_selection
            r.scene.set_light_selection(LightSelection(sel.families, "sweep", weights=slot_weights(sel, p)))
        images = []
        for seed in range(seeds):
            wide.opt.spp, wide.opt.seed = opts.spp, seed
            images.append(wide.render().image.astype(np.float64))
        variance = float(np.stack(images).var(0, ddof=1).mean())
        errors = []
        for seed in range(seeds):
            small.opt.spp, small.opt.seed = 64, seed
            img = small.render().image.astype(np.float64)
            errors.append(float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2))))
        text = "/".join(f"{p[k]:.3f}" for k in ("area", "point", "sky"))
        print(f"{name:36s} {text}  absolute {variance:.5g}  relMSE {float(np.mean(errors)):.5g}", flush=True)


def split(name: str, seeds: int) -> None:
    import time

    sys.path.insert(0, str(ROOT / "benchmarks"))
    import equal_time_vs_mitsuba as et

    from drpt.render.renderer import Renderer
    from drpt.scene.model import PointLight

    case = et.Case(name=name, target=2.0, path=CORPUS / f"test_{name}_path.xml")
    renderers = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for part in ("whole", "point", "others"):
            scene, opts, _ = et.setup(case, 192, 10 ** 6)
            if part == "others":
                scene.lights = [light for light in scene.lights if not isinstance(light, PointLight)]
            elif part == "point":
                scene.lights = [light for light in scene.lights if isinstance(light, PointLight)]
                for m in scene.materials:
                    if m.is_emissive:
                        m.emission = (0.0, 0.0, 0.0)
            renderers[part] = r = Renderer(scene, replace(opts, light_sampler="mixed"))
            r.render()  # compile
    images = {k: [] for k in renderers}
    seconds = {k: [] for k in renderers}
    for seed in range(seeds):
        for part, r in renderers.items():
            r.opt.seed = seed
            t0 = time.perf_counter()
            images[part].append(r.render().image.astype(np.float64))
            seconds[part].append(time.perf_counter() - t0)
    var = {k: float(np.stack(v).var(0, ddof=1).mean()) for k, v in images.items()}
    sec = {k: float(np.median(v)) for k, v in seconds.items()}
    print(f"{name:36s} whole (mixed) {var['whole']:.4g} {sec['whole']:.3f} s | point at every vertex "
          f"{var['point'] + var['others']:.4g} (point alone {var['point']:.4g} {sec['point']:.3f} s, "
          f"the others {var['others']:.4g} {sec['others']:.3f} s) | variance ratio "
          f"{var['whole'] / (var['point'] + var['others']):.2f}", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rows")
    ap.add_argument("--shares", action="store_true")
    ap.add_argument("--sweep", default="")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--split", action="store_true")
    a = ap.parse_args(argv)
    selections = []
    for s in filter(None, a.sweep.split(",")):
        v = [float(x) for x in s.split("/")]
        selections.append(dict(zip(("area", "point", "sky"), np.array(v) / sum(v))))
    for name in a.rows.split(","):
        probabilities(name)
        if a.shares:
            shares(name)
        if selections:
            sweep(name, selections, a.seeds)
        if a.split:
            split(name, a.seeds)


if __name__ == "__main__":
    main()
