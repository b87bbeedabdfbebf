"""Point and directional lights (drpt/render/lights/delta.py), against Mitsuba."""

import numpy as np
import pytest

from drpt.scene import load_scene
from drpt.testing import assert_agree, render_both

SCENE = """
PerspectiveCamera {{ center 0 1.5 5  direction 0 -0.3 -1  up 0 1 0  angle 40 }}
Lights {{
    numLights {n}
    {lights}
}}
Materials {{ numMaterials 2
    Material {{ diffuseColor 0.8 0.8 0.8 }}
    Material {{ diffuseColor 0.9 0.3 0.2 }}
}}
Group {{
    numObjects 2
    MaterialIndex 0
    Plane {{ normal 0 1 0 offset 0 }}
    MaterialIndex 1
    Sphere {{ center 0 1 0 radius 1 }}
}}
"""


def scene(tmp_path, *lights):
    p = tmp_path / "lights.txt"
    p.write_text(SCENE.format(n=len(lights), lights="\n    ".join(lights)))
    return load_scene(p)


@pytest.mark.mitsuba
def test_point_light_matches_mitsuba(tmp_path):
    s = scene(tmp_path, "PointLight { position 2 4 2  color 20 20 20 }")
    r, ref, ref_var = render_both(s, 48, 32, 64)
    assert r.image.mean() > 0.01
    assert_agree(r, ref, ref_var)


@pytest.mark.mitsuba
def test_directional_and_scaled_point_light_match_mitsuba(tmp_path):
    s = scene(tmp_path, "DirectionalLight { direction -1 -2 -1  color 1.5 1.4 1.2 }",
              "PointLight { position -2 3 1  color 10 10 10  attenuation 0 0 2 }")
    r, ref, ref_var = render_both(s, 48, 32, 64)
    assert_agree(r, ref, ref_var)


def test_point_light_falloff_follows_attenuation(tmp_path):
    # Direct light only: doubling q halves the image exactly (same samples).
    a = scene(tmp_path, "PointLight { position 2 4 2  color 20 20 20  attenuation 0 0 1 }")
    b = scene(tmp_path, "PointLight { position 2 4 2  color 20 20 20  attenuation 0 0 2 }")
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    opt = dict(width=16, height=16, spp=4, progress=False, path=PathOptions(max_depth=2))
    ia = Renderer(a, RenderOptions(**opt)).render().image
    ib = Renderer(b, RenderOptions(**opt)).render().image
    np.testing.assert_allclose(ib, ia / 2, rtol=1e-5, atol=1e-7)
