"""The light samplers (power, Mitsuba's uniform, mixed, the light BVH) at equal spp and equal time.

    PYTHONPATH=. .venv/bin/python benchmarks/light_sampler.py [SPP] [REPEATS] [all|mixed|NAMES]

For each scene with area lights (the bundled ones, the generated Veach MIS scene and the
50-light scene of :mod:`drpt.tools.scenegen.many_lights`, the XML
test scenes with several emitters, and the Mitsuba corpus scenes with area lights that drpt
reads, when ``../shared/corpus`` is present) and each scene whose emitters are of several
families (``mixed``, the only ones with that argument: the generated sky-and-sun scene
with a point light, ``ptracer.xml`` rendered by the path tracer (area, point, spot and
directional lights and a sky), ``projector_spot.xml``, and the corpus's media scenes with
an area light and a sky, rendered by volpath; ``NAMES``: the scenes whose names start with
one of these comma-separated prefixes) drpt renders ``REPEATS`` images (seeds 0..)
at ``SPP`` (default 64) with each ``--light-sampler`` (``power``, ``uniform``, ``mixed``,
``bvh``; those the checkout has), and measures
each against a reference: the corpus scene's shipped Mitsuba reference, Mitsuba at 8192
spp for the other XML scenes, and drpt at 8192 spp (power, another seed) for drpt's own
format. It prints, per scene, the emitters, the mean relMSE
(``mean((x - ref)^2 / (ref^2 + 0.01))``) of each sampler, the fastest render's seconds
(compilation excluded: a discarded first render; the samplers' renders taken round robin,
so that load from other processes spreads over all of them), and each other rule's ratio
to ``power`` at equal time (relMSE times seconds; below 1: that rule is better).
``power``, ``uniform`` and ``mixed`` trace the same kernel (only the tables differ), so
their time ratio is 1 up to the timing noise of short renders; ``bvh`` walks the tree at
every light sample and every emitter hit. For XML scenes Mitsuba's relMSE at the same
spp (its seeds 0..) and drpt's (power) over it follow.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from drpt.options import RenderOptions, with_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT.parent / "shared" / "corpus" / "mitsuba-data" / "tests" / "scenes"
REF_SPP = 8192


def mixed_scenes(tmp: Path) -> list[tuple[str, Path, str, dict]]:
    """Scenes whose emitters are of several families: ``(name, path, reference kind,
    defines)``."""
    from drpt.tools.scenegen import envsun

    xml = ROOT / "tests/data/xml"
    out = [("envsun + point light (scenegen)", envsun.main(tmp / "envsun", point=True), "drpt", {}),
           ("ptracer.xml (path)", xml / "ptracer.xml", "mitsuba", {"integrator": "path"}),
           ("projector_spot.xml", xml / "projector_spot.xml", "mitsuba", {})]
    for rel in ("participating_media/test_homo_emitter_inside_medium_volpath.xml",
                "participating_media/test_homo_obj_inside_medium_volpath.xml",
                "participating_media/test_surf_area_light_volpath.xml"):
        if (CORPUS / rel).is_file():
            out.append((rel, CORPUS / rel, "corpus", {}))
    return out


def scenes() -> list[tuple[str, Path, str]]:
    """``(name, path, reference kind)``: ``drpt``, ``mitsuba`` or ``corpus``."""
    from drpt.tools.scenegen import many_lights, veach_mis

    tmp = Path(tempfile.mkdtemp())
    out = [("cornellbox", ROOT / "scenes/cornellbox/cornellbox.txt", "drpt"),
           ("newscene", ROOT / "scenes/newscene/newscene.txt", "drpt"),
           ("veach_mis (scenegen, tessellated)",
            next(p for p in veach_mis.main(tmp) if p.suffix == ".txt"), "drpt"),
           ("many_lights (scenegen, 50 lights)",
            next(p for p in many_lights.main(tmp, 50) if p.suffix == ".txt"), "drpt")]
    xml = ROOT / "tests/data/xml"
    out += [(f"{n}.xml", xml / f"{n}.xml", "mitsuba") for n in ("veach_mis", "sphere_light", "ptracer")]
    for rel in ("bsdf_spheres/test_arealight_path.xml", "various_emitters/test_various_emitters_ptracer.xml"):
        if (CORPUS / rel).is_file():
            out.append((rel, CORPUS / rel, "corpus"))
    return [(*x, {}) for x in out] + mixed_scenes(tmp)


def options(scene, spp, seed, sampler, size):
    opts, scene = with_scene_settings(RenderOptions(progress=False, seed=seed, light_sampler=sampler), scene)
    if scene.settings is None:
        opts = replace(opts, width=size, height=size)
    return replace(opts, spp=spp)


def reference(name, path, kind, scene, size, defines=None):
    from drpt.imageio import read_image

    if kind == "corpus":
        stem = path.stem.rsplit("_", 1)[0]
        return np.asarray(read_image(path.parent / "refs" / f"{stem}_ref_rgb.exr"), np.float64)[..., :3]
    if kind == "mitsuba":
        import mitsuba as mi

        from drpt.backend import mitsuba_variant

        mi.set_variant(mitsuba_variant())
        ms = mi.load_file(str(path), optimize=False, **(defines or {}))
        return np.mean([np.asarray(mi.render(ms, spp=REF_SPP // 8, seed=1000 + k), np.float64)[..., :3]
                        for k in range(8)], 0)
    return Renderer(scene, options(scene, REF_SPP, 10**6, "power", size)).render().image.astype(np.float64)


def mitsuba_error(path, kind, spp, repeats, ref, extra=None):
    """Mitsuba's mean relMSE at ``spp`` on an XML scene (``None`` for drpt's own format)."""
    if kind == "drpt":
        return None
    import mitsuba as mi

    from drpt.backend import mitsuba_variant

    mi.set_variant(mitsuba_variant())
    defines = {"spp": str(spp)} if kind == "corpus" else {}
    ms = mi.load_file(str(path), optimize=False, **defines, **(extra or {}))
    errs = [np.mean((np.asarray(mi.render(ms, spp=spp, seed=k), np.float64)[..., :3] - ref) ** 2
                    / (ref ** 2 + 1e-2)) for k in range(repeats)]
    return float(np.mean(errs))


def emitters(device_scene) -> int:
    sel = getattr(device_scene, "emitter_selection", None)
    if sel is None:  # (a checkout before the one light selection: its area emitters)
        return getattr(device_scene.area_lights, "emitters", 0)
    return sum(len(np.unique(f.units()[0])) for f in sel.families)


def main(spp=64, repeats=4, which="all", size=64):
    from drpt.options import LIGHT_SAMPLERS

    rules = [r for r in ("power", "uniform", "mixed", "bvh") if r in LIGHT_SAMPLERS]
    print("| scene | emitters | " + " | ".join(f"relMSE {r}" for r in rules) + " | "
          + " | ".join(f"s {r}" for r in rules) + " | " + " | ".join(f"{r} / power, equal time" for r in rules[1:])
          + " | Mitsuba relMSE | power / Mitsuba |\n" + "|---" * (3 * len(rules) + 3) + "|")
    if which in ("all", "mixed"):
        todo = scenes() if which == "all" else mixed_scenes(Path(tempfile.mkdtemp()))
    else:  # scenes whose names start with one of the comma-separated prefixes
        todo = [x for x in scenes() if any(x[0].startswith(w) for w in which.split(","))]
    for name, path, kind, extra in todo:
        defines = {**({"spp": str(spp)} if kind == "corpus" else {}), **extra}
        scene = load_scene(path, defines=defines) if defines else load_scene(path)
        ref = reference(name, path, kind, scene, size, extra)
        renderers = {}
        for sampler in rules:
            renderers[sampler] = r = Renderer(scene, options(scene, 1, 99, sampler, size))
            r.render()  # compile
        errs = {k: [] for k in rules}
        secs = {k: [] for k in rules}
        for seed in range(repeats):
            for sampler in rules:
                r2 = renderers[sampler].derive(options(scene, spp, seed, sampler, size))
                t0 = time.perf_counter()
                img = r2.render().image.astype(np.float64)
                secs[sampler].append(time.perf_counter() - t0)
                errs[sampler].append(float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2))))
        row = {k: (float(np.mean(errs[k])), float(np.min(secs[k])), emitters(renderers[k].scene))
               for k in rules}
        ep, sp, count = row["power"]
        em = mitsuba_error(path, kind, spp, repeats, ref, extra)
        mcols = "| | |" if em is None else f"| {em:.4g} | {ep / em:.2f} |"
        print(f"| {name} | {count} | " + " | ".join(f"{row[r][0]:.4g}" for r in rules) + " | "
              + " | ".join(f"{row[r][1]:.2f}" for r in rules) + " | "
              + " | ".join(f"{row[r][0] * row[r][1] / (ep * sp):.2f}" for r in rules[1:]) + f" {mcols}", flush=True)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]), *sys.argv[3:4])
