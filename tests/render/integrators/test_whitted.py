"""The Whitted integrator (drpt/render/integrators/whitted.py).

Mitsuba has no Whitted integrator; its path tracer agrees with Whitted only
where no light path with a diffuse bounce before the last vertex carries
light (see the module docstring). These tests use such scenes.
"""

import numpy as np
import pytest

from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import assert_agree, render_both

SCENE = """
PerspectiveCamera {{ center 0 1.2 6  direction 0 -0.2 -1  up 0 1 0  angle 35 }}
Background {{ color 0 0 0  ambientLight {ambient} }}
Lights {{ numLights 1  PointLight {{ position 3 5 4  color 40 40 40 }} }}
Materials {{ numMaterials 2
    PhongMaterial {{ diffuseColor 0.8 0.5 0.3 }}
    PhongMaterial {{ diffuseColor 0 0 0  reflectiveColor 0.9 0.9 0.9 }}
}}
Group {{
    numObjects {n}
    MaterialIndex 0
    Sphere {{ center -0.8 1 0 radius 1 }}
    {mirror}
}}
"""


def load(tmp_path, ambient="0 0 0", mirror=True):
    p = tmp_path / "w.txt"
    m = "MaterialIndex 1\n    Sphere { center 1.3 0.8 -0.5 radius 0.8 }" if mirror else ""
    p.write_text(SCENE.format(ambient=ambient, n=2 if mirror else 1, mirror=m))
    return load_scene(p)


def render(scene, integrator, depth, spp=64, W=48, H=32, seed=0):
    return Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, progress=False,
                                         integrator=integrator,
                                         path=PathOptions(max_depth=depth))).render()


def test_direct_light_equals_path_tracer_at_depth_2(tmp_path):
    # Depth 2 = direct light only: Whitted and the path tracer estimate the
    # same integral (a point light: exactly the same value per pixel).
    s = load(tmp_path, mirror=False)
    w = render(s, "whitted", 2, spp=4)
    p = render(s, "path", 2, spp=4)
    np.testing.assert_allclose(w.image, p.image, rtol=1e-4, atol=1e-6)


def test_ambient_term_adds_ambient_times_kd(tmp_path):
    a = render(load(tmp_path, ambient="0 0 0", mirror=False), "whitted", 4, spp=4)
    b = render(load(tmp_path, ambient="0.1 0.2 0.3", mirror=False), "whitted", 4, spp=4)
    diff = b.image - a.image
    expect = np.array([0.1 * 0.8, 0.2 * 0.5, 0.3 * 0.3])
    coverage = diff / expect  # fraction of each pixel's samples that hit the sphere
    assert np.all(coverage > -1e-4) and np.all(coverage < 1 + 1e-4)
    assert np.allclose(coverage[..., 0], coverage[..., 1], atol=1e-4)
    assert (coverage[..., 0] > 1 - 1e-4).mean() > 0.1  # pixels fully on the sphere


@pytest.mark.mitsuba
def test_mirror_scene_matches_mitsuba_path_at_depth_3(tmp_path):
    # Point light, one convex diffuse sphere, one mirror sphere, black
    # background: Mitsuba's paths of up to 3 segments are exactly Whitted's
    # (camera -> diffuse -> light, camera -> mirror -> diffuse -> light).
    s = load(tmp_path, mirror=True)
    w = render(s, "whitted", 3, spp=128)
    _, ref, ref_var = render_both(s, 48, 32, 128, max_depth=3)
    assert w.image.mean() > 0.01
    assert_agree(w, ref, ref_var)


def test_mirror_reflection_is_seen(tmp_path):
    # With the mirror, Whitted at depth 3 sees the diffuse sphere in it:
    # more light than at depth 2 (where the mirror shows only black).
    s = load(tmp_path, mirror=True)
    d2 = render(s, "whitted", 2, spp=16).image.sum()
    d3 = render(s, "whitted", 3, spp=16).image.sum()
    assert d3 > d2 * 1.01
