"""The light selection rules on every multi-emitter scene at hand, at equal spp and equal time.

    PYTHONPATH=. .venv/bin/python benchmarks/light_sampler.py [SPP] [REPEATS] [NAMES]

The scenes: every scene with more than one emitter (an emitter: an emissive shape, a delta
light, the sky) that drpt reads and that is at hand: the generated ones (Veach's MIS scene
tessellated, the 50-light floor of :mod:`drpt.tools.scenegen.many_lights`, a sky with a
sun and a point light, the living room at 64x64), the seed's scenes with an area light and
a sky (``../shared/seed/scenes``), the test XML scenes (``tests/data/xml``; ``ptracer.xml``
also rendered by the path tracer) and the Mitsuba corpus scenes (``../shared/corpus``:
the sphere grids with an area light, a point light and a sky, two media scenes, the
various-emitters scene); those whose files are absent are left out. ``NAMES``: only the
scenes whose names start with one of these comma-separated prefixes.

For each scene drpt renders ``REPEATS`` images (seeds 0..) at ``SPP`` (default 64) with
each ``--light-sampler`` rule (:data:`drpt.options.LIGHT_SAMPLERS`), the rules taken round
robin so that load from other processes spreads over all of them, and measures each
image's relMSE (``mean((x - ref)^2 / (ref^2 + 0.01))``) against a reference: the corpus
scene's shipped Mitsuba reference, Mitsuba at 8192 spp for the other XML scenes, drpt at
8192 spp (``uniform``, another seed) for drpt's own format. It prints one row per scene:
the number of emitters, each rule's mean relMSE, its seconds, and its efficiency relative
to ``uniform`` (Mitsuba's rule): ``relMSE_uniform * s_uniform / (relMSE * s)``, above 1:
better than uniform at equal time. The rules whose selection is static (``uniform``,
``power``, ``mixed``, ...) trace the same kernel, only their tables differ, so they share
one time, the fastest of all their renders (the time of a short render on a loaded machine
is noise that would otherwise swamp their ratios); ``bvh`` walks its tree at every light
sample and every emitter hit and is timed alone (its fastest render; compilation excluded:
a discarded first render). ``pilot`` measures its selection when the renderer is built
(:mod:`drpt.render.lights.pilot`): its column "pilot s" is that build's seconds less
``mixed``'s, which the render seconds leave out. Last, per rule, the geometric mean of its efficiency over the
scenes and its worst scene.
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
SHARED = ROOT.parent / "shared"
CORPUS = SHARED / "corpus" / "mitsuba-data" / "tests" / "scenes"
SEED = SHARED / "seed" / "scenes"
REF_SPP = 8192
SIZE = 64  # drpt's own format: SIZE x SIZE
SPHERES = ("bumpmap", "normalmap_identity_roughconductor", "normalmap", "normalmap_roughconductor",
           "roughdielectric", "roughplastic_linear", "roughplastic_nonlinear", "textured_diffuse",
           "textured_roughconductor", "texturedprincipled1", "texturedprincipled2", "texturedprincipledthin")


def scenes() -> list[tuple[str, Path, str, dict]]:
    """``(name, path, reference kind, defines)``; kind ``drpt``, ``mitsuba`` or ``corpus``."""
    from drpt.tools.scenegen import envsun, living_room, many_lights, veach_mis

    tmp = Path(tempfile.mkdtemp())
    first = lambda paths, suffix: next(p for p in paths if p.suffix == suffix)  # noqa: E731
    xml = ROOT / "tests/data/xml"
    out = [(f"{n}.xml", xml / f"{n}.xml", "mitsuba", {})
           for n in ("veach_mis", "sphere_light", "area_textured", "hide_emitters", "thin", "projector_spot",
                     "ptracer")]
    out.append(("ptracer.xml (path)", xml / "ptracer.xml", "mitsuba", {"integrator": "path"}))
    out += [(f"bsdf_spheres/{n}", CORPUS / "bsdf_spheres" / f"test_{n}_path.xml", "corpus", {}) for n in SPHERES]
    out += [(rel.split("/test_")[1].rsplit("_", 1)[0], CORPUS / rel, "corpus", {})
            for rel in ("participating_media/test_homo_emitter_inside_medium_volpath.xml",
                        "participating_media/test_surf_area_light_volpath.xml",
                        "various_emitters/test_various_emitters_ptracer.xml")]
    out += [("veach_mis (scenegen, tessellated)", first(veach_mis.main(tmp / "veach"), ".txt"), "drpt", {}),
            ("many_lights (scenegen, 50 lights)", first(many_lights.main(tmp / "many", 50), ".txt"), "drpt", {}),
            ("envsun + point light (scenegen)", envsun.main(tmp / "envsun", point=True), "drpt", {})]
    out += [(f"seed {n}.txt", SEED / f"{n}.txt", "drpt", {}) for n in ("cornellbox", "newscene")]
    out.append(("living_room (scenegen, 64x64)", first(living_room.main(tmp / "living"), ".xml"), "mitsuba",
                {"w": "64", "h": "64"}))
    return [x for x in out if x[1].is_file()]


def options(scene, spp, seed, rule):
    opts, scene = with_scene_settings(RenderOptions(progress=False, seed=seed, light_sampler=rule), scene)
    if scene.settings is None:
        opts = replace(opts, width=SIZE, height=SIZE)
    return replace(opts, spp=spp)


def reference(path, kind, scene, defines):
    from drpt.imageio import read_image

    if kind == "corpus":
        stem = path.stem.rsplit("_", 1)[0]
        return np.asarray(read_image(path.parent / "refs" / f"{stem}_ref_rgb.exr"), np.float64)[..., :3]
    if kind == "mitsuba":
        import mitsuba as mi

        from drpt.backend import mitsuba_variant

        mi.set_variant(mitsuba_variant())
        ms = mi.load_file(str(path), optimize=False, **defines)
        return np.mean([np.asarray(mi.render(ms, spp=REF_SPP // 8, seed=1000 + k), np.float64)[..., :3]
                        for k in range(8)], 0)
    return Renderer(scene, options(scene, REF_SPP, 10**6, "uniform")).render().image.astype(np.float64)


def emitters(device_scene) -> int:
    return sum(len(np.unique(f.units()[0])) for f in device_scene.emitter_selection.families)


def measure(path, kind, defines, rules, spp, repeats) -> tuple[int, dict, dict, dict]:
    """The scene's emitter count and each rule's mean relMSE, seconds and build seconds."""
    defines = {**({"spp": str(spp)} if kind == "corpus" else {}), **defines}
    scene = load_scene(path, defines=defines) if defines else load_scene(path)
    ref = reference(path, kind, scene, defines)
    renderers = {}
    for rule in rules:
        renderers[rule] = r = Renderer(scene, options(scene, 1, 99, rule))
        r.render()  # compile
    errs = {k: [] for k in rules}
    secs = {k: [] for k in rules}
    for seed in range(repeats):
        for rule in rules:
            r2 = renderers[rule].derive(options(scene, spp, seed, rule))
            t0 = time.perf_counter()
            img = r2.render().image.astype(np.float64)
            secs[rule].append(time.perf_counter() - t0)
            errs[rule].append(float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2))))
    static = [r for r in rules if renderers[r].scene.emitter_selection.static]
    shared = min(min(secs[r]) for r in static)
    seconds = {r: shared if r in static else min(secs[r]) for r in rules}
    build = {r: renderers[r].build_seconds for r in rules}
    return emitters(renderers[rules[0]].scene), {r: float(np.mean(errs[r])) for r in rules}, seconds, build


def main(spp=64, repeats=4, which=None):
    from drpt.options import LIGHT_SAMPLERS

    rules = ["uniform"] + [r for r in LIGHT_SAMPLERS if r != "uniform"]
    others = rules[1:]
    print(f"{spp} spp, {repeats} seeds; efficiency: relMSE x seconds of uniform over the rule's\n")
    print("| scene | emitters | " + " | ".join(f"relMSE {r}" for r in rules) + " | s static | "
          + " | ".join(f"s {r}" for r in others if r == "bvh") + " | "
          + " | ".join(f"{r} / uniform" for r in others) + " |" + (" pilot s |" if "pilot" in rules else ""))
    print("|---" * (2 + len(rules) + 1 + ("bvh" in others) + len(others) + ("pilot" in rules)) + "|")
    todo = scenes()
    if which:
        todo = [x for x in todo if any(x[0].startswith(w) for w in which.split(","))]
    eff = {r: [] for r in others}
    for name, path, kind, defines in todo:
        count, err, sec, build = measure(path, kind, defines, rules, spp, repeats)
        row = {r: err["uniform"] * sec["uniform"] / (err[r] * sec[r]) for r in others}
        for r in others:
            eff[r].append((row[r], name))
        print(f"| {name} | {count} | " + " | ".join(f"{err[r]:.4g}" for r in rules) + f" | {sec['uniform']:.2f} | "
              + " | ".join(f"{sec[r]:.2f}" for r in others if r == "bvh") + " | "
              + " | ".join(f"{row[r]:.2f}" for r in others) + " |"
              + (f" {build['pilot'] - build['mixed']:.2f} |" if "pilot" in rules else ""), flush=True)
    print(f"\nover {len(todo)} scenes, efficiency relative to uniform:")
    for r in others:
        vals = np.array([v for v, _ in eff[r]])
        worst = min(eff[r])
        print(f"  {r}: geometric mean {np.exp(np.mean(np.log(vals))):.2f}, worst {worst[0]:.2f} ({worst[1]}), "
              f"best {max(eff[r])[0]:.2f} ({max(eff[r])[1]})")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]), *sys.argv[3:4])
