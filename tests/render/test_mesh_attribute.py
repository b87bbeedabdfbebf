"""Mitsuba's ``mesh_attribute`` texture (drpt.materials.spec.MeshAttribute, drpt.render.texture._Attribute):
vertex attributes interpolated with the hit's barycentric coordinates and face attributes, 1 and 3
channels, equal Mitsuba's ``eval`` at the same hits of the same PLY mesh (negative control: the
corners blended in another order); scenes with a vertex-colored, a face-colored and a face-weighted
``blendbsdf`` mesh render like Mitsuba on the same file (4x4 block z-test); a shape without the
attribute is a located error."""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Bool, Float, UInt32

from drpt.scene import load_scene
from drpt.testing import mitsuba


def _write_ply(path: Path, n=5, seed=0):
    """An n x n grid of quads in z = 0 over [-1, 1]^2 (bent in z), two triangles each, with
    ``vertex_color`` (3), ``face_color`` (3) and ``face_weight`` (1) attributes."""
    rng = np.random.default_rng(seed)
    xs = np.linspace(-1, 1, n + 1)
    vx, vy = np.meshgrid(xs, xs)
    v = np.stack([vx.ravel(), vy.ravel(), 0.2 * vx.ravel() ** 2], 1)
    col = rng.uniform(0.05, 0.95, (len(v), 3))
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j
            faces += [(a, b, c), (a, c, d)]
    fcol = rng.uniform(0.05, 0.95, (len(faces), 3))
    fw = rng.uniform(0, 1, len(faces))
    lines = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x", "property float y",
             "property float z", "property float color_0", "property float color_1", "property float color_2",
             f"element face {len(faces)}", "property list uchar int vertex_indices",
             "property float color_0", "property float color_1", "property float color_2",
             "property float weight_0", "end_header"]
    lines += [" ".join(f"{x:.6f}" for x in (*p, *c)) for p, c in zip(v, col)]
    lines += [f"3 {a} {b} {c} " + " ".join(f"{x:.6f}" for x in (*fc, w))
              for (a, b, c), fc, w in zip(faces, fcol, fw)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _scene_xml(path: Path, ply: Path, bsdf: str, spp=16) -> Path:
    path.write_text(f'''<scene version="3.0.0">
    <default name="spp" value="{spp}"/>
    <integrator type="direct"/>
    <emitter type="directional"><vector name="direction" value="0.2, 0.1, -1"/>
        <rgb name="irradiance" value="2"/></emitter>
    <sensor type="perspective"><float name="fov" value="35"/>
        <transform name="to_world"><lookat origin="0.3, 0.2, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>
            <rfilter type="box"/></film></sensor>
    {bsdf}
    <shape type="ply"><string name="filename" value="{ply}"/><ref id="bsdf"/></shape>
</scene>''')
    return path


BSDFS = {
    "vertex_color": '<bsdf type="diffuse" id="bsdf"><texture type="mesh_attribute" name="reflectance">'
                    '<string name="name" value="vertex_color"/></texture></bsdf>',
    "face_color": '<bsdf type="diffuse" id="bsdf"><texture type="mesh_attribute" name="reflectance">'
                  '<string name="name" value="face_color"/><float name="scale" value="0.9"/></texture></bsdf>',
    "face_weight": '<bsdf type="blendbsdf" id="bsdf"><texture type="mesh_attribute" name="weight">'
                   '<string name="name" value="face_weight"/></texture>'
                   '<bsdf type="diffuse"><rgb name="reflectance" value="0 .5 .5"/></bsdf>'
                   '<bsdf type="diffuse"><rgb name="reflectance" value="1 1 0"/></bsdf></bsdf>',
}
#: one BSDF that reads all three attributes (so that the reader loads each)
ALL = ('<bsdf type="blendbsdf" id="bsdf"><texture type="mesh_attribute" name="weight">'
       '<string name="name" value="face_weight"/></texture>'
       '<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">'
       '<string name="name" value="vertex_color"/></texture></bsdf>'
       '<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">'
       '<string name="name" value="face_color"/></texture></bsdf></bsdf>')


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["vertex_color", "face_color", "face_weight"])
def test_lookups_equal_mitsubas_eval(tmp_path, name):
    from drpt.materials.spec import MeshAttribute
    from drpt.options import RenderOptions
    from drpt.render.camera import RayCamera
    from drpt.render.scene import DeviceScene
    from drpt.render.texture import TextureSet

    mi = mitsuba()
    ply = _write_ply(tmp_path / "grid.ply")
    p = _scene_xml(tmp_path / "s.xml", ply, ALL)
    s = load_scene(p)
    dev = DeviceScene(s, RenderOptions(progress=False))
    xs, ys = np.meshgrid(np.linspace(0.5, 31.5, 40), np.linspace(0.5, 31.5, 40))
    o, d = RayCamera(s.camera, 32, 32).ray(Float(xs.ravel()), Float(ys.ravel()))
    si = dev.intersect(o, d, Bool(True))
    # the scene's material reads vertex_color; evaluate each attribute through a set of its own
    ts = TextureSet([MeshAttribute(name=name, scale=0.9 if name == "face_color" else 1.0)], s.triangles)
    n = dr.width(si.valid)
    ours = np.array(ts.lookup(dr.zeros(UInt32, n), si.uv, si.valid, si=si))
    hit = np.array(si.valid)
    assert hit.mean() > 0.3 and dev.materials.textures is not None

    scene = mi.load_file(str(p))
    ray = mi.Ray3f(mi.Point3f(*np.array(o)), mi.Vector3f(*np.array(d)))
    msi = scene.ray_intersect(ray)
    mtex = mi.load_dict({"type": "mesh_attribute", "name": name,
                         "scale": 0.9 if name == "face_color" else 1.0})
    theirs = np.array(mtex.eval(msi) if name != "face_weight" else mtex.eval_1(msi))
    theirs = np.broadcast_to(theirs, (3, n))
    assert np.array_equal(np.array(msi.is_valid()), hit)
    np.testing.assert_allclose(ours[:, hit], theirs[:, hit], atol=2e-5, rtol=0)
    if name == "vertex_color":  # negative control: the corners blended in another order
        a = s.triangles.attributes[name]
        s.triangles.attributes[name] = a[:, [0, 2, 1]]
        ts2 = TextureSet([MeshAttribute(name=name)], s.triangles)
        wrong = np.array(ts2.lookup(dr.zeros(UInt32, n), si.uv, si.valid, si=si))
        assert np.abs(wrong[:, hit] - theirs[:, hit]).max() > 0.05
        s.triangles.attributes[name] = a


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["vertex_color", "face_color", "face_weight"])
def test_renders_like_mitsuba(tmp_path, name):
    """The mesh lit by a directional light, direct integrator, 128 spp, 4x4 block z-test
    (|z| < 4.5 over 64 blocks x 3 channels)."""
    from drpt.testing import assert_agree
    from support.xml import render_xml_both

    ply = _write_ply(tmp_path / "grid.ply")
    p = _scene_xml(tmp_path / "s.xml", ply, BSDFS[name])
    scene = load_scene(p)
    r, ref, var = render_xml_both(scene, p, 128)
    assert ref.mean() > 0.05
    assert_agree(r, ref, var, zmax=4.5, block=4)


