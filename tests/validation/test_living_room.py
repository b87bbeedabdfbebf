"""The living room (:mod:`drpt.tools.scenegen.living_room`): the generator writes the scene its
docstring promises (the materials, textures, alpha cut-outs and emitters drpt reads from the XML),
and drpt renders it like Mitsuba on the same file.

Agreement: 48 x 48, drpt at 64 spp against Mitsuba at 256 spp (8 batches, the variance of their
mean), every 8 x 8 block's z below 4.5 (:func:`drpt.testing.assert_agree`) and the image mean's z
below 4 per channel (:func:`support.xml.mean_z`). Negative control: drpt renders a copy whose
ceiling panel is 10% brighter against the same Mitsuba image; its image mean's z must exceed 6
in every channel (the panel lights much of the room; the copy measures z ~ 15, the original
below 1).
"""

from __future__ import annotations

import numpy as np
import pytest

from drpt.imageio import read_image
from drpt.scene import load_scene
from drpt.tools.scenegen import living_room


def _kinds(spec) -> set[str]:
    return {spec.kind} | {k for c in spec.children for k in _kinds(c)}


def test_generator_writes_the_promised_scene(tmp_path):
    files = living_room.main(tmp_path)
    assert [f.name for f in files] == list(living_room.FILES) and all(f.is_file() for f in files)
    scene = load_scene(tmp_path / "living_room.xml")
    assert (scene.settings.width, scene.settings.height, scene.settings.spp) == (128, 128, 64)
    kinds = set().union(*(_kinds(m.bsdf) for m in scene.materials if m.bsdf is not None))
    assert {"roughplastic", "conductor", "roughconductor", "mask", "twosided", "diffuse"} <= kinds
    params = {m.name: m.bsdf for m in scene.materials if m.bsdf is not None}
    leaf = next(b for b in params.values() if b.kind == "mask")
    assert type(leaf.params["opacity"]).__name__ == "Texture" and leaf.params["opacity"].raw
    floor = params["floor"].children[0].params["kd"]
    rug = params["rug"].children[0].params["kd"]
    assert type(floor).__name__ == "Texture" and type(rug).__name__ == "Checkerboard"
    emissive = sorted(max(m.emission) for m in scene.materials if max(m.emission) > 0)
    assert emissive == [6.0, 17.0, 40.0]  # panel, sconce, lamp: three powers
    assert len(scene.lights) == 1 and scene.lights[0].path.name == "sky.exr"
    sky = read_image(tmp_path / "sky.exr")
    assert np.isfinite(sky).all() and sky.min() > 0 and sky.max() > 50 * np.median(sky)
    alpha = read_image(tmp_path / "leaf.png", linear=False)
    assert set(np.unique(alpha).tolist()) == {0.0, 1.0} and 0.2 < alpha.mean() < 0.6


@pytest.mark.slow
@pytest.mark.mitsuba
def test_renders_like_mitsuba(tmp_path):
    from dataclasses import replace

    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.testing import assert_agree
    from support.xml import mean_z, render_xml_both

    living_room.main(tmp_path)
    path = tmp_path / "living_room.xml"
    defines = {"w": "48", "h": "48"}
    scene = load_scene(path, defines=defines)
    r, ref, var = render_xml_both(scene, path, 64, defines=defines, ref_spp=256)
    assert ref.mean() > 0.05
    assert_agree(r, ref, var, zmax=4.5)
    assert np.abs(mean_z(r, ref, var)).max() < 4.0

    text = path.read_text()
    panel = '<rgb name="radiance" value="6, 5.7, 5.2"/>'
    assert text.count(panel) == 1
    bright = tmp_path / "bright.xml"
    bright.write_text(text.replace(panel, '<rgb name="radiance" value="6.6, 6.27, 5.72"/>'))
    scene = load_scene(bright, defines=defines)
    opts = replace(with_scene_settings(RenderOptions(progress=False, seed=3), scene)[0], spp=64)
    bad = Renderer(scene, opts).render()
    z = mean_z(bad, ref, var)
    print(f"living room: image mean z {mean_z(r, ref, var)}, with the panel 10% brighter {z}")
    assert (z > 6.0).all()
