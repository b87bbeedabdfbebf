"""drpt.export.mitsuba: the Scene as a Mitsuba 3 scene (dict and XML).

Each test renders tiny images (64x48, a few spp) with Mitsuba's
``llvm_ad_rgb`` variant; together they check the conventions the module
documents: camera mapping (perspective, orthographic, rotated), one-sided
area emitters (and which normal decides the side), uv orientation, plane
orientation, directional light direction, and dict == XML.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import DrptError
from drpt.scene.model import (
    Background,
    DirectionalLight,
    Material,
    OrthographicCamera,
    PerspectiveCamera,
    Planes,
    PointLight,
    Scene,
    Skybox,
    Spheres,
    Triangles,
)

mi = pytest.importorskip("mitsuba")
pytestmark = pytest.mark.mitsuba

from drpt.export.mitsuba import look_at_matrix, to_mitsuba_dict, write_xml  # noqa: E402
from support import SCENES  # noqa: E402

W, H = 64, 48


@pytest.fixture(scope="module", autouse=True)
def variant():
    try:
        from drpt.backend import mitsuba_variant
        mi.set_variant(mitsuba_variant())
    except Exception as e:  # pragma: no cover - no LLVM
        pytest.skip(f"Mitsuba llvm_ad_rgb unavailable: {e}")


# ------------------------------------------------------------ helpers
def quad(c, a, b) -> np.ndarray:
    """Two triangles c +- a +- b, counter-clockwise seen from cross(a, b)."""
    c, a, b = (np.asarray(v, float) for v in (c, a, b))
    p00, p10, p11, p01 = c - a - b, c + a - b, c + a + b, c - a + b
    return np.array([[p00, p10, p11], [p00, p11, p01]])


def quad_uvs() -> np.ndarray:
    """OBJ-convention uvs for quad(): (0,0) at c-a-b, (1,1) at c+a+b."""
    return np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float)


def make_scene(camera, materials, triangles=None, spheres=None, planes=None,
               lights=(), background=(0.0, 0.0, 0.0)) -> Scene:
    return Scene(
        path=Path("test.txt"), camera=camera, materials=list(materials),
        triangles=triangles if triangles is not None else Triangles.empty(),
        spheres=spheres if spheres is not None else Spheres.empty(),
        planes=planes if planes is not None else Planes.empty(),
        lights=list(lights), background=Background(tuple(background)),
    )


def render(d_or_scene, spp=None) -> np.ndarray:
    s = mi.load_dict(d_or_scene) if isinstance(d_or_scene, dict) else d_or_scene
    return np.array(mi.render(s, spp=spp) if spp else mi.render(s))


def render_scene(scene, spp=4, max_depth=-1, seed=0) -> np.ndarray:
    return render(to_mitsuba_dict(scene, W, H, spp, max_depth=max_depth, seed=seed))


def basis(cam):
    f = np.asarray(cam.direction, float)
    f /= np.linalg.norm(f)
    r = np.cross(f, cam.up)
    r /= np.linalg.norm(r)
    return f, r, np.cross(r, f)


def drpt_ray(cam, x, y):
    """drpt's documented camera mapping (pixel coords from the top-left)."""
    f, r, u = basis(cam)
    if isinstance(cam, PerspectiveCamera):
        half_h = math.tan(math.radians(cam.fov) / 2)
    else:
        half_h = cam.size / 2
    sx = (2 * x / W - 1) * half_h * W / H
    sy = (1 - 2 * y / H) * half_h
    c = np.asarray(cam.center, float)
    if isinstance(cam, PerspectiveCamera):
        d = f + sx * r + sy * u
        return c, d / np.linalg.norm(d)
    return c + sx * r + sy * u, f


def pixel_size_at(cam, dist):
    if isinstance(cam, PerspectiveCamera):
        return 2 * math.tan(math.radians(cam.fov) / 2) * dist / H
    return cam.size / H


