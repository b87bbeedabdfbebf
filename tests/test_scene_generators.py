"""The procedural scene generators (drpt.tools.scenegen.diningroom and .showcase):
they write loadable scenes with the promised content, the dining room's
tessellation follows ``--triangles`` (and reaches 500k by default, counted in
memory without writing it), and every scene renders finite, non-black pixels
at a tiny size with Cook-Torrance."""

from __future__ import annotations

import numpy as np
import pytest

from drpt.imageio import read_image
from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.shading import interpret


@pytest.fixture(scope="module")
def diningroom():
    from drpt.tools.scenegen import diningroom

    return diningroom


@pytest.fixture(scope="module")
def showcase():
    from drpt.tools.scenegen import showcase

    return showcase


def _tiny_render(scene) -> np.ndarray:
    opts = RenderOptions(width=16, height=12, spp=2, bsdf="cook-torrance", progress=False)
    img = Renderer(scene, opts).render().image
    assert img.shape == (12, 16, 3)
    assert np.isfinite(img).all()
    assert img.mean() > 1e-3
    return img


def _materials(scene) -> dict:
    used = set(np.unique(scene.triangles.material).tolist())
    return {m.name: m for i, m in enumerate(scene.materials) if i in used}


def test_diningroom_triangle_counts_scale(diningroom):
    counts = [diningroom.triangle_count(n) for n in (20_000, 80_000)]
    for n, c in zip((20_000, 80_000), counts):
        assert n <= c <= 1.1 * n
    assert diningroom.DEFAULT_TRIANGLES >= 500_000
    assert diningroom.triangle_count() >= 500_000  # built in memory, not written


@pytest.mark.slow
def test_diningroom_scene(diningroom, tmp_path):
    n = diningroom.main(tmp_path, triangles=20_000)
    assert 20_000 <= n <= 22_000
    scene = load_scene(tmp_path / "diningroom.txt")
    assert len(scene.triangles) == n
    mats = _materials(scene)
    glass = [m for m in mats.values() if m.dissolve < 1]
    assert {m.name for m in glass} >= {"table_glass", "wine_glass"}
    assert all(m.ior == 1.5 and interpret(m, "cook-torrance").kind == "dielectric" for m in glass)
    for mode, kind in (("cook-torrance", "cook_torrance"), ("phong", "phong")):
        assert interpret(mats["vase_brass"], mode).leaves()[0].kind == kind
    assert mats["vase_brass"].metalness == 1 and mats["brushed_steel"].metalness == 1
    lights = [m for m in mats.values() if m.is_emissive]
    assert [m.name for m in lights] == ["ceiling_light"]
    for m in mats.values():  # both --bsdf phong and cook-torrance have their parameters
        assert m.roughness is not None and m.metalness is not None, m.name
    # the lights face down (one-sided emitters): geometric normals point to -y
    tri = scene.triangles
    li = tri.positions[tri.material == scene.materials.index(lights[0])]
    nrm = np.cross(li[:, 1] - li[:, 0], li[:, 2] - li[:, 0])
    assert (nrm[:, 1] < 0).all() and np.allclose(nrm[:, [0, 2]], 0)
    # the floor is textured, with uvs, and the texture loads
    floor = mats["floor_wood"]
    assert floor.map_kd is not None and floor.map_kd.is_file()
    tex = read_image(floor.map_kd)
    assert tex.shape[2] == 3 and tex.std() > 0.01
    assert tri.uvs is not None
    _tiny_render(scene)


@pytest.mark.slow
def test_showcase_scenes(showcase, tmp_path):
    n = showcase.main(tmp_path)
    assert (tmp_path / "showcase.obj").stat().st_size < 2_200_000
    for which in ("day", "dusk"):
        scene = load_scene(tmp_path / f"showcase_{which}.txt")
        assert len(scene.triangles) == n
        assert len(scene.lights) == 1 and scene.lights[0].path.name == f"sky_{which}.exr"
        sky = read_image(scene.lights[0].path)
        assert sky.shape == (256, 512, 3) and np.isfinite(sky).all() and sky.min() >= 0
        lum = sky @ [0.2126, 0.7152, 0.0722]
        upper = lum[: sky.shape[0] // 2]
        assert 1e4 <= lum.max() / np.median(upper) <= 1e5  # a small, very bright sun
        # the sun sits where make_sky puts it (texel of its direction is the brightest)
        d = showcase.sun_direction(which)
        u = np.arctan2(d[0], -d[2]) / (2 * np.pi) % 1.0
        v = np.arccos(d[1]) / np.pi
        r, c = np.unravel_index(np.argmax(lum), lum.shape)
        assert abs(r - v * 256) <= 2 and min(abs(c - u * 512), 512 - abs(c - u * 512)) <= 2
        mats = _materials(scene)
        assert interpret(mats["car_glass"], "cook-torrance").kind == "dielectric"
        assert interpret(mats["chrome"], "cook-torrance").metalness == 1
        assert not any(m.is_emissive for m in mats.values())
        for name in ("grille", "plate"):
            assert read_image(mats[name].map_kd).std() > 0.01
        _tiny_render(scene)
