"""Mitsuba XML scenes (drpt/scene/mitsuba): what drpt reads from the corpus in tests/data/xml,
its cameras and geometry against Mitsuba's own, bad files, and renders against Mitsuba.

The corpus (tests/data/xml, assets from make_assets.py): ``sphere`` (analytic and flipped
spheres, rectangles, an area light), ``meshes`` (obj, ply, serialized, cube, disk, cylinder,
point light, constant), ``instances`` (shapegroup/instance, directional, the ``direct``
integrator), ``spot`` (spot light, ``hide_emitters``), ``envmap`` (rotated, scaled map),
``textured`` (bitmap on obj and rectangle uvs), ``composites`` (blendbsdf with a texture
weight, mask, twosided, dielectric), ``glossy`` (conductor, roughconductor,
named-IOR dielectric, thindielectric, roughdielectric, principled), ``lens`` (thinlens, a
gaussian rfilter), ``bsdfs`` (every BSDF plugin of the vocabulary, with textures and
composites) and ``legacy06`` (a 0.6 file: camelCase names, serialized meshes, parameters the
plugins do not read). All but ``legacy06`` (which Mitsuba 3 itself refuses) are rendered here
by drpt and by Mitsuba *from the same file* (block z-test, drpt/testing.py, and the z of
the image mean), and so is ``aniso`` (an anisotropic roughconductor on a sphere and a
rectangle: shading frames follow Mitsuba's dp/du; tests/render/test_perturbed_frames.py has the
meshes, the rotated sphere, normal and bump maps and their negative controls).
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import SceneError
from drpt.scene import load_scene
from drpt.scene.model import DirectionalLight, PointLight, Skybox, SpotLight
from support.xml import XML, load, mean_z, render_xml_both

#: corpus scenes of BSDFs drpt renders, z-tested against Mitsuba
RENDER_CORPUS = ("sphere", "meshes", "instances", "spot", "envmap", "textured", "composites", "glossy",
                 "lens", "bsdfs", "ortho")


def spec_of(scene, name):
    (m,) = [m for m in scene.materials if m.name == name]
    return m.bsdf


# ------------------------------------------------------------ what drpt reads
def test_sphere_scene():
    s, warns = load("sphere")
    cam = s.camera
    assert np.allclose(cam.center, (0, 1.5, 5))
    d = np.array([0, -1.5, -5]) / math.hypot(1.5, 5)
    assert np.allclose(cam.direction, d)
    # fov 40 on x (Mitsuba's default axis) over a 32x24 film -> vertical fov
    assert math.isclose(cam.fov, math.degrees(2 * math.atan(math.tan(math.radians(20)) * 24 / 32)))
    st = s.settings
    assert (st.width, st.height, st.spp, st.integrator, st.max_depth, st.rr_depth) == (32, 24, 16, "path", 3, 5)
    assert st.rfilter == "box" and st.hide_emitters is False
    assert len(s.spheres) == 1 and np.allclose(s.spheres.center[0], (-0.8, 0, 0))
    assert math.isclose(s.spheres.radius[0], 0.6)
    assert any("flip_normals is tessellated" in w for w in warns)
    # the flipped sphere's normals point inward: toward its center (0.9, -0.1, 0)
    tris = s.triangles
    flipped = tris.material == [i for i, m in enumerate(s.materials) if m.name == "white"][0]
    centroid = tris.positions.mean(1)
    sel = flipped & (np.linalg.norm(centroid - (0.9, -0.1, 0), axis=1) < 0.51)
    assert sel.sum() > 10000
    inward = np.einsum("ij,ij->i", tris.normals[sel].mean(1), (0.9, -0.1, 0) - centroid[sel])
    assert np.all(inward > 0)
    names = [m.name for m in s.materials]
    assert names == ["diffuse@10", "white", "default+area"]
    light = s.materials[2]
    assert light.emission == (6.0, 6.0, 6.0) and light.bsdf.kind == "diffuse"
    assert light.bsdf.params == {"kd": (0.0, 0.0, 0.0)}  # Mitsuba's default BSDF of an emitter
    white = spec_of(s, "white")
    assert white.kind == "twosided" and white.children[0].params == {"kd": (0.7, 0.7, 0.7)}
    assert s.materials[0].kd == (0.2, 0.5, 0.8)


def test_meshes_scene_counts_and_lights():
    s, _ = load("meshes")
    # obj 2 + ply 4 + serialized quad 2 + cube 12 + disk 256 + cylinder 2*256
    assert len(s.triangles) == 2 + 4 + 2 + 12 + 256 + 512
    assert len(s.spheres) == 0
    (light,) = s.lights
    assert isinstance(light, PointLight) and light.position == (1, 3, 3) and light.color == (20, 20, 20)
    assert s.background.color == (0.15, 0.15, 0.15)
    tris = s.triangles
    # obj with face_normals: its shading normals are the geometric ones, facing +y after the rotation
    obj = np.nonzero(tris.material == 0)[0][:2]
    assert np.allclose(tris.normals[obj], (0, 1, 0), atol=1e-6)
    assert np.all(tris.positions[obj][..., 1] == pytest.approx(-0.7))


def test_instances_and_direct_integrator():
    s, _ = load("instances")
    assert len(s.triangles) == 3 * 12 + 2 and len(s.spheres) == 3
    # the third instance scales by 1.5 and moves to (1.3, 0, -0.5): its sphere
    k = np.argmax(s.spheres.radius)
    assert math.isclose(s.spheres.radius[k], 0.375)
    assert np.allclose(s.spheres.center[k], (1.3, 0.75, -0.5))
    # the second turns 45 degrees about y: its cube's corners are at radius 0.25 * sqrt(2)
    st = s.settings
    assert st.integrator == "path" and st.max_depth == 2  # Mitsuba's direct
    (light,) = s.lights
    assert isinstance(light, DirectionalLight) and light.direction == (-0.3, -1.0, -0.4)


def test_spot_and_hide_emitters():
    s, _ = load("spot")
    (spot,) = s.lights
    assert isinstance(spot, SpotLight)
    assert spot.position == (0.5, 3.0, 1.0) and (spot.cutoff_angle, spot.beam_width) == (30, 20)
    axis = np.array([0, -0.5, 0]) - (0.5, 3, 1)
    assert np.allclose(spot.direction, axis / np.linalg.norm(axis))
    assert s.settings.hide_emitters is True and s.settings.max_depth == 4


def test_envmap_scale_and_rotation():
    s, _ = load("envmap")
    (sky,) = s.lights
    assert isinstance(sky, Skybox) and sky.path == XML / "sky.exr" and sky.scale == 1.5
    c, si = math.cos(math.radians(90)), math.sin(math.radians(90))
    assert np.allclose(sky.rotation, [[c, 0, si], [0, 1, 0], [-si, 0, c]])
    assert sky.mis_compensation is None  # the file does not say: RenderOptions.env_compensation


@pytest.mark.parametrize("value", ["true", "false"])
def test_envmap_mis_compensation_is_read(tmp_path, value):
    body = (f'<emitter type="envmap"><string name="filename" value="{XML / "sky.exr"}"/>'
            f'<boolean name="mis_compensation" value="{value}"/></emitter>')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = load_scene(_xml(tmp_path, body))
    (sky,) = s.lights
    assert sky.mis_compensation is (value == "true")
    assert not [w for w in caught if "mis_compensation" in str(w.message)]


def test_textured_specs_and_uvs():
    s, _ = load("textured")
    for m in s.materials:
        assert m.bsdf.kind == "diffuse" and m.bsdf.params["kd"].path == XML / "checker.png"
        assert m.map_kd == XML / "checker.png"  # for the renderer before Material.bsdf
    assert s.triangles.uvs is not None
    # drpt keeps OBJ uvs (v up): the obj quad's corner (-1, -1) has its file uv (0, 0);
    # the rectangle's Mitsuba uv (0, 0) at local (-1, -1) becomes drpt (0, 1)
    tris = s.triangles
    p, uv = tris.positions.reshape(-1, 3), tris.uvs.reshape(-1, 2)
    obj_corner = np.nonzero(np.all(np.isclose(p, (-2.1, -1, 0)), axis=1))[0]
    assert np.allclose(uv[obj_corner], (0, 0))
    rect = tris.material.repeat(3) == 1
    local = p[rect] - (1.1, 0, 0)
    a = math.radians(-20)  # undo the rectangle's rotation about z
    lx = math.cos(a) * local[:, 0] - math.sin(a) * local[:, 1]
    ly = math.sin(a) * local[:, 0] + math.cos(a) * local[:, 1]
    assert np.allclose(uv[rect][:, 0], (lx + 1) / 2, atol=1e-6)
    assert np.allclose(uv[rect][:, 1], 1 - (ly + 1) / 2, atol=1e-6)


def test_bsdf_specs():
    s, _ = load("bsdfs")
    tex = XML / "checker.png"
    gold = spec_of(s, "gold")
    assert (gold.kind, gold.params) == ("conductor", {"material": "Au"})
    brushed = spec_of(s, "brushed")
    assert brushed.params == {"distribution": "ggx", "alpha_u": 0.05, "alpha_v": 0.3,
                              "eta": (0.2, 0.9, 1.1), "k": (3.9, 2.4, 2.2)}
    assert spec_of(s, "water").params == {"int_ior": "water", "ext_ior": 1.0}
    assert spec_of(s, "pane").kind == "thindielectric"
    assert spec_of(s, "frosted").params == {"alpha": 0.2, "sample_visible": False}
    assert spec_of(s, "shiny").params == {"diffuse_reflectance": (0.1, 0.2, 0.6), "nonlinear": True}
    matte = spec_of(s, "matte")
    assert matte.params["diffuse_reflectance"].path == tex and matte.params["alpha"] == 0.3
    car = spec_of(s, "car")
    assert car.params["roughness"].path == tex and car.params["clearcoat"] == 1.0
    mix = spec_of(s, "mix")
    assert mix.kind == "blendbsdf" and mix.params == {"weight": 0.25}
    assert [c.kind for c in mix.children] == ["roughconductor", "diffuse"]
    assert mix.children[0].params == {"material": "Au", "alpha": 0.2}  # the <ref>'d 'satin'
    assert mix.children[1].params == {}  # Mitsuba's defaults: the lobe fills them in
    leaf = spec_of(s, "leaf")
    assert leaf.kind == "mask" and leaf.params == {"opacity": 0.7}
    (two,) = leaf.children
    assert two.kind == "twosided" and two.children[0].params["kd"].path == tex
    assert all(m.loc.file == str(XML / "bsdfs.xml") and m.loc.line for m in s.materials)


def test_legacy_06_file_is_upgraded_and_unread_parameters_warned_once():
    s, warns = load("legacy06")
    st = s.settings
    assert (st.width, st.height, st.spp, st.max_depth, st.rr_depth) == (40, 30, 8, 4, 3)
    assert st.rfilter == "gaussian"
    assert math.isclose(s.camera.fov, 35.0)  # fovAxis y: drpt's own convention
    assert len(s.triangles) == 2 + 1 and len(s.spheres) == 1
    metal = spec_of(s, "metal")
    assert metal.params == {"alpha": 0.2, "specular_reflectance": (0.9, 0.9, 0.9)}
    unread = [w for w in warns if "do not read" in w]
    assert len(unread) == 1
    assert "'int_ior' of bsdf 'roughconductor'" in unread[0] and "'strict_normals' of integrator" in unread[0]
    assert "legacy06.xml:5" in unread[0] and "legacy06.xml:23" in unread[0]
    with pytest.raises(SceneError, match=r"legacy06.xml:\d+: .*does not read parameter"):
        load_scene(XML / "legacy06.xml", strict=True)


def test_defines_fill_variables():
    s, _ = load("sphere", defines={"w": "64", "h": "16", "spp": "3"})
    assert (s.settings.width, s.settings.height, s.settings.spp) == (64, 16, 3)
    # the fov is on x: the vertical fov follows the new aspect
    assert math.isclose(s.camera.fov, math.degrees(2 * math.atan(math.tan(math.radians(20)) / 4)))


def _xml(tmp_path, body: str, name="t.xml", version="3.0.0") -> Path:
    p = tmp_path / name
    sensor = ('<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>'
              '<integer name="height" value="8"/></film></sensor>')
    p.write_text(f'<scene version="{version}">\n{sensor}\n{body}\n</scene>\n')
    return p


@pytest.mark.parametrize("axis, fov, aspect, expect_y", [
    ("x", 60, 2.0, 2 * math.atan(math.tan(math.radians(30)) / 2)),
    ("y", 60, 2.0, math.radians(60)),
    ("diagonal", 60, 2.0, 2 * math.atan(math.tan(math.radians(30)) / math.sqrt(5))),
    ("smaller", 60, 2.0, math.radians(60)),  # wide film: the smaller axis is y
    ("smaller", 60, 0.5, 2 * math.atan(math.tan(math.radians(30)) / 0.5)),
    ("larger", 60, 2.0, 2 * math.atan(math.tan(math.radians(30)) / 2)),
])
def test_fov_axes(axis, fov, aspect, expect_y):
    from drpt.scene.mitsuba.reader import vertical_fov

    assert math.isclose(math.radians(vertical_fov(fov, axis, aspect)), expect_y, rel_tol=1e-12)


def test_unsupported_plugins_stop_or_are_left_out(tmp_path):
    p = _xml(tmp_path, '<medium type="homogeneous" id="fog"><phase type="rayleigh"/></medium>\n'
                       '<shape type="sphere"><bsdf type="diffuse"/><ref name="interior" id="fog"/></shape>\n'
                       '<shape type="sphere"><bsdf type="hair"><float name="eumelanin" value="1"/>'
                       '</bsdf></shape>')
    with pytest.raises(SceneError, match=r"t.xml:3: unsupported phase function 'rayleigh'"):
        load_scene(p)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = load_scene(p, ignore_unsupported=True)
    msgs = [str(w.message) for w in caught]
    assert any("t.xml:3: unsupported phase function 'rayleigh'" in m and "using isotropic" in m for m in msgs)
    assert any("t.xml:5: unsupported BSDF plugin 'hair'" in m for m in msgs)
    assert len(s.spheres) == 2 and s.materials[1].bsdf.kind == "diffuse"


@pytest.mark.parametrize("body, message", [
    ('<shape type="sphere"><string name="radius" value="big"/></shape>',
     r"t.xml:3: shape 'sphere': parameter 'radius' must be a float, got a string"),
    ('<shape type="obj"><string name="filename" value="nothere.obj"/></shape>',
     r"t.xml:3: shape 'obj': nothere.obj: no such file"),
    ('<shape type="sphere"><bsdf type="diffuse"><string name="reflectance" value="red"/></bsdf></shape>',
     r"t.xml:3: bsdf 'diffuse': parameter 'reflectance' must be a color"),
    ('<shape type="sphere"><bsdf type="conductor"><texture type="bitmap" name="material">'
     '<string name="filename" value="a.png"/></texture></bsdf></shape>',
     r"t.xml:3: bsdf 'conductor': parameter 'material' cannot be a texture"),
    ('<emitter type="area"/>', r"t.xml:3: emitter 'area' must be attached to a shape"),
    ('<shape type="sphere"><emitter type="area"><spectrum name="radiance" value="400:1, 700:x"/>'
     '</emitter></shape>', r"t.xml:3: Could not parse wavelength:value pair \"700:x\""),
    ('<integrator type="bdpt"/>', r"t.xml:3: unsupported integrator 'bdpt'"),
    ('<shape type="sphere"><bsdf type="twosided"/></shape>',
     r"t.xml:3: bsdf 'twosided' needs 1 nested BSDF, got 0"),
    ('<shape type="sphere"><bsdf type="twosided"><bsdf type="dielectric"/></bsdf></shape>',
     r"t.xml:3: bsdf 'twosided': twosided cannot hold the transmissive BSDF 'dielectric'"),
])
def test_bad_parameters_are_located_errors(tmp_path, body, message):
    with pytest.raises(SceneError, match=message):
        load_scene(_xml(tmp_path, body))


def test_textured_sphere_is_tessellated_for_its_uvs():
    s, warns = load("bsdfs")
    # the spheres of 'matte' and 'car' have textures: tessellated, with Mitsuba's uvs
    assert len(s.spheres) == 8 - 2
    assert sum("a texture (drpt's analytic spheres have no uvs)" in w for w in warns) == 2
    matte = [i for i, m in enumerate(s.materials) if m.name == "matte"][0]
    sel = s.triangles.material == matte
    p = s.triangles.positions[sel].reshape(-1, 3) - (1, 0, 0)
    uv = s.triangles.uvs[sel].reshape(-1, 2)
    theta = np.arccos(np.clip(p[:, 2] / 0.3, -1, 1))
    assert np.allclose(1 - uv[:, 1], theta / np.pi, atol=1e-6)  # drpt's v is Mitsuba's 1 - v


def test_mirrored_or_scaled_camera_is_refused(tmp_path):
    for op in ('<scale x="-1"/>', '<scale value="2"/>'):
        p = tmp_path / "cam.xml"
        p.write_text(f'<scene version="3.0.0"><sensor type="perspective"><transform name="to_world">{op}'
                     '<lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform></sensor></scene>')
        with pytest.raises(SceneError, match=r"cam.xml:1: sensor 'perspective': (the camera's to_world mirrors|scale)"):
            load_scene(p)


def test_crop_window_and_thin_lens_reach_the_camera(tmp_path):
    p = tmp_path / "crop.xml"
    p.write_text('<scene version="3.0.0"><sensor type="thinlens"><float name="aperture_radius" value="0.1"/>'
                 '<film type="hdrfilm"><integer name="crop_width" value="10"/></film></sensor></scene>')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = load_scene(p)
    assert not caught
    assert (s.settings.width, s.settings.height) == (10, 576)  # the crop of Mitsuba's default film
    w = s.camera.window
    assert (w.film_width, w.film_height, w.crop_size) == (768, 576, (10, 576))  # tests/render/test_film_window.py
    # Mitsuba's focus distance defaults to the far clip plane
    assert (s.camera.aperture_radius, s.camera.focus_distance) == (0.1, 1e4)
    assert s.settings.rfilter == "gaussian"  # the film's default filter


def test_apply_scene_settings_flags_win(tmp_path):
    from drpt.cli import build_parser
    from drpt.cli.args import given_settings, options_from_args
    from drpt.options import with_scene_settings

    s, _ = load("spot")
    args = build_parser().parse_args(["render", "x.xml", "--spp", "5", "--max-depth", "2"])
    opts, s = with_scene_settings(options_from_args(args), s, given_settings(args))
    assert (opts.width, opts.height, opts.spp) == (32, 24, 5)
    assert (opts.path.max_depth, opts.path.rr_depth, opts.path.hide_emitters) == (2, 5, True)
    # a flag given at its default value still wins
    args = build_parser().parse_args(["render", "x.xml", "--size", "512", "512", "--filter", "box"])
    opts, s = with_scene_settings(options_from_args(args), s, given_settings(args))
    assert (opts.width, opts.height, opts.spp, opts.path.max_depth) == (512, 512, 16, 4)
    assert opts.filter == "box"
    lens, _ = load("lens")
    args = build_parser().parse_args(["render", "x.xml"])
    assert with_scene_settings(options_from_args(args), lens, given_settings(args))[0].filter == "gaussian:stddev=0.7"
    args = build_parser().parse_args(["render", "x.xml", "--filter", "box"])
    assert with_scene_settings(options_from_args(args), lens, given_settings(args))[0].filter == "box"
    legacy, _ = load("legacy06")  # <rfilter type="gaussian"/>: Mitsuba's stddev 0.5
    args = build_parser().parse_args(["render", "x.xml"])
    assert with_scene_settings(options_from_args(args), legacy, given_settings(args))[0].filter == "gaussian"


# ------------------------------------------------------------ against Mitsuba itself
@pytest.mark.mitsuba
@pytest.mark.parametrize("axis", ["x", "y", "diagonal", "smaller", "larger"])
@pytest.mark.parametrize("size", [(48, 24), (20, 40)])
def test_camera_rays_match_mitsuba(tmp_path, axis, size):
    """drpt's ray through each pixel position is Mitsuba's for the same sensor node."""
    import mitsuba as mi
    from drjit.auto import Float

    from drpt.backend import mitsuba_variant
    from drpt.render.camera import RayCamera

    W, H = size
    p = tmp_path / "cam.xml"
    p.write_text(f'<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="50"/>'
                 f'<string name="fov_axis" value="{axis}"/><transform name="to_world">'
                 '<lookat origin="1, 2, 3" target="-1, 0.5, -2" up="0.2, 1, 0"/></transform>'
                 f'<film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" '
                 f'value="{H}"/></film></sensor></scene>')
    scene = load_scene(p)
    xs, ys = np.meshgrid(np.linspace(0, W, 7), np.linspace(0, H, 5))
    xs, ys = xs.ravel(), ys.ravel()
    o, d = RayCamera(scene.camera, W, H).ray(Float(xs), Float(ys))
    d = np.array(d).T
    mi.set_variant(mitsuba_variant())
    sensor = mi.load_file(str(p)).sensors()[0]
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(xs / W, ys / H), mi.Point2f(0.5, 0.5))
    md = np.array(ray.d).T
    assert np.allclose(np.array(o).T, (1, 2, 3), atol=1e-5)
    assert np.abs(d - md).max() < 2e-5, np.abs(d - md).max()


def _intersect_numpy(scene, o, d):
    """Closest hit (t, shading normal) of rays against drpt's triangles and spheres, in numpy."""
    n_rays = len(d)
    t_best = np.full(n_rays, np.inf)
    n_best = np.zeros((n_rays, 3))
    tris = scene.triangles
    if len(tris):
        p0, p1, p2 = (tris.positions[:, k] for k in range(3))
        e1, e2 = p1 - p0, p2 - p0
        for i in range(n_rays):
            pv = np.cross(d[i], e2)
            det = np.einsum("ij,ij->i", e1, pv)
            ok = np.abs(det) > 1e-12
            inv = np.where(ok, 1 / np.where(ok, det, 1), 0)
            tv = o[i] - p0
            u = np.einsum("ij,ij->i", tv, pv) * inv
            qv = np.cross(tv, e1)
            v = (qv @ d[i]) * inv
            t = np.einsum("ij,ij->i", e2, qv) * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
            if hit.any():
                k = np.argmin(np.where(hit, t, np.inf))
                if t[k] < t_best[i]:
                    t_best[i] = t[k]
                    nrm = tris.normals[k] if tris.normals is not None else None
                    if nrm is None:
                        g = np.cross(e1[k], e2[k])
                        n_best[i] = g / np.linalg.norm(g)
                    else:
                        ns = (1 - u[k] - v[k]) * nrm[0] + u[k] * nrm[1] + v[k] * nrm[2]
                        n_best[i] = ns / np.linalg.norm(ns)
    for c, r in zip(scene.spheres.center, scene.spheres.radius):
        oc = o - c
        b = np.einsum("ij,ij->i", oc, d)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
        sq = np.sqrt(np.maximum(disc, 0))
        t = np.where(-b - sq > 1e-6, -b - sq, -b + sq)
        hit = (disc > 0) & (t > 1e-6) & (t < t_best)
        t_best[hit] = t[hit]
        n_best[hit] = (o[hit] + t[hit, None] * d[hit] - c) / r
    return t_best, n_best


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["sphere", "meshes", "instances"])
def test_geometry_matches_mitsubas(name):
    """Camera rays hit the same surfaces at the same distances with the same front side
    (the sign of the shading normal along the ray) in drpt's scene as in Mitsuba's."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant

    scene, _ = load(name)
    mi.set_variant(mitsuba_variant())
    ms = mi.load_file(str(XML / f"{name}.xml"), optimize=False)
    W, H = 32, 24
    xs, ys = np.meshgrid((np.arange(W) + 0.5) / W, (np.arange(H) + 0.5) / H)
    ray, _ = ms.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f(xs.ravel(), ys.ravel()), mi.Point2f(0.5))
    si = ms.ray_intersect(ray)
    o, d = np.array(ray.o, np.float64).T, np.array(ray.d, np.float64).T
    mt = np.where(np.array(si.is_valid()), np.array(si.t), np.inf)
    mn = np.array(si.sh_frame.n, np.float64).T
    t, n = _intersect_numpy(scene, o, d)
    hit, mhit = np.isfinite(t), np.isfinite(mt)
    assert np.mean(hit == mhit) > 0.99  # silhouettes of tessellated shapes may differ
    both = hit & mhit
    t, mt = np.where(both, t, 0), np.where(both, mt, 0)
    close = both & (np.abs(t - mt) < 1e-3 * np.maximum(mt, 1))
    assert close.sum() > 0.97 * both.sum()
    side = np.sign(np.einsum("ij,ij->i", n, d)) == np.sign(np.einsum("ij,ij->i", mn, d))
    assert side[close].all()
    assert (np.einsum("ij,ij->i", n[close], mn[close]) > 0.99).mean() > 0.99


# ------------------------------------------------------------ the command line
def _run(args, cwd=None):
    return subprocess.run([sys.executable, "-m", "drpt", *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


BAD = {
    "malformed": ('<scene version="3.0.0"><shape type="sphere"></scene>', r"malformed.xml:1: malformed XML"),
    "missing_mesh": ('<scene version="3.0.0"><sensor type="perspective"/>\n'
                     '<shape type="ply"><string name="filename" value="gone.ply"/></shape></scene>',
                     r"missing_mesh.xml:2: shape 'ply': gone.ply: no such file"),
    "unknown_plugin": ('<scene version="3.0.0"><sensor type="perspective"/>\n<shape type="teapot"/></scene>',
                       r"unknown_plugin.xml:2: unsupported shape 'teapot'"),
    "wrong_type": ('<scene version="3.0.0"><sensor type="perspective">\n<integer name="fov" value="x"/>'
                   '</sensor></scene>', r"wrong_type.xml:2: could not parse integer value"),
    "undefined_var": ('<scene version="3.0.0"><sensor type="perspective">\n<float name="fov" value="$f"/>'
                      '</sensor></scene>', r"undefined_var.xml:2: undefined parameter: \$f"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_xml_is_one_line_exit_2_nothing_written(tmp_path, case):
    import re

    text, message = BAD[case]
    p = tmp_path / f"{case}.xml"
    p.write_text(text)
    out = tmp_path / "out.png"
    r = _run(["render", str(p), "-o", str(out), "-q"])
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("drpt: error: ") and re.search(message, lines[0]), lines[0]
    assert str(p) in lines[0]
    assert not out.exists() and list(tmp_path.iterdir()) == [p]


@pytest.mark.slow
def test_render_xml_with_its_own_settings_and_flags(tmp_path):
    out = tmp_path / "s.exr"
    r = _run(["render", str(XML / "legacy06.xml"), "-o", str(out), "-q", "--strict"])
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "does not read parameter" in r.stderr and not out.exists()
    r = _run(["render", str(XML / "sphere.xml"), "-o", str(out), "-q", "-D", "spp=2", "-D", "w=12"])
    assert r.returncode == 0, r.stderr
    assert "12x24, 2 spp" in r.stdout  # the film's size (with $w) and the sampler's count
    assert r.stderr.count("drpt: warning:") == 1 and "tessellated" in r.stderr
    from drpt.imageio import read_image

    assert read_image(out).shape == (24, 12, 3)
    r = _run(["render", str(XML / "sphere.xml"), "-o", str(out), "-q", "-D", "nope"])
    assert r.returncode == 2 and "-D needs name=value" in r.stderr


# ------------------------------------------------------------ renders against Mitsuba
@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", RENDER_CORPUS)
def test_corpus_renders_like_mitsuba(name):
    """drpt and Mitsuba render the very same XML file alike (8x8 block z-test): the file's own
    size, integrator, depths and filter (box), no extra flags."""
    from drpt.testing import assert_agree

    scene, _ = load(name)
    r, ref, var = render_xml_both(scene, XML / f"{name}.xml", 256)
    assert r.image.shape == (24, 32, 3) and ref.mean() > 0.05
    assert_agree(r, ref, var, zmax=4.5)
    z = mean_z(r, ref, var)
    assert np.abs(z).max() < 4.0, f"image mean z = {z}"


@pytest.mark.slow
@pytest.mark.mitsuba
def test_anisotropic_roughconductor_on_a_sphere_renders_like_mitsuba():
    from drpt.testing import assert_agree

    scene, _ = load("aniso")
    r, ref, var = render_xml_both(scene, XML / "aniso.xml", 256)
    assert_agree(r, ref, var, zmax=4.5)


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("what", ["envmap rotation", "hide_emitters", "spot beam", "emitter bsdf",
                                  "pinhole for thinlens", "box for gaussian"])
def test_negative_controls_fail_the_z_test(what):
    """The render check catches a wrong reading of the file: each perturbed scene must FAIL."""
    from dataclasses import replace

    from drpt.testing import block_z

    if what == "envmap rotation":
        scene, _ = load("envmap")
        scene.lights[0].rotation = None
        path = XML / "envmap.xml"
    elif what == "hide_emitters":
        scene, _ = load("spot")
        scene.settings = replace(scene.settings, hide_emitters=False)
        path = XML / "spot.xml"
    elif what == "spot beam":
        scene, _ = load("spot")
        scene.lights[0].beam_width = 29.0
        path = XML / "spot.xml"
    elif what == "pinhole for thinlens":
        scene, _ = load("lens")
        scene.camera = replace(scene.camera, aperture_radius=0.0, focus_distance=None)
        path = XML / "lens.xml"
    elif what == "box for gaussian":
        scene, _ = load("lens")
        scene.settings = replace(scene.settings, rfilter="box", rfilter_params={})
        path = XML / "lens.xml"
    else:  # the area light's rectangle given Mitsuba's diffuse 0.5 instead of its black default
        scene, _ = load("composites")
        (light,) = [m for m in scene.materials if m.is_emissive]
        light.bsdf = replace(light.bsdf, params={"kd": (0.5, 0.5, 0.5)})
        path = XML / "composites.xml"
    # a 1% bias: 256 spp show it at z ~ 4.5, 1024 at ~ 9
    r, ref, var = render_xml_both(scene, path, 1024 if what == "emitter bsdf" else 256)
    z = block_z(r.image, r.variance, ref, var)
    zm = mean_z(r, ref, var)
    assert np.abs(z).max() > 6 or np.abs(zm).max() > 6, \
        f"{what}: max |z| = {np.abs(z).max():.2f}, mean z {zm} (should fail)"


def _mitsuba_mean_var(path: Path, spp: int, seed: int, **defines):
    import mitsuba as mi

    from drpt.backend import mitsuba_variant

    mi.set_variant(mitsuba_variant())
    batches = 8
    ms = mi.load_file(str(path), optimize=False, **defines)
    runs = np.stack([np.asarray(mi.render(ms, spp=spp // batches, seed=seed + 7919 * k),
                                np.float64)[..., :3] for k in range(batches)])
    return runs.mean(0), runs.var(0, ddof=1) / batches


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["composites", "spot", "envmap", "instances", "aniso_mesh", "normalmap", "thin",
                                  "bumpmap"])
def test_export_of_an_imported_scene_renders_the_same_in_mitsuba(tmp_path, name):
    """Round trip: ``drpt export`` of an imported XML scene, rendered by Mitsuba, agrees with
    Mitsuba's render of the original file (block z-test and the mean's z)."""
    from drpt.cli import main
    from drpt.testing import block_z

    out = tmp_path / f"{name}.xml"
    assert main(["export", str(XML / f"{name}.xml"), str(out)]) == 0
    a, va = _mitsuba_mean_var(out, 256, seed=1)
    b, vb = _mitsuba_mean_var(XML / f"{name}.xml", 256, seed=5)
    assert a.shape == b.shape == (24, 32, 3)
    z = block_z(a, va, b, vb)
    assert np.abs(z).max() < 4.5, f"max |z| = {np.abs(z).max():.2f}"
    n = a.shape[0] * a.shape[1]
    zm = (a.mean((0, 1)) - b.mean((0, 1))) / np.sqrt(va.mean((0, 1)) / n + vb.mean((0, 1)) / n)
    assert np.abs(zm).max() < 4.0, zm


@pytest.mark.slow
@pytest.mark.mitsuba
def test_mitsubas_blend_of_a_delta_and_a_smooth_lobe_is_biased():
    """Why no corpus scene blends a delta lobe: Mitsuba 3.9's ``blendbsdf`` adds the delta
    lobe's sample "pdf" (1) to the smooth lobe's density (blendbsdf.cpp, ``sample``), which is
    biased. On a convex sphere under constant light the image is linear in the BSDF, so
    ``blend(w)`` must equal ``(1 - w) blend(0) + w blend(1)``: drpt's does, Mitsuba's does not."""
    from dataclasses import replace

    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer

    path = XML / "blend_delta.xml"
    a, va = _mitsuba_mean_var(path, 1024, 1, weight="0")  # all conductor
    b, vb = _mitsuba_mean_var(path, 1024, 2, weight="1")  # all diffuse
    lin, vlin = 0.75 * a + 0.25 * b, 0.75 ** 2 * va + 0.25 ** 2 * vb
    m, vm = _mitsuba_mean_var(path, 1024, 3)
    scene, _ = load("blend_delta")
    r = Renderer(scene, replace(with_scene_settings(RenderOptions(progress=False, seed=4), scene)[0],
                                spp=1024)).render()
    n = lin.shape[0] * lin.shape[1]

    def mean_z(x, vx):
        return (x.mean((0, 1)) - lin.mean((0, 1))) / np.sqrt(vx.mean((0, 1)) / n + vlin.mean((0, 1)) / n)

    assert np.abs(mean_z(r.image.astype(np.float64), r.variance)).max() < 4.0
    assert np.abs(mean_z(m, vm)).max() > 8.0  # Mitsuba's blend: about 1% darker in red
