"""'Model only what a scene requires': code for features a scene lacks is
never traced. Each test replaces a feature's kernel function with one that
raises, renders a scene without the feature (must work), then one with it
(must hit the trap: the positive control that the trap is armed)."""

import pytest

from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


class Traced(Exception):
    pass


def trap(*args, **kwargs):
    raise Traced


def assert_traced(fn, *args, **kwargs):
    """``fn`` must fail because a trap ran (Dr.Jit wraps exceptions raised
    while tracing a loop, so look along the chain of causes)."""
    try:
        fn(*args, **kwargs)
    except Exception as e:  # noqa: BLE001 - we inspect the chain below
        while e is not None:
            if isinstance(e, Traced):
                return
            e = e.__cause__ or e.__context__
    pytest.fail("the trapped feature was not traced")


def render(path, bsdf="phong", accel="auto"):
    Renderer(load_scene(path), RenderOptions(width=4, height=4, spp=1, bsdf=bsdf, accel=accel,
                                             progress=False)).render()


def test_diffuse_scene_traces_no_ggx_or_phong(monkeypatch, cornell, scenes_dir):
    from drpt.render.bsdf import cook_torrance, microfacet, phong

    for mod, name in [(cook_torrance, "eval"), (cook_torrance, "sample"), (microfacet.Distribution, "D"),
                      (phong, "eval"), (phong, "sample")]:
        monkeypatch.setattr(mod, name, trap)
    render(cornell)  # Cornell box: diffuse only
    assert_traced(render, (scenes_dir / "newscene" / "newscene.txt"), bsdf="cook-torrance")


def test_untextured_scene_traces_no_texture_lookup(monkeypatch, tmp_path, cornell):
    import numpy as np

    from drpt.imageio import write_image
    from drpt.render import texture

    monkeypatch.setattr(texture.TextureSet, "lookup", trap)
    render(cornell)
    write_image(tmp_path / "t.png", np.full((4, 4, 3), 0.5, np.float32))
    (tmp_path / "q.mtl").write_text("newmtl t\nKd 1 1 1\nmap_Kd t.png\nnewmtl l\nKe 5 5 5\n")
    (tmp_path / "q.obj").write_text("mtllib q.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl t\n"
                                    "f 1/1 2/2 3/3 4/4\n")
    (tmp_path / "s.txt").write_text(
        "PerspectiveCamera { center 0 0 3 direction 0 0 -1 up 0 1 0 angle 40 }\n"
        "Lights { numLights 1 PointLight { position 0 0 2 color 1 1 1 } }\n"
        "Group { numObjects 1 TriangleMesh { obj_file q.obj } }\n")
    assert_traced(render, tmp_path / "s.txt")


def test_sphere_only_scene_traces_no_triangle_test(monkeypatch, tmp_path, cornell):
    from drpt.accel import bvh4, inline, primitives

    monkeypatch.setattr(primitives, "test_triangle", trap)
    monkeypatch.setattr(bvh4, "test_triangle4", trap)
    monkeypatch.setattr(inline, "watertight_permuted", trap)
    (tmp_path / "s.txt").write_text(
        "PerspectiveCamera { center 0 0 3 direction 0 0 -1 up 0 1 0 angle 40 }\n"
        "Lights { numLights 1 PointLight { position 0 2 2 color 5 5 5 } }\n"
        "Group { numObjects 1 Sphere { center 0 0 0 radius 1 } }\n")
    for accel in ("auto", "bvh"):  # auto: inline here
        render(tmp_path / "s.txt", accel=accel)
        assert_traced(render, cornell, accel=accel)


def test_scene_without_emissive_spheres_traces_no_sphere_light_sampling(monkeypatch, tmp_path, cornell):
    from drpt.render.lights import area

    monkeypatch.setattr(area.AreaLights, "_sphere_point", trap)
    monkeypatch.setattr(area.AreaLights, "pdf_sphere", trap)
    render(cornell)  # a triangle light and no sphere
    (tmp_path / "s.txt").write_text(
        "PerspectiveCamera { center 0 0 3 direction 0 0 -1 up 0 1 0 angle 40 }\n"
        "Materials { numMaterials 2 Material { Kd 0.5 0.5 0.5 } Material { Kd 0 0 0 Ke 5 5 5 } }\n"
        "Group { numObjects 4 MaterialIndex 0 Sphere { center 0 0 0 radius 1 }\n"
        "Triangle { vertex0 -3 -1 -3 vertex1 3 -1 -3 vertex2 0 -1 3 }\n"
        "MaterialIndex 1 Triangle { vertex0 -1 3 -1 vertex1 0 3 1 vertex2 1 3 -1 }\n"
        "MaterialIndex 0 Sphere { center 2 0 0 radius 0.3 } }\n")
    render(tmp_path / "s.txt")  # spheres, none emissive
    (tmp_path / "s.txt").write_text((tmp_path / "s.txt").read_text().replace(
        "MaterialIndex 0 Sphere { center 2", "MaterialIndex 1 Sphere { center 2"))
    assert_traced(render, tmp_path / "s.txt")