# -------------------------------------------------------------- tests
def test_look_at_matches_mitsuba():
    o, t, up = [1, 2, 3], [-0.5, 0.2, 0.1], [0.3, 1, -0.2]
    ours = look_at_matrix(o, t, up)
    theirs = np.array(mi.ScalarTransform4f().look_at(origin=o, target=t, up=up).matrix)
    np.testing.assert_allclose(ours, theirs, atol=1e-6)


CAMERAS = {
    "perspective": PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 50.0),
    "perspective-rotated": PerspectiveCamera((1.0, 2.0, 3.0), (-0.4, -0.3, -1.0), (1.0, 0.4, 0.2), 35.0),
    "orthographic": OrthographicCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 3.0),
    "orthographic-rotated": OrthographicCamera((-1.0, 0.5, 2.0), (0.5, -0.2, -1.0), (-1.0, 1.0, 0.3), 2.5),
}


@pytest.mark.parametrize("name", list(CAMERAS))
def test_camera_equivalence(name):
    """Tiny emitters placed on drpt's rays through chosen pixel centers light
    exactly those pixels in Mitsuba (R, G, B: one per asymmetric position)."""
    cam = CAMERAS[name]
    targets = [(5, 7), (50, 11), (20, 40)]  # (x, y) from the top-left
    dist = 4.0
    centers, radii = [], []
    for x, y in targets:
        o, d = drpt_ray(cam, x + 0.5, y + 0.5)
        centers.append(o + dist * d)
        radii.append(0.3 * pixel_size_at(cam, dist))
    mats = [Material(f"e{c}", kd=(0, 0, 0), emission=tuple(100.0 * (np.arange(3) == c)))
            for c in range(3)]
    scene = make_scene(cam, mats, spheres=Spheres(np.array(centers), np.array(radii),
                                                  np.arange(3, dtype=np.int32)))
    img = render_scene(scene, spp=16)
    for c, (x, y) in enumerate(targets):
        ch = img[..., c]
        yy, xx = np.unravel_index(np.argmax(ch), ch.shape)
        assert (xx, yy) == (x, y), f"channel {c}: brightest pixel {(xx, yy)}, want {(x, y)}"
        assert ch[y, x] > 1.0
        ch = ch.copy()
        ch[y, x] = 0
        assert ch.max() == 0.0  # nothing leaks into neighbours


