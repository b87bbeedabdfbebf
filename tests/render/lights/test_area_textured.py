"""Area emitters with a bitmap ``radiance`` (drpt.scene.model.Material.emission_texture,
drpt.render.material.MaterialTable.textured_emission, drpt.render.lights.area): the reader keeps
the texture and its mean radiance; a scene of two textured emitters, seen directly and lighting a
floor, renders like Mitsuba on the same file (8x8 block z-test), and the negative control (each
emitter at its mean radiance) fails it."""

from __future__ import annotations

import numpy as np
import pytest

from drpt.scene import load_scene


def test_reader_keeps_the_texture():
    from support.xml import XML

    s = load_scene(XML / "area_textured.xml")
    lights = [m for m in s.materials if m.emission_texture is not None]
    assert len(lights) == 2
    assert lights[1].emission_texture.filter_type == "nearest"
    assert all(0.0 < min(m.emission) and m.bsdf.params["kd"] == (0.0, 0.0, 0.0) for m in lights)


@pytest.mark.mitsuba
def test_renders_like_mitsuba():
    from dataclasses import replace

    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.testing import assert_agree, block_z
    from support.xml import XML, render_xml_both

    path = XML / "area_textured.xml"
    scene = load_scene(path)
    r, ref, var = render_xml_both(scene, path, 128)
    assert ref.mean() > 0.05
    assert_agree(r, ref, var, zmax=4.5)
    for m in scene.materials:  # negative control: the emitters at their mean radiance
        m.emission_texture = None
    opts = replace(with_scene_settings(RenderOptions(progress=False, seed=3), scene)[0], spp=128)
    bad = Renderer(scene, opts).render()
    assert np.abs(block_z(bad.image, bad.variance, ref, var)).max() > 6.0


@pytest.mark.mitsuba
def test_export_round_trip(tmp_path):
    """The exporter writes the textured radiance back: drpt reads the same textures from the
    exported file, and Mitsuba renders it as it renders the original (image means within 3%)."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    from drpt.export.mitsuba import write_xml
    from support.xml import XML

    s = load_scene(XML / "area_textured.xml")
    out = write_xml(s, tmp_path / "x.xml", 32, 24, 4, max_depth=3)
    back = load_scene(out)
    def textures(scene):
        return sorted(repr(m.emission_texture) for m in scene.materials if m.emission_texture is not None)

    assert len(textures(s)) == 2 and textures(back) == textures(s)
    mi.set_variant(mitsuba_variant())
    a, b = (np.array(mi.render(mi.load_file(str(p)), spp=64, seed=1)) for p in (XML / "area_textured.xml", out))
    assert a.mean() > 0.05 and abs(b.mean() / a.mean() - 1.0) < 0.03
