"""Regenerates the Mitsuba 3 reference images in reference/.

Each bundled scene is exported with drpt's Mitsuba exporter and rendered by
Mitsuba's ``path`` integrator (llvm_ad_rgb) at high spp; the EXR holds linear
float32 RGB. Run from the repository root:

    .venv/bin/python reference/make_references.py            # all
    .venv/bin/python reference/make_references.py cornellbox # one

The table below is the single source of truth for what each reference is;
tests read it through :func:`reference_path`.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# name: (scene file, width, height, spp, max_depth, material mode)
REFERENCES = {
    "cornellbox": ("scenes/cornellbox/cornellbox.txt", 128, 128, 8192, -1, "phong"),
    "newscene": ("scenes/newscene/newscene.txt", 96, 96, 4096, -1, "cook-torrance"),
    "newscene_hard": ("scenes/newscene/newscene_hard.txt", 96, 96, 4096, -1, "cook-torrance"),
}


def reference_path(name: str) -> Path:
    _, w, h, spp, depth, _ = REFERENCES[name]
    return ROOT / "reference" / f"{name}_{w}x{h}_{spp}spp_depth{depth}.exr"


def render_reference(name: str, seed: int = 12345) -> Path:
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    from drpt.export.mitsuba import to_mitsuba_dict
    from drpt.imageio import write_image
    from drpt.scene import load_scene

    scene_file, w, h, spp, depth, mode = REFERENCES[name]
    scene = load_scene(ROOT / scene_file)
    ms = mi.load_dict(to_mitsuba_dict(scene, w, h, spp, max_depth=depth, seed=seed, bsdf=mode))
    t0 = time.perf_counter()
    img = mi.render(ms, spp=spp, seed=seed)
    out = reference_path(name)
    import numpy as np

    write_image(out, np.asarray(img, dtype=np.float32))
    print(f"{out.relative_to(ROOT)}: {w}x{h}, {spp} spp, {time.perf_counter() - t0:.1f} s")
    return out


if __name__ == "__main__":
    for name in sys.argv[1:] or REFERENCES:
        render_reference(name)
