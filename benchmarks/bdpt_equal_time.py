"""Equal-time error of bidirectional path tracing against the path tracer (not a test).

For each scene (the bundled Cornell box; the caustic scene of
:mod:`drpt.tools.scenegen.caustic`: a glass sphere on a diffuse floor under a small
spherical area light, with a back wall; and the seed's Cornell box with a glass sphere,
authored here from its report, :func:`seed_glass_cornell`), both
integrators render SIZE x SIZE at their spp after a warm-up render of 1 spp that
compiles the kernels; a bdpt render of REF_SPP spp and another seed is the reference
(by default 16384 spp for the Cornell boxes and 131072 for the caustic scene, below).
Prints per integrator the seconds (the fastest of REPEAT renders; also the process's CPU
seconds, steadier on a loaded machine), the relMSE against the reference (minus the
reference's own estimated relMSE) and relMSE x seconds (lower is better: the relMSE at
equal time, up to a constant), then bdpt's relMSE x seconds over path's (by wall and by
CPU seconds). ``--sampler`` sets both integrators' sampler (the reference's stays
``independent``); ``--path-sampler`` and ``--bdpt-sampler`` set one integrator's (``auto``:
what a user gets, :func:`drpt.options.resolve_sampler`).

``--seeds N`` renders each integrator with seeds ``2 .. N + 1``, path and bdpt in turns
(ABAB: both see the same load), and sums the relMSE and the seconds over the seeds (one
seed's error is heavy-tailed where caustics are; the ratio of sums is the equal-time
ratio of the N-seed renders). ``--reference PATH`` keeps the references in the folder
``PATH`` (``SCENE-SIZE-DEPTH-REFSPP.npz``: the image and its estimated relMSE), rendered
there the first time and read afterwards, so that runs of two commits are scored against
the same images. A reference must hold every pixel's rare paths many times over: on the
caustic scene the camera sees the small light through the glass sphere in a few pixels, a
hit in about 1 of 250-1000 samples there, which a 2048-spp reference holds 2-8 times on average (its
values there 0.3-1.2x the converged ones, and a render's hit there then reads as a
firefly), so that scene's default reference has 131072 spp (docs/performance.md, "The caustic
scene's reference"; about 5 minutes on 2 cores: keep it with ``--reference``). ``--ref-spp``
sets every scene's.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bdpt_equal_time.py [--size 64] [--depth 8]
[--path-spp 256] [--bdpt-spp 64] [--ref-spp N] [--scenes cornell,caustic,glass] [--repeat 3]
[--sampler auto] [--path-sampler S] [--bdpt-sampler S] [--seeds 1] [--reference PATH]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from drpt.tools.scenegen.caustic import SCENE as CAUSTIC


def seed_glass_cornell() -> str:
    """The seed's Cornell box (its report's scene: a box of [-1, 1]^3 open toward the camera,
    a red left and a green right wall, white floor, ceiling and back wall, a 0.5 x 0.5 area
    light of radiance 10 just below the ceiling, a tall box of 0.5 x 0.5 x 1.5 turned by 45
    degrees at (-0.45, -0.5), a sphere of radius 0.5 on the floor at (0.5, -0.5, 0)), its
    sphere made of glass (IOR 1.5) and its tall box glossy Phong (Kd 0.5, Ks 0.5, Ns 33:
    the report's Kd 1 and Ks 1 would reflect twice the light it receives)."""
    def quad(a, b, c, d):  # two triangles a b c, a c d (the winding sets the light's side)
        return [f"Triangle {{ vertex0 {a} vertex1 {b} vertex2 {c} }}",
                f"Triangle {{ vertex0 {a} vertex1 {c} vertex2 {d} }}"]

    def v(x, y, z):
        return f"{x:.6g} {y:.6g} {z:.6g}"

    white = (quad(v(-1, -1, -1), v(1, -1, -1), v(1, -1, 1), v(-1, -1, 1))  # floor
             + quad(v(-1, 1, -1), v(-1, 1, 1), v(1, 1, 1), v(1, 1, -1))  # ceiling
             + quad(v(-1, -1, -1), v(-1, 1, -1), v(1, 1, -1), v(1, -1, -1)))  # back wall
    red = quad(v(-1, -1, -1), v(-1, -1, 1), v(-1, 1, 1), v(-1, 1, -1))
    green = quad(v(1, -1, -1), v(1, 1, -1), v(1, 1, 1), v(1, -1, 1))
    h = 0.9999
    light = quad(v(-0.25, h, -0.25), v(0.25, h, -0.25), v(0.25, h, 0.25), v(-0.25, h, 0.25))  # faces -y
    r = 0.25 * math.sqrt(2.0)  # the tall box's corners, 45 degrees around (-0.45, ., -0.5)
    corners = [(-0.45 + r * math.cos(a), -0.5 + r * math.sin(a)) for a in (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi)]
    box = quad(*(v(x, 0.5, z) for x, z in corners))
    for (x0, z0), (x1, z1) in zip(corners, corners[1:] + corners[:1]):
        box += quad(v(x0, -1, z0), v(x1, -1, z1), v(x1, 0.5, z1), v(x0, 0.5, z0))
    groups = [("0", white), ("1", red), ("2", green), ("3", box), ("5", light)]
    body = []
    for index, tris in groups:
        body += [f"  MaterialIndex {index}"] + [f"  {t}" for t in tris]
    body += ["  MaterialIndex 4", "  Sphere { center 0.5 -0.5 0 radius 0.5 }"]
    count = sum(len(t) for _, t in groups) + 1
    return "\n".join([
        "PerspectiveCamera { center 0 0 2.5 direction 0 0 -1 up 0 1 0 angle 60 }",
        "Materials { numMaterials 6",
        "  Material { diffuseColor 1 1 1 }",
        "  Material { diffuseColor 1 0 0 }",
        "  Material { diffuseColor 0 1 0 }",
        "  Material { diffuseColor 0.5 0.5 0.5 specularColor 0.5 0.5 0.5 exponent 33 }",
        "  Material { transparentColor 1 1 1 indexOfRefraction 1.5 }",
        "  Material { Ke 10 10 10 }",
        "}",
        f"Group {{ numObjects {count}", *body, "}", ""])


REF_SPP = {"cornell": 16384, "glass": 16384, "caustic": 131072}  # the references' default spp


def scene_files(folder: Path) -> dict[str, Path]:
    """The scene files by ``--scenes`` name: the bundled Cornell box, and the caustic scene and
    the glass Cornell box written into ``folder``."""
    (folder / "caustic.txt").write_text(CAUSTIC)
    (folder / "glass_cornell.txt").write_text(seed_glass_cornell())
    repo = Path(__file__).resolve().parents[1]
    return {"cornell": repo / "scenes" / "cornellbox" / "cornellbox.txt", "caustic": folder / "caustic.txt",
            "glass": folder / "glass_cornell.txt"}


def main() -> None:
    from drpt.metrics import rel_mse
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--path-spp", type=int, default=256)
    p.add_argument("--bdpt-spp", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=None,
                   help="the references' spp (default: REF_SPP, per scene)")
    p.add_argument("--scenes", default="cornell,caustic,glass")
    p.add_argument("--repeat", type=int, default=3, help="timed renders; the fastest counts")
    p.add_argument("--sampler", default="auto", help="both integrators' --sampler (default: each one's own)")
    p.add_argument("--path-sampler", default=None, help="the path tracer's --sampler (default: --sampler)")
    p.add_argument("--bdpt-sampler", default=None, help="bdpt's --sampler (default: --sampler)")
    p.add_argument("--seeds", type=int, default=1, help="renders of seeds 2 .. N + 1 each, in turns")
    p.add_argument("--reference", type=Path, default=None,
                   help="a folder that keeps the references (rendered there when missing)")
    a = p.parse_args()
    files = scene_files(Path(tempfile.mkdtemp()))
    for name in a.scenes.split(","):
        scene = load_scene(files[name])
        base = RenderOptions(width=a.size, height=a.size, progress=False, path=PathOptions(max_depth=a.depth),
                             sampler=a.sampler)
        ref_image, ref_err = reference(scene, base, name, a)
        renderers = {}
        samplers = {"path": a.path_sampler or a.sampler, "bdpt": a.bdpt_sampler or a.sampler}
        for integrator, spp in (("path", a.path_spp), ("bdpt", a.bdpt_spp)):
            r = Renderer(scene, replace(base, integrator=integrator, spp=1, seed=1, sampler=samplers[integrator]))
            r.render()  # compiles the kernels
            renderers[integrator] = r.derive(replace(r.opt, spp=spp))
        totals = {k: [0.0, 0.0, 0.0] for k in renderers}  # relMSE, seconds, CPU seconds
        for seed in range(2, a.seeds + 2):
            for integrator, r in renderers.items():  # in turns: the same load for both
                r = r.derive(replace(r.opt, seed=seed))
                seconds, cpu = math.inf, math.inf
                for _ in range(a.repeat):  # the same seed: the same image, the fastest time
                    t, c = time.perf_counter(), time.process_time()
                    img = r.render()
                    seconds = min(seconds, time.perf_counter() - t)
                    cpu = min(cpu, time.process_time() - c)
                err = rel_mse(img.image, ref_image) - ref_err
                for i, v in enumerate((err, seconds, cpu)):
                    totals[integrator][i] += v
                print(f"{name} {integrator} seed {seed}: {r.opt.spp} spp, {r.opt.sampler}, {seconds:.2f} s "
                      f"({cpu:.2f} s CPU), relMSE {err:.4g}, relMSE x s {err * seconds:.4g}", flush=True)
        rows = {}
        for integrator, (err, seconds, cpu) in totals.items():
            rows[integrator] = (err * seconds, err * cpu)
            print(f"{name} {integrator}: {a.seeds} seeds, {seconds:.2f} s ({cpu:.2f} s CPU), "
                  f"relMSE (mean) {err / a.seeds:.4g}")
        print(f"{name}: bdpt / path relMSE at equal time {rows['bdpt'][0] / rows['path'][0]:.3f} "
              f"(by CPU seconds {rows['bdpt'][1] / rows['path'][1]:.3f}; {a.seeds} seeds; reference: bdpt "
              f"{ref_spp(name, a)} spp, its estimated relMSE {ref_err:.3g})", flush=True)


def ref_spp(name: str, a) -> int:
    """The reference's spp: ``--ref-spp`` where given, else the scene's :data:`REF_SPP`."""
    return a.ref_spp if a.ref_spp is not None else REF_SPP[name]


def reference(scene, base, name: str, a) -> tuple:
    """``(image, estimated relMSE)`` of the reference: a bdpt render of :func:`ref_spp` spp,
    seed 99, ``independent``, without caustic merging, with its variance; kept in (or read from) the folder
    ``a.reference`` when given."""
    import numpy as np

    from drpt.render.renderer import Renderer

    path = None
    if a.reference is not None:
        path = a.reference / f"{name}-{a.size}-{a.depth}-{ref_spp(name, a)}.npz"
        if path.exists():
            data = np.load(path)
            return data["image"], float(data["rel_mse"])
    opt = replace(base, integrator="bdpt", spp=ref_spp(name, a), seed=99, sampler="independent")
    names = {f.name for f in dataclasses.fields(opt)}
    if "variance" in names:
        opt = replace(opt, variance=True)  # (its estimated relMSE is subtracted)
    if "bdpt_merge" in names:
        opt = replace(opt, bdpt_merge=False)  # (unbiased: caustic merging is consistent, not unbiased)
    ref = Renderer(scene, opt).render()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, image=ref.image, rel_mse=ref.estimated_rel_mse)
    return ref.image, ref.estimated_rel_mse


if __name__ == "__main__":
    main()
