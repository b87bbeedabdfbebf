"""The light samplers (power, Mitsuba's uniform, the light BVH) at equal spp and equal time.

    PYTHONPATH=. .venv/bin/python benchmarks/light_sampler.py [SPP] [REPEATS] [SIZE]

For each scene with area lights (the bundled ones, the generated Veach MIS scene and the
50-light scene of :mod:`drpt.tools.scenegen.many_lights`, the XML test scenes with several
emitters, and the Mitsuba corpus scenes with area lights that drpt reads, when
``../shared/corpus`` is present) drpt renders ``REPEATS`` images (seeds 0..) at ``SPP``
(default 64) with each ``--light-sampler``, and measures each against a reference: the
corpus scene's shipped Mitsuba reference, Mitsuba at 8192 spp for the other XML scenes,
and drpt at 8192 spp (power, another seed) for drpt's own format (``SIZE`` x ``SIZE``
pixels, default 64). It prints, per scene, the emitters, the mean relMSE
(``mean((x - ref)^2 / (ref^2 + 0.01))``) of each sampler, the fastest render's seconds
(compilation excluded: a discarded first render; the samplers' renders taken round robin,
so that load from other processes spreads over all of them), and the ratios ``X / power``
of the relMSE at equal time (relMSE times seconds); below 1: X is better. ``power`` and
``uniform`` trace the same kernel (only the tables differ), so their time ratio is 1 up
to the timing noise of short renders; ``bvh`` walks the tree at every light sample and
every emitter hit. For XML scenes Mitsuba's relMSE at the same spp (its seeds 0..)
follows.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from drpt.options import RenderOptions, apply_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT.parent / "shared" / "corpus" / "mitsuba-data" / "tests" / "scenes"
REF_SPP = 8192


def scenes() -> list[tuple[str, Path, str]]:
    """``(name, path, reference kind)``: ``drpt``, ``mitsuba`` or ``corpus``."""
    from drpt.tools.scenegen import many_lights, veach_mis

    tmp = Path(tempfile.mkdtemp())
    out = [("cornellbox", ROOT / "scenes/cornellbox/cornellbox.txt", "drpt"),
           ("newscene", ROOT / "scenes/newscene/newscene.txt", "drpt"),
           ("newscene_hard", ROOT / "scenes/newscene/newscene_hard.txt", "drpt"),
           ("veach_mis (scenegen, tessellated)",
            next(p for p in veach_mis.main(tmp) if p.suffix == ".txt"), "drpt"),
           ("many_lights (scenegen, 50 lights)",
            next(p for p in many_lights.main(tmp, 50) if p.suffix == ".txt"), "drpt")]
    xml = ROOT / "tests/data/xml"
    out += [(f"{n}.xml", xml / f"{n}.xml", "mitsuba") for n in ("veach_mis", "sphere_light", "ptracer")]
    for rel in ("bsdf_spheres/test_arealight_path.xml", "various_emitters/test_various_emitters_ptracer.xml"):
        if (CORPUS / rel).is_file():
            out.append((rel, CORPUS / rel, "corpus"))
    return out


def options(scene, spp, seed, sampler, size):
    opts = apply_scene_settings(RenderOptions(progress=False, seed=seed, light_sampler=sampler), scene)
    if scene.settings is None:
        opts = replace(opts, width=size, height=size)
    return replace(opts, spp=spp)


def reference(name, path, kind, scene, size):
    from drpt.imageio import read_image

    if kind == "corpus":
        stem = path.stem.rsplit("_", 1)[0]
        return np.asarray(read_image(path.parent / "refs" / f"{stem}_ref_rgb.exr"), np.float64)[..., :3]
    if kind == "mitsuba":
        import mitsuba as mi

        from drpt.backend import mitsuba_variant

        mi.set_variant(mitsuba_variant())
        ms = mi.load_file(str(path), optimize=False)
        return np.mean([np.asarray(mi.render(ms, spp=REF_SPP // 8, seed=1000 + k), np.float64)[..., :3]
                        for k in range(8)], 0)
    return Renderer(scene, options(scene, REF_SPP, 10**6, "power", size)).render().image.astype(np.float64)


def mitsuba_error(path, kind, spp, repeats, ref):
    """Mitsuba's mean relMSE at ``spp`` on an XML scene (``None`` for drpt's own format)."""
    if kind == "drpt":
        return None
    import mitsuba as mi

    from drpt.backend import mitsuba_variant

    mi.set_variant(mitsuba_variant())
    defines = {"spp": str(spp)} if kind == "corpus" else {}
    ms = mi.load_file(str(path), optimize=False, **defines)
    errs = [np.mean((np.asarray(mi.render(ms, spp=spp, seed=k), np.float64)[..., :3] - ref) ** 2
                    / (ref ** 2 + 1e-2)) for k in range(repeats)]
    return float(np.mean(errs))


SAMPLERS = ("power", "uniform", "bvh")


def main(spp=64, repeats=4, size=64):
    print("| scene | emitters | relMSE power | uniform | bvh | s power | uniform | bvh | "
          "uniform / power, equal time | bvh / power, equal time | Mitsuba relMSE |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|")
    for name, path, kind in scenes():
        defines = {"spp": str(spp)} if kind == "corpus" else None
        scene = load_scene(path, defines=defines) if defines else load_scene(path)
        ref = reference(name, path, kind, scene, size)
        renderers = {}
        for sampler in SAMPLERS:
            renderers[sampler] = r = Renderer(scene, options(scene, 1, 99, sampler, size))
            r.render()  # compile
        errs = {k: [] for k in SAMPLERS}
        secs = {k: [] for k in SAMPLERS}
        for seed in range(repeats):
            for sampler in SAMPLERS:
                r2 = renderers[sampler].derive(options(scene, spp, seed, sampler, size))
                t0 = time.perf_counter()
                img = r2.render().image.astype(np.float64)
                secs[sampler].append(time.perf_counter() - t0)
                errs[sampler].append(float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2))))
        row = {k: (float(np.mean(errs[k])), float(np.min(secs[k])), renderers[k].scene.area_lights)
               for k in SAMPLERS}
        ep, sp, lights = row["power"]
        em = mitsuba_error(path, kind, spp, repeats, ref)
        errs = " | ".join(f"{row[k][0]:.4g}" for k in SAMPLERS)
        secs = " | ".join(f"{row[k][1]:.2f}" for k in SAMPLERS)
        ratios = " | ".join(f"{row[k][0] * row[k][1] / (ep * sp):.2f}" for k in SAMPLERS[1:])
        print(f"| {name} | {getattr(lights, 'emitters', 0)} | {errs} | {secs} | {ratios} | "
              f"{'' if em is None else f'{em:.4g}'} |", flush=True)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
