"""A ``mask`` over a diffuse rectangle, lit by a point light with nothing
behind it: drpt's image over Mitsuba's, per opacity (not a test).

Mitsuba's ``path`` integrator keeps a path's radiance only once one of its vertices has
sampled a non-null lobe or hit an emitter (``valid_ray``, where the scene has no
environment); a camera ray whose vertex samples the mask's pass-through (probability
``1 - a``) and then leaves the scene loses the direct light it gathered there, so Mitsuba's
image is ``a^2`` times the opaque one where drpt's is ``a`` times: the ratio drpt / Mitsuba
reads ``1 / a`` (docs/performance.md, "Masks: Mitsuba's `valid_ray`").

The scene is ``tests/render/integrators/test_path.py``'s (``max_depth`` 2, a box filter) at
``--size``; each renderer renders ``--rounds`` images of ``--spp`` samples (seeds 0, 1, ...)
per opacity, and the ratio is of the images' sums over all rounds. An ``--opacity`` entry is
a constant or an image file, a ``bitmap`` texture (``--filter-type``, ``--raw``): the corpus's
leaf mask is ``../shared/corpus/mitsuba-data/common/textures/leaf_mask.png``.

Run: PYTHONPATH=. .venv/bin/python benchmarks/mask_opacity_vs_mitsuba.py [--opacity 1,0.5,0.25,FILE]
[--filter-type bilinear|nearest] [--raw] [--size 128] [--spp 256] [--rounds 8]
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

SCENE = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0, 0, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="1" y="1" z="3"/><rgb name="intensity" value="10"/></emitter>
  <shape type="rectangle">
    <bsdf type="mask">{opacity}
      <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.7"/></bsdf></bsdf>
  </shape>
</scene>"""


def opacity_xml(entry: str, filter_type: str, raw: bool) -> str:
    """The mask's ``opacity``: a float, or a ``bitmap`` of the file ``entry``."""
    try:
        return f'<float name="opacity" value="{float(entry)}"/>'
    except ValueError:
        return (f'<texture name="opacity" type="bitmap"><string name="filename" value="{Path(entry).resolve()}"/>'
                f'<string name="filter_type" value="{filter_type}"/><boolean name="raw" value="{str(raw).lower()}"/>'
                '</texture>')


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--opacity", default="1,0.5,0.25", help="comma-separated opacities or image files")
    ap.add_argument("--filter-type", default="bilinear", choices=("bilinear", "nearest"))
    ap.add_argument("--raw", action="store_true", help="the bitmaps' values without sRGB decoding")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--rounds", type=int, default=8)
    a = ap.parse_args()

    import mitsuba as mi  # after drpt's backend, as the other Mitsuba benchmarks

    from drpt import llvm_tuning
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    ensure()
    set_mitsuba_variant()
    print(f"{a.size}x{a.size}, {a.rounds} x {a.spp} spp per renderer and opacity")
    with tempfile.TemporaryDirectory() as tmp:
        for entry in a.opacity.split(","):
            path = Path(tmp) / "mask.xml"
            path.write_text(SCENE.format(opacity=opacity_xml(entry, a.filter_type, a.raw), size=a.size, spp=a.spp))
            opt, scene = with_scene_settings(RenderOptions(progress=False), load_scene(path))
            renderer = Renderer(scene, opt)
            with llvm_tuning.dr_default():
                ms = mi.load_file(str(path))
            ours = theirs = 0.0
            for k in range(a.rounds):
                ours += float(np.sum(renderer.derive(replace(renderer.opt, seed=k))
                                     .render().image, dtype=np.float64))
                with llvm_tuning.dr_default():
                    theirs += float(np.sum(np.asarray(mi.render(ms, spp=a.spp, seed=k), np.float64)[..., :3]))
            try:
                note = f" (1 / opacity {1.0 / float(entry):.4f})"
            except ValueError:
                note = f" ({a.filter_type}{', raw' if a.raw else ''})"
            print(f"  opacity {entry}: drpt / Mitsuba {ours / theirs:.4f}{note}")


if __name__ == "__main__":
    main()