def _front_quad_scene(flip_winding=False, normals=None, max_depth=1):
    cam = PerspectiveCamera((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    pos = quad([0, 0, 0], [0.5, 0, 0], [0, 0.5, 0])  # front (+z) faces the camera
    if flip_winding:
        pos = pos[:, ::-1]
    tri = Triangles(pos, np.zeros(2, np.int32),
                    normals=None if normals is None else np.broadcast_to(np.asarray(normals, float), (2, 3, 3)).copy())
    mats = [Material("lamp", kd=(0, 0, 0), emission=(2.0, 3.0, 4.0))]
    return make_scene(cam, mats, triangles=tri)


def test_area_emitter_is_one_sided():
    front = render_scene(_front_quad_scene(), max_depth=1)
    np.testing.assert_allclose(front[H // 2, W // 2], [2, 3, 4], rtol=1e-6)
    back = render_scene(_front_quad_scene(flip_winding=True), max_depth=1)
    assert back.max() == 0.0
    # a sphere emits outward only: seen from inside it is black
    inside = _front_quad_scene()
    inside.triangles = Triangles.empty()
    inside.spheres = Spheres(np.array([[0.0, 0.0, 3.0]]), np.array([1.0]), np.zeros(1, np.int32))
    assert render_scene(inside, max_depth=1).max() == 0.0
    inside.camera = PerspectiveCamera((0.0, 0.0, 6.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    np.testing.assert_allclose(render_scene(inside, max_depth=1)[H // 2, W // 2], [2, 3, 4], rtol=1e-6)


def test_area_emitter_side_follows_shading_normal():
    """With vertex normals, Mitsuba emits toward the *shading* normal, even
    when it disagrees with the winding (geometric normal)."""
    # geometric front faces the camera, vertex normals point away: black
    img = render_scene(_front_quad_scene(normals=(0, 0, -1)), max_depth=1)
    assert img.max() == 0.0
    # geometric back faces the camera, vertex normals point to it: lit
    img = render_scene(_front_quad_scene(flip_winding=True, normals=(0, 0, 1)), max_depth=1)
    np.testing.assert_allclose(img[H // 2, W // 2], [2, 3, 4], rtol=1e-6)


def test_area_light_sampling_side_follows_shading_normal():
    """Next-event estimation uses the same side: a ceiling lamp whose winding
    faces up but whose vertex normals face down lights the floor below."""
    cam = PerspectiveCamera((0.0, 1.0, 4.0), (0.0, -0.3, -1.0), (0.0, 1.0, 0.0), 45.0)
    lamp = quad([0, 2, 0], [0, 0, 0.4], [0.4, 0, 0])  # cross(a, b) = +y: faces up
    floor = quad([0, 0, 0], [5, 0, 0], [0, 0, -5])
    for normals, lit in (((0, -1, 0), True), ((0, 1, 0), False)):
        nrm = np.zeros((4, 3, 3))
        nrm[:2] = normals
        nrm[2:] = (0, 1, 0)
        tri = Triangles(np.concatenate([lamp, floor]), np.array([0, 0, 1, 1], np.int32), normals=nrm)
        mats = [Material("lamp", kd=(0, 0, 0), emission=(5, 5, 5)), Material("floor", kd=(0.5, 0.5, 0.5))]
        img = render_scene(make_scene(cam, mats, triangles=tri), spp=4, max_depth=2)
        floor_px = img[H // 2 + 4, W // 2]
        assert (floor_px.max() > 0.05) == lit, (normals, floor_px)


def _texture(tmp_path) -> Path:
    from PIL import Image

    a = np.zeros((8, 8, 3), np.uint8)
    a[:4, :, 0] = 255  # top half red
    a[4:, :, 1] = 255  # bottom half green
    p = tmp_path / "tex.png"
    Image.fromarray(a).save(p)
    return p


def test_uv_orientation_matches_obj(tmp_path):
    """OBJ uv v=0 is the image's bottom row: a quad whose uv (0,0) is its
    bottom-left corner shows the texture upright, in dict and XML alike."""
    cam = PerspectiveCamera((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    tri = Triangles(quad([0, 0, 0], [0.6, 0, 0], [0, 0.6, 0]), np.zeros(2, np.int32),
                    uvs=quad_uvs())
    mats = [Material("tex", map_kd=_texture(tmp_path))]
    scene = make_scene(cam, mats, triangles=tri, background=(1, 1, 1))
    imgs = [render_scene(scene, spp=8, max_depth=2)]
    xml = write_xml(scene, tmp_path / "uv.xml", W, H, 8, max_depth=2)
    imgs.append(render(mi.load_file(str(xml))))
    for img in imgs:
        top, bottom = img[H // 2 - 6, W // 2], img[H // 2 + 6, W // 2]
        assert top[0] > 0.5 and top[1] < 0.05, top
        assert bottom[1] > 0.5 and bottom[0] < 0.05, bottom


def test_texture_without_uvs_is_kd_in_drpt_and_export(tmp_path):
    """A map_Kd in a scene without texture coordinates: one rule
    (drpt.materials.interpret.interpret_scene) drops the texture for both, so drpt and
    the exported scene both render Kd (green here, the texture is red), and
    both report the material."""
    from PIL import Image

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    red = tmp_path / "red.png"
    Image.fromarray(np.full((4, 4, 3), (255, 0, 0), np.uint8)).save(red)
    cam = PerspectiveCamera((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    tri = Triangles(quad([0, 0, 0], [0.6, 0, 0], [0, 0.6, 0]), np.zeros(2, np.int32))
    mats = [Material("tex", kd=(0.0, 0.8, 0.0), map_kd=red)]
    scene = make_scene(cam, mats, triangles=tri, lights=[PointLight((0, 0, 2), (4, 4, 4))])
    with pytest.warns(UserWarning, match="material 'tex': texture red.png needs texture"):
        mits = render_scene(scene, spp=4, max_depth=2)
    r = Renderer(scene, RenderOptions(width=W, height=H, spp=4, path=PathOptions(max_depth=2),
                                      progress=False))
    assert any("material 'tex'" in w and "red.png" in w for w in r.warnings)
    ours = r.render().image
    for img in (mits, ours):
        c = img[H // 2, W // 2]
        assert c[1] > 0.1 and c[0] < 1e-3 * c[1], c
    np.testing.assert_allclose(ours[H // 2 - 4:H // 2 + 4, W // 2 - 4:W // 2 + 4],
                               mits[H // 2 - 4:H // 2 + 4, W // 2 - 4:W // 2 + 4], rtol=0.02)


def test_plane_orientation_and_extent():
    """An emissive plane y = -1 with normal +y fills the lower half of the
    view toward the horizon; with normal -y (same plane) it is invisible."""
    cam = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 60.0)
    mats = [Material("glow", kd=(0, 0, 0), emission=(1, 1, 1))]
    up = make_scene(cam, mats, planes=Planes(np.array([[0, 1.0, 0]]), np.array([-1.0]),
                                             np.zeros(1, np.int32)))
    img = render_scene(up, max_depth=1)
    assert np.all(img[H // 2 + 1:] == 1.0)  # below the horizon, to the edges
    assert np.all(img[: H // 2 - 1] == 0.0)
    down = make_scene(cam, mats, planes=Planes(np.array([[0, -1.0, 0]]), np.array([1.0]),
                                               np.zeros(1, np.int32)))
    assert render_scene(down, max_depth=1).max() == 0.0


def test_directional_light_direction_is_travel_direction():
    """Light travelling along -x lights the +x side of a sphere."""
    cam = PerspectiveCamera((0.0, 0.0, 4.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    mats = [Material("white", kd=(0.8, 0.8, 0.8))]
    scene = make_scene(cam, mats, spheres=Spheres(np.zeros((1, 3)), np.ones(1), np.zeros(1, np.int32)),
                       lights=[DirectionalLight((-1.0, 0.0, 0.0), (1.0, 1.0, 1.0))])
    img = render_scene(scene, max_depth=2)
    right, left = img[H // 2, W // 2 + 8], img[H // 2, W // 2 - 8]
    assert right.mean() > 0.1 and left.max() == 0.0


def _mixed_scene(tmp_path) -> Scene:
    cam = PerspectiveCamera((0.0, 1.0, 4.0), (0.0, -0.2, -1.0), (0.0, 1.0, 0.0), 45.0)
    floor = quad([0, 0, 0], [2, 0, 0], [0, 0, -2])
    lamp = quad([0, 1.9, 0], [0.3, 0, 0], [0, 0, 0.3])
    pos = np.concatenate([floor, lamp])
    rng = np.random.default_rng(1)
    nrm = np.broadcast_to([0.0, 1.0, 0.0], (4, 3, 3)) + 0.1 * rng.standard_normal((4, 3, 3))
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    nrm[2:] = (0, -1, 0)
    uvs = np.concatenate([quad_uvs(), quad_uvs()]) * 2.0
    tri = Triangles(pos, np.array([0, 0, 1, 2], np.int32), normals=nrm, uvs=uvs)
    mats = [
        Material("white", kd=(0.7, 0.7, 0.7)),
        Material("lamp", kd=(0.0, 0.0, 0.0), emission=(10.0, 9.0, 8.0)),
        Material("tex", map_kd=_texture(tmp_path)),
        Material("red", kd=(0.8, 0.1, 0.1)),
    ]
    return make_scene(
        cam, mats, triangles=tri,
        spheres=Spheres(np.array([[0.5, 0.5, 0.0]]), np.array([0.4]), np.array([3], np.int32)),
        planes=Planes(np.array([[0.0, 0.0, 1.0]]), np.array([-2.0]), np.zeros(1, np.int32)),
        lights=[PointLight((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)),
                DirectionalLight((0.0, -1.0, 0.0), (0.2, 0.2, 0.2))],
        background=(0.1, 0.1, 0.1),
    )


def test_dict_loads_with_expected_settings(tmp_path):
    scene = _mixed_scene(tmp_path)
    d = to_mitsuba_dict(scene, W, H, 8, max_depth=7, rr_depth=3, seed=5)
    assert d["sensor"]["fov_axis"] == "y" and d["sensor"]["fov"] == 45.0
    assert d["sensor"]["film"]["rfilter"] == {"type": "box"}
    assert d["sensor"]["film"]["component_format"] == "float32"
    assert d["sensor"]["sampler"] == {"type": "independent", "sample_count": 8, "seed": 5}
    assert d["integrator"] == {"type": "path", "max_depth": 7, "rr_depth": 3, "hide_emitters": False}
    s = mi.load_dict(d)
    assert list(s.sensors()[0].film().size()) == [W, H]
    kinds = sorted(e.class_name() for e in s.emitters())
    assert kinds == ["AreaLight", "ConstantBackgroundEmitter", "DirectionalEmitter", "PointLight"]
    meshes = [sh for sh in s.shapes() if sh.id().startswith("mesh_")]
    assert sorted(m.face_count() for m in meshes) == [1, 1, 2]  # one mesh per material
    assert all(m.has_vertex_normals() and m.has_vertex_texcoords() for m in meshes)


@pytest.mark.parametrize("drpt_sampler, plugin", [("ldsampler", "ldsampler"), ("multijitter", "multijitter"),
                                                  ("zsobol", "independent")])
def test_export_names_the_sampler_drpt_draws_with(tmp_path, drpt_sampler, plugin):
    """The export names Mitsuba's plugin of drpt's resolved sampler (``independent`` for one
    Mitsuba lacks), in the dict and in the XML, and Mitsuba loads it as that plugin."""
    scene = _mixed_scene(tmp_path)
    d = to_mitsuba_dict(scene, W, H, 8, seed=5, sampler=drpt_sampler)
    assert d["sensor"]["sampler"] == {"type": plugin, "sample_count": 8, "seed": 5}
    names = {"ldsampler": "LowDiscrepancySampler", "multijitter": "MultijitterSampler",
             "independent": "IndependentSampler"}
    assert mi.load_dict(d).sensors()[0].sampler().class_name() == names[plugin]
    xml = write_xml(scene, tmp_path / "s.xml", W, H, 8, sampler=drpt_sampler)
    assert f'<sampler type="{plugin}">' in xml.read_text()


def test_xml_renders_same_as_dict(tmp_path):
    scene = _mixed_scene(tmp_path)
    a = render(to_mitsuba_dict(scene, W, H, 16, seed=3))
    xml = write_xml(scene, tmp_path / "out" / "scene.xml", W, H, 16, seed=3)
    text = xml.read_text()
    assert 'version="3.0.0"' in text
    plys = sorted((tmp_path / "out" / "scene_meshes").glob("*.ply"))
    assert [p.name for p in plys] == ["000_white.ply", "001_lamp.ply", "002_tex.ply"]
    # optimize=False: the default merges meshes sharing an identical BSDF
    # (the plane's rectangle included) and orders mesh emitters
    # nondeterministically -- same expectation, different random sequence.
    b = render(mi.load_file(str(xml), optimize=False))
    assert a.mean() > 0.05
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)


def test_xml_without_normals_uses_face_normals(tmp_path):
    cam = PerspectiveCamera((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    tri = Triangles(quad([0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]), np.zeros(2, np.int32))
    scene = make_scene(cam, [Material("w")], triangles=tri, background=(1, 1, 1))
    xml = write_xml(scene, tmp_path / "s.xml", W, H, 4)
    assert 'name="face_normals" value="true"' in xml.read_text()
    s = mi.load_file(str(xml))
    mesh = [sh for sh in s.shapes() if sh.is_mesh()][0]
    assert not mesh.has_vertex_normals() and mesh.face_count() == 2
    np.testing.assert_allclose(render(s), render_scene(scene), rtol=1e-4, atol=1e-5)


def test_point_light_attenuation_warns():
    cam = PerspectiveCamera((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    scene = make_scene(cam, [Material("w")], lights=[PointLight((0, 0, 1), (1, 1, 1), (1.0, 0.5, 0.0))])
    with pytest.warns(UserWarning, match="attenuation"):
        d = to_mitsuba_dict(scene, W, H, 1)
    mi.load_dict(d)
    scene.lights = [PointLight((0, 0, 1), (1, 1, 1))]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        to_mitsuba_dict(scene, W, H, 1)


def test_skybox_envmap_replaces_background(tmp_path):
    from drpt.imageio import write_image

    env = tmp_path / "env.exr"
    write_image(env, np.full((8, 16, 3), 0.5, np.float32))
    cam = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    scene = make_scene(cam, [Material("w")], lights=[Skybox(env)], background=(1, 0, 0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a clean map exports without warnings
        d = to_mitsuba_dict(scene, W, H, 1)
    assert "background" not in d
    img = render(d)
    np.testing.assert_allclose(img, 0.5, rtol=1e-3)


def test_background_constant_emitter():
    cam = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    scene = make_scene(cam, [Material("w")], background=(0.25, 0.5, 1.0))
    img = render_scene(scene, spp=1)
    np.testing.assert_allclose(img, np.broadcast_to([0.25, 0.5, 1.0], img.shape), rtol=1e-6)


def test_bad_inputs_raise_drpt_error(tmp_path):
    cam = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    with pytest.raises(DrptError, match="not found"):
        to_mitsuba_dict(make_scene(cam, [Material("t", map_kd=tmp_path / "no.png")]), W, H, 1)
    with pytest.raises(DrptError, match="not found"):
        write_xml(make_scene(cam, [Material("w")], lights=[Skybox(tmp_path / "no.hdr")]),
                  tmp_path / "s.xml", W, H, 1)
    cam = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0)
    with pytest.raises(DrptError, match="parallel"):
        to_mitsuba_dict(make_scene(cam, [Material("w")]), W, H, 1)
    cam = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 40.0)
    with pytest.raises(DrptError):
        to_mitsuba_dict(make_scene(cam, [Material("w")]), 0, H, 1)


def test_xml_matches_dict_with_several_emitters(tmp_path):
    """Emitter order (which decides light selection) is the document order
    in both outputs, so several emissive meshes still match exactly."""
    cam = PerspectiveCamera((0.0, 1.0, 4.0), (0.0, -0.3, -1.0), (0.0, 1.0, 0.0), 50.0)
    n = 4
    pos = np.concatenate([quad([i - 1.5, 1.5, 0], [0, 0, 0.3], [0.3, 0, 0]) for i in range(n)]
                         + [quad([0, 0, 0], [5, 0, 0], [0, 0, -5])])
    mat = np.array([i for i in range(n) for _ in range(2)] + [n, n], np.int32)
    mats = [Material(f"lamp{i}", kd=(0, 0, 0), emission=(1.0 + i, 2.0, 3.0 - 0.5 * i)) for i in range(n)]
    mats.append(Material("floor", kd=(0.6, 0.6, 0.6)))
    scene = make_scene(cam, mats, triangles=Triangles(pos, mat),
                       spheres=Spheres(np.array([[0.0, 0.5, -1.0]]), np.array([0.3]), np.array([0], np.int32)),
                       lights=[PointLight((0.0, 2.0, 1.0), (2.0, 2.0, 2.0))])
    a = render(to_mitsuba_dict(scene, W, H, 8, max_depth=3, seed=7))
    xml = write_xml(scene, tmp_path / "multi.xml", W, H, 8, max_depth=3, seed=7)
    b = render(mi.load_file(str(xml), optimize=False))
    assert a.mean() > 0.05
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)
    # The default (optimized) load draws other samples but converges to the same image.
    c = render(mi.load_file(str(xml)))
    assert abs(c.mean() - a.mean()) < 0.05 * a.mean()


# ------------------------------------------------------------ media
def test_media_export_as_homogeneous_media_with_volpath(tmp_path):
    """The bundled Cornell box with media: the XML and the dict both give Mitsuba's volpath,
    the sphere's and the fog box's interior media (sigma_t above 1 as a color in [0, 1]
    times the scale) and render alike sample for sample; a heterogeneous medium is refused."""
    from dataclasses import replace as dc_replace

    from drpt.errors import DrptError
    from drpt.scene import load_scene
    from drpt.scene.model import GridVolume

    scene = load_scene(SCENES / "cornellbox_media" / "cornellbox_media.txt")
    xml = write_xml(scene, tmp_path / "m.xml", 16, 16, 4, seed=3)
    text = xml.read_text()
    assert '<integrator type="volpath"' in text and text.count('<medium type="homogeneous" name="interior">') == 2
    loaded = mi.load_file(str(xml))
    media = [s.interior_medium() for s in loaded.shapes() if s.interior_medium() is not None]
    assert len(media) == 2
    sigma = sorted(np.array(mi.traverse(m)["sigma_t.value.value"]).ravel().tolist() for m in media)
    scales = sorted(float(mi.traverse(m)["scale"]) for m in media)
    assert np.allclose(scales, [0.4, 2.8]) and np.allclose(sigma[0], [1.2 / 2.8, 2.0 / 2.8, 1.0])
    a = render(loaded)
    b = render(to_mitsuba_dict(scene, 16, 16, 4, seed=3))
    assert np.allclose(a, b, atol=1e-5)
    grid = GridVolume(data=np.ones((2, 2, 2, 1), np.float32), to_local=np.eye(4))
    hetero = dc_replace(scene, media=[dc_replace(scene.media[0], sigma_t_grid=grid), scene.media[1]])
    with pytest.raises(DrptError, match="heterogeneous medium"):
        write_xml(hetero, tmp_path / "h.xml", 16, 16, 4)


def test_the_export_carries_the_triangle_test_drpt_traces(tmp_path):
    """drpt's own format is traced with Embree's robust triangle test, so its export asks
    Mitsuba for it (Mitsuba's default is off) and drpt reading the export keeps it; a
    Mitsuba XML scene that does not ask for it is exported without it."""
    from drpt.scene import load_scene
    from drpt.scene.model import embree_robust

    scene = _mixed_scene(tmp_path)
    assert embree_robust(scene)
    assert to_mitsuba_dict(scene, W, H, 4)["embree_use_robust_intersections"] is True
    xml = write_xml(scene, tmp_path / "own" / "scene.xml", W, H, 4)
    assert '<boolean name="embree_use_robust_intersections" value="true"/>' in xml.read_text()
    assert load_scene(xml).settings.embree_robust is True
    plain = tmp_path / "plain.xml"
    plain.write_text("""<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">
        <integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
        <shape type="sphere"/><emitter type="constant"/></scene>""")
    read = load_scene(plain)
    assert not embree_robust(read)
    again = write_xml(read, tmp_path / "again" / "scene.xml", 8, 8, 4)
    assert '<boolean name="embree_use_robust_intersections" value="false"/>' in again.read_text()
    assert load_scene(again).settings.embree_robust is False
