"""Regenerates the Mitsuba 3 reference images in reference/.

Each bundled scene is exported with drpt's Mitsuba exporter and rendered by
Mitsuba's ``path`` integrator (llvm_ad_rgb) at high spp; the EXR holds linear
float32 RGB. Run from the repository root:

    .venv/bin/python reference/make_references.py            # all
    .venv/bin/python reference/make_references.py cornellbox # one

References listed in ``BATCHES`` are rendered as independent batches and also
write ``<name>_..._var.exr``, the per-pixel variance of the mean (the batches'
spread), for tests whose own low-spp variance estimate is unreliable.

The dining room (``scenes/diningroom/``, git-ignored) is generated first by
``scenes/make_diningroom.py`` at its default size when it is missing or was
generated at another triangle count (:func:`scene_path`); the generator is
deterministic, so the reference always matches the regenerated scene.

The table below is the single source of truth for what each reference is;
tests read it through :func:`reference_path`.
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# name: (scene file, width, height, spp, max_depth, material mode)
REFERENCES = {
    "cornellbox": ("scenes/cornellbox/cornellbox.txt", 128, 128, 8192, -1, "phong"),
    "newscene": ("scenes/newscene/newscene.txt", 96, 96, 4096, -1, "cook-torrance"),
    "newscene_hard": ("scenes/newscene/newscene_hard.txt", 96, 96, 4096, -1, "cook-torrance"),
    # the Cornell box read as Cook-Torrance (Kd only: alpha sqrt(2/(Ns+2)) = 0.82, metalness 0)
    "cornellbox_ct": ("scenes/cornellbox/cornellbox.txt", 128, 128, 8192, -1, "cook-torrance"),
    "showcase_day": ("scenes/showcase/showcase_day.txt", 128, 72, 4096, -1, "cook-torrance"),
    "showcase_dusk": ("scenes/showcase/showcase_dusk.txt", 128, 72, 4096, -1, "cook-torrance"),
    "diningroom": ("scenes/diningroom/diningroom.txt", 96, 96, 4096, -1, "cook-torrance"),
}

# References rendered as this many independent batches (default 1): their spread gives
# the per-pixel variance of the reference (variance_path). Scenes lit through glass and
# by a small sun have heavy-tailed samples; a test at low spp cannot estimate their
# variance from its own samples, the reference's 4096 can.
BATCHES = {"showcase_day": 16, "showcase_dusk": 16, "diningroom": 16}

# Scenes generated on demand (git-ignored): scene file -> (generator, triangle count of
# its default output). The count is read back from the OBJ's first line.
GENERATED = {
    "scenes/diningroom/diningroom.txt": ("scenes/make_diningroom.py", 510_416),
}


def reference_path(name: str) -> Path:
    _, w, h, spp, depth, _ = REFERENCES[name]
    return ROOT / "reference" / f"{name}_{w}x{h}_{spp}spp_depth{depth}.exr"


def _generated_triangles(obj: Path) -> int | None:
    try:
        with open(obj, encoding="utf-8") as f:
            m = re.search(r"(\d+) triangles", f.readline())
    except OSError:
        return None
    return int(m.group(1)) if m else None


def scene_path(scene_file: str, out_dir: Path | None = None) -> Path:
    """The scene file ``scene_file`` (a REFERENCES path), generating it first if it is
    a generated scene that is missing or was generated at another size.

    With ``out_dir``, a generated scene missing from scenes/ is looked for, or else
    written, in ``out_dir`` instead (tests use a temporary folder; scenes/ is left
    alone)."""
    path = ROOT / scene_file
    if scene_file not in GENERATED:
        return path
    script, triangles = GENERATED[scene_file]

    def ready(p: Path) -> bool:
        return p.exists() and _generated_triangles(p.with_suffix(".obj")) == triangles

    if ready(path):
        return path
    if out_dir is not None:
        path = Path(out_dir) / path.name
        if ready(path):
            return path
    import importlib.util

    spec = importlib.util.spec_from_file_location(Path(script).stem, ROOT / script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    t0 = time.perf_counter()
    n = mod.main(path.parent)  # default size
    if n != triangles:
        raise RuntimeError(f"{script} wrote {n} triangles, the reference is for {triangles}; "
                           "update GENERATED and regenerate the reference")
    print(f"{path.parent}: generated ({n} triangles, {time.perf_counter() - t0:.1f} s)",
          file=sys.stderr)
    return path


def variance_path(name: str) -> Path:
    """Per-pixel variance of the reference's mean (float32 EXR), for references
    rendered in batches (:data:`BATCHES`); absent for the others."""
    p = reference_path(name)
    return p.with_name(p.stem + "_var.exr")


def render_reference(name: str, seed: int = 12345) -> Path:
    """Render ``name``; with ``BATCHES[name] = B > 1`` as B independent renders of
    spp / B samples (seeds ``seed + k``) whose mean is the reference and whose
    spread, ``var(ddof=1) / B`` per pixel and channel, is written to
    :func:`variance_path`."""
    import mitsuba as mi
    import numpy as np

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.imageio import write_image
    from drpt.scene import load_scene

    scene_file, w, h, spp, depth, mode = REFERENCES[name]
    batches = BATCHES.get(name, 1)
    per = spp // batches
    assert per * batches == spp, (name, spp, batches)
    scene = load_scene(scene_path(scene_file))
    ms = mi.load_dict(to_mitsuba_dict(scene, w, h, per, max_depth=depth, seed=seed, bsdf=mode))
    t0 = time.perf_counter()
    runs = np.stack([np.asarray(mi.render(ms, spp=per, seed=seed + k), np.float64)
                     for k in range(batches)])
    out = reference_path(name)
    write_image(out, runs.mean(0).astype(np.float32))
    if batches > 1:
        write_image(variance_path(name), (runs.var(0, ddof=1) / batches).astype(np.float32))
    print(f"{out.relative_to(ROOT)}: {w}x{h}, {spp} spp in {batches} batch(es), "
          f"{time.perf_counter() - t0:.1f} s")
    return out


if __name__ == "__main__":
    for name in sys.argv[1:] or REFERENCES:
        render_reference(name)