def test_missing_attribute_and_bad_name(tmp_path):
    from drpt.errors import SceneError

    ply = _write_ply(tmp_path / "grid.ply")
    bad = BSDFS["vertex_color"].replace('value="vertex_color"', 'value="vertex_nope"')
    with pytest.raises(SceneError, match="no mesh attribute 'vertex_nope'"):
        load_scene(_scene_xml(tmp_path / "a.xml", ply, bad))
    bad = BSDFS["vertex_color"].replace('value="vertex_color"', 'value="color"')
    with pytest.raises(SceneError, match="must start with 'vertex_' or 'face_'"):
        load_scene(_scene_xml(tmp_path / "b.xml", ply, bad))
    sphere = _scene_xml(tmp_path / "c.xml", ply, BSDFS["vertex_color"]).read_text().replace(
        f'<shape type="ply"><string name="filename" value="{ply}"/>', '<shape type="sphere">')
    (tmp_path / "c.xml").write_text(sphere)
    with pytest.raises(SceneError, match="has no mesh attributes"):
        load_scene(tmp_path / "c.xml")


@pytest.mark.mitsuba
def test_export_round_trip(tmp_path):
    """The exporter writes the attributes into its PLY (``color_0..2`` vertex and face
    properties, ``weight_0``) and the textures as ``mesh_attribute``: drpt reads the exported
    file back with the same corner values, and Mitsuba renders it as it renders the original."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict, write_xml

    ply = _write_ply(tmp_path / "grid.ply")
    s = load_scene(_scene_xml(tmp_path / "s.xml", ply, ALL))
    out = write_xml(s, tmp_path / "out" / "x.xml", 16, 16, 4)
    back = load_scene(out)
    assert set(back.triangles.attributes) == {"vertex_color", "face_color", "face_weight"}
    for k, a in s.triangles.attributes.items():
        np.testing.assert_allclose(back.triangles.attributes[k], a, atol=1e-6)
    mi.set_variant(mitsuba_variant())
    imgs = [np.array(mi.render(mi.load_file(str(p)), spp=16, seed=1)) for p in (tmp_path / "s.xml", out)]
    imgs.append(np.array(mi.render(mi.load_dict(to_mitsuba_dict(s, 32, 32, 16)), spp=16, seed=1)))
    assert imgs[0].mean() > 0.05
    for img in imgs[1:]:
        assert abs(img.mean() / imgs[0].mean() - 1.0) < 0.03
