"""AOVs (``--aovs``, Mitsuba's ``aov`` integrator): their names, their values against
Mitsuba's ``aov`` integrator on the same file, the kernel traced only when asked for,
chunked and resumed renders, the EXR layers and the denoiser's guides."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drpt.aovs import parse_aovs, split
from drpt.errors import DrptError, SceneError
from drpt.options import RenderOptions, with_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

#: every supported AOV type; a sphere (analytic), a rectangle and a cube (meshes with
#: uvs), diffuse and rough-conductor BSDFs, a constant sky; Mitsuba's depth is measured
#: from the near clip plane, where its camera rays start
AOVS = "dd.y:depth,nn:sh_normal,gn:geo_normal,pos:position,alb:albedo,uv:uv,pi:prim_index"
SCENE = """<scene version="3.0.0">
  <default name="filter" value="box"/>
  <integrator type="aov">
    <string name="aovs" value="{aovs}"/>
    <integrator type="path" name="img"><integer name="max_depth" value="3"/></integrator>
  </integrator>
  <sensor type="perspective">
    <float name="fov" value="40"/><float name="near_clip" value="1"/>
    <transform name="to_world"><lookat origin="0,1,4" target="0,0,0" up="0,1,0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
    <film type="hdrfilm"><integer name="width" value="48"/><integer name="height" value="32"/>
      <rfilter type="$filter"/></film>
  </sensor>
  <shape type="sphere"><point name="center" value="-0.6,0,0"/><float name="radius" value="0.5"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.2,0.5,0.8"/></bsdf></shape>
  <shape type="rectangle">
    <transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/><translate y="-0.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7,0.2,0.1"/></bsdf></shape>
  <shape type="cube">
    <transform name="to_world"><scale value="0.35"/><rotate y="1" angle="30"/><translate x="0.7" y="-0.1"/></transform>
    <bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""


def _scene_file(tmp_path, aovs=AOVS):
    p = tmp_path / "aov.xml"
    p.write_text(SCENE.format(aovs=aovs))
    return p


# ------------------------------------------------------------------ names
def test_aov_names_are_mitsubas():
    assert parse_aovs("albedo, normal,dd.y:depth") == (("albedo", "albedo"), ("normal", "sh_normal"),
                                                        ("dd.y", "depth"))
    layers, guides = split(parse_aovs("dd.y:depth,nn:sh_normal,uv"), True, np.zeros((2, 2, 12)))
    assert list(layers) == ["dd.y.T", "nn.X", "nn.Y", "nn.Z", "uv.U", "uv.V"]
    assert sorted(guides) == ["guide_albedo", "guide_normal"]


@pytest.mark.parametrize("text,message", [("depth,colour", "unknown AOV type 'colour'"),
                                          ("duv_dx", "'duv_dx' is not supported"),
                                          (":depth", "empty name"),
                                          ("a:depth,a:uv", "'a' is given twice")])
def test_bad_aov_lists_are_one_error(text, message):
    with pytest.raises(DrptError, match=message):
        parse_aovs(text)


def test_options_check_their_aovs():
    with pytest.raises(DrptError, match="must be \\(name, type\\) pairs"):
        RenderOptions(aovs="depth").validate()
    with pytest.raises(DrptError, match="given twice"):
        RenderOptions(aovs=(("a", "depth"), ("a", "uv"))).validate()
    RenderOptions(aovs=parse_aovs("depth,uv")).validate()


def test_the_aov_integrator_is_read(tmp_path):
    s = load_scene(_scene_file(tmp_path))
    assert s.settings.aovs == parse_aovs(AOVS) and s.settings.aov_image == "img"
    assert s.settings.max_depth == 3  # the nested integrator's settings
    opts, s = with_scene_settings(RenderOptions(progress=False), s)
    assert opts.aovs == parse_aovs(AOVS)
    with pytest.raises(SceneError, match=r"aov.xml:3: .*unknown AOV type 'bogus'"):
        load_scene(_scene_file(tmp_path, "d:bogus"))


# ------------------------------------------------------------------ against Mitsuba
@pytest.mark.parametrize("rfilter", ["box", "gaussian"])
def test_aovs_equal_mitsubas_aov_integrator(tmp_path, rfilter):
    """drpt's AOVs against Mitsuba's ``aov`` integrator rendering the same file, both at 64
    spp (scalar_rgb). The pixels on silhouettes average several surfaces (or the sky's 0),
    so the two differ there by pixel-coverage noise: per channel, the mean |difference| must
    be below 1% of the channel's largest |value| (measured: at most 0.55%, the normals' y
    on the cube's and sphere's outlines). Negative control: the same images one pixel row
    apart fail it in every channel (measured: 1.8% to 7.5%)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = _scene_file(tmp_path)
    ref = np.array(mi.render(mi.load_file(str(path), filter=rfilter), spp=64))[..., 3:]
    s = load_scene(path, defines={"filter": rfilter})
    opts, s = with_scene_settings(RenderOptions(progress=False), s)
    assert opts.filter.startswith(rfilter)
    ours = Renderer(s, opts).render().aov
    assert ours.shape == ref.shape == (32, 48, 16)
    scale = np.abs(ref).max(axis=(0, 1))
    err = np.abs(ours - ref).mean(axis=(0, 1)) / scale
    assert err.max() < 0.01, err
    shifted = np.abs(ours[1:] - ref[:-1]).mean(axis=(0, 1)) / scale
    assert shifted.min() > 0.01, shifted


def test_shape_index_is_mitsubas(tmp_path):
    """``shape_index`` numbers the shapes as Mitsuba's scalar variants do (its
    ``scene.shapes()``: the shapes that are not meshes first, so the cube, second in the
    file, is number 4 after two spheres and a disk), 0 where the ray misses; ``prim_index``
    is the face within its shape. Same criterion as above (measured: 0.3%, 0.2%).
    Negative controls: the one-row shift fails it (3.4%, 1.9%), and so does numbering the
    shapes in file order (the cube 2: 17%)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    text = SCENE.format(aovs="s:shape_index,p:prim_index").replace(
        '<shape type="rectangle">', '<shape type="sphere"><point name="center" value="0.9,0.6,-1"/>'
        '<float name="radius" value="0.4"/></shape>\n  <shape type="disk">')
    i = text.index('  <shape type="cube">')
    cube = text[i:text.index("</shape>", i) + len("</shape>\n")]
    text = text.replace(cube, "")
    first = text.index("</shape>\n") + len("</shape>\n")
    p = tmp_path / "shapes.xml"
    p.write_text(text[:first] + cube + text[first:])  # sphere, cube, sphere, disk
    ref = np.array(mi.render(mi.load_file(str(p), filter="box"), spp=64))[..., 3:]
    s = load_scene(p)
    ours = Renderer(s, with_scene_settings(RenderOptions(progress=False), s)[0]).render().aov
    assert sorted(np.unique(np.round(ref[..., 0]))) == [0, 1, 2, 3, 4]
    scale = np.abs(ref).max(axis=(0, 1))
    err = np.abs(ours - ref).mean(axis=(0, 1)) / scale
    assert err.max() < 0.01, err
    assert (np.abs(ours[1:] - ref[:-1]).mean(axis=(0, 1)) / scale).min() > 0.01
    file_order = np.array([0, 1, 3, 4, 2], float)[np.round(ours[..., 0]).astype(int)]
    assert np.abs(file_order - ref[..., 0]).mean() / scale[0] > 0.01


def test_uv_of_a_mesh_without_texture_coordinates_is_barycentric(tmp_path):
    """Mitsuba's uv on a mesh without texture coordinates is the hit's barycentric
    coordinates ``(b1, b2)``: drpt's equals it to 0.03 mean |difference| (measured: 0.018,
    the pixels' own 16-spp noise); zeros (a mesh without uvs read as (0, 0)) miss by 0.29."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    (tmp_path / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n")
    p = tmp_path / "quad.xml"
    p.write_text(MASKS.replace('value="a:albedo"', 'value="u:uv"').split("  <shape")[0]
                 + '  <shape type="obj"><string name="filename" value="quad.obj"/></shape>\n</scene>')
    ref = np.array(mi.render(mi.load_file(str(p)), spp=16))[..., 3:]
    s = load_scene(p)
    ours = Renderer(s, replace(with_scene_settings(RenderOptions(progress=False), s)[0], spp=16)).render().aov
    assert np.abs(ours - ref).mean() < 0.03
    assert np.abs(ref).mean() > 0.2  # the negative control: zeros


ALL = "d:depth,n:sh_normal,g:geo_normal,p:position,a:albedo,u:uv,i:prim_index"


@pytest.mark.parametrize("rel", ["texture_interp/test_texture_interp_direct.xml",
                                 "orthographic_sensor/test_orthographic_path.xml"])
def test_corpus_aovs_equal_mitsubas(rel):
    """Mitsuba's own render-test scenes (a textured plane, an orthographic sensor), their AOVs
    by Mitsuba's ``aov`` integrator in place of the file's and by drpt, 16 spp each: per
    channel, mean |difference| below 1.5% of the channel's largest value (measured: at most
    1.07%, the textured albedo; it falls as 1/sqrt(spp): noise). The one-row shift fails
    it (albedo 7.4% and 3.4%; constant channels, such as a plane's normal, cannot)."""
    from support.corpus import corpus_scene

    path = corpus_scene(rel)
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    aov = mi.load_dict({"type": "aov", "aovs": ALL})
    ref = np.array(mi.render(mi.load_file(str(path)), integrator=aov, spp=16))[..., -16:]
    s = load_scene(path)
    opts = replace(with_scene_settings(RenderOptions(progress=False), s)[0], spp=16, aovs=parse_aovs(ALL))
    ours = Renderer(s, opts).render().aov
    scale = np.maximum(np.abs(ref).max(axis=(0, 1)), 1e-6)
    err = np.abs(ours - ref).mean(axis=(0, 1)) / scale
    assert err.max() < 0.015, err
    shifted = np.abs(ours[1:] - ref[:-1]).mean(axis=(0, 1)) / scale
    assert shifted.max() > 0.015, shifted


MASKS = """<scene version="3.0.0">
  <integrator type="aov"><string name="aovs" value="a:albedo"/><integrator type="path"/></integrator>
  <sensor type="perspective"><float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film></sensor>
  <shape type="sphere"><float name="radius" value="0.6"/><point name="center" value="-0.5,0,0"/>
    <bsdf type="mask"><float name="opacity" value="0.3"/>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.2,0.6,0.3"/></bsdf></bsdf></shape>
  <shape type="sphere"><float name="radius" value="0.4"/><point name="center" value="0.6,0,0"/>
    <bsdf type="blendbsdf"><float name="weight" value="0.25"/>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.8,0.1,0.1"/></bsdf>
    <bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.1,0.1,0.9"/></bsdf></bsdf></shape>
  <emitter type="constant"/>
</scene>"""


def test_albedo_of_masks_and_blends_is_mitsubas(tmp_path):
    """Mitsuba's albedo of a ``mask`` is its nested BSDF's (not weighted by the opacity),
    of a ``blendbsdf`` the blend of its two (here a diffuse and a rough plastic's diffuse
    reflectance): the pixels at the two spheres' centers equal Mitsuba's exactly."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    p = tmp_path / "masks.xml"
    p.write_text(MASKS)
    ref = np.array(mi.render(mi.load_file(str(p)), spp=4))[..., 3:]
    s = load_scene(p)
    ours = Renderer(s, replace(with_scene_settings(RenderOptions(progress=False), s)[0], spp=4)).render().aov
    for px in ((8, 4), (8, 12)):
        assert np.allclose(ours[px], ref[px], atol=1e-6), (px, ours[px], ref[px])
    assert np.allclose(ours[8, 4], [0.2, 0.6, 0.3], atol=1e-6)  # not 0.3 x that


# ------------------------------------------------------------------ the kernel
def test_aov_kernel_is_traced_only_when_asked_for(monkeypatch, cornell):
    from drpt.render import renderer

    def trap(*args, **kwargs):
        raise RuntimeError("traced")

    monkeypatch.setattr(renderer, "aov_values", trap)  # the AOV kernel, as the renderer calls it
    opts = RenderOptions(width=4, height=4, spp=1, progress=False)
    r = Renderer(load_scene(cornell), opts).render()  # no AOVs: no AOV kernel
    assert r.aov is None
    with pytest.raises(RuntimeError, match="traced"):
        Renderer(load_scene(cornell), replace(opts, aovs=parse_aovs("depth"))).render()
    with pytest.raises(RuntimeError, match="traced"):
        Renderer(load_scene(cornell), replace(opts, denoise=True)).render()


@pytest.mark.parametrize("flags", [{}, {"filter": "gaussian"}, {"integrator": "ptracer"}],
                         ids=["box", "gaussian", "ptracer"])
def test_aovs_leave_the_image_bit_for_bit(flags, cornell):
    """The AOV kernel draws from random streams of its own: the image and its variance
    are those of a render without AOVs (light tracing's variance to float64 rounding: its
    film adds splats atomically, in varying order, :mod:`drpt.render.film`)."""
    scene = load_scene(cornell)
    opts = RenderOptions(width=12, height=10, spp=3, progress=False, variance=True, **flags)
    plain = Renderer(scene, opts).render()
    with_aovs = Renderer(scene, replace(opts, aovs=parse_aovs("depth,uv,albedo"), denoise=True)).render()
    assert np.array_equal(plain.image, with_aovs.image)
    if "integrator" in flags:
        assert np.allclose(plain.variance, with_aovs.variance, rtol=1e-9, atol=0.0)
    else:
        assert np.array_equal(plain.variance, with_aovs.variance)
    assert with_aovs.aov.shape == (10, 12, 1 + 2 + 3 + 6) and np.isfinite(with_aovs.aov).all()


def test_chunked_and_resumed_aovs_equal_the_plain_render(tmp_path, cornell):
    from support.resume import interrupted_then_resumed

    scene = load_scene(cornell)
    opts = RenderOptions(width=16, height=12, spp=8, progress=False, aovs=parse_aovs("depth,albedo"),
                         denoise=True, max_lanes=16 * 12 * 2)
    plain = Renderer(scene, opts).render()
    chunked = replace(opts, chunk_spp=2)
    resumed = interrupted_then_resumed(scene, chunked, tmp_path / "x.exr", after=2,
                                       checkpoint_seconds=None).result
    assert np.array_equal(plain.image, resumed.image)
    assert np.array_equal(plain.aov, resumed.aov)
    assert plain.aov.shape == (12, 16, 4 + 6)


def test_guides_follow_mirrors_to_the_first_other_surface(tmp_path):
    """A mirror sphere before a red wall: where the camera sees the mirror, Mitsuba's
    ``albedo`` is 0 (a delta lobe) and the denoiser's guide albedo is the red wall's
    reflected in it (or 0 where the reflection sees the sky)."""
    p = tmp_path / "mirror.xml"
    p.write_text("""<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film></sensor>
  <shape type="sphere"><float name="radius" value="0.6"/><bsdf type="conductor"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="20"/><translate z="6"/></transform>
    <bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.8,0.1,0.1"/></bsdf></bsdf>
  </shape>
  <shape type="rectangle"><transform name="to_world"><scale value="20"/><translate z="-2"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.1,0.1,0.8"/></bsdf></shape>
  <emitter type="constant"/>
</scene>""")
    s = load_scene(p)
    opts = replace(with_scene_settings(RenderOptions(progress=False), s)[0], spp=4,
                   aovs=parse_aovs("albedo"), denoise=True)
    a = Renderer(s, opts).render().aov
    albedo, guide = a[..., :3], a[..., 3:6]
    center = (slice(6, 10), slice(6, 10))  # the sphere's middle reflects the red wall behind the camera
    assert np.allclose(albedo[center], 0.0)
    assert np.allclose(guide[center], [0.8, 0.1, 0.1], atol=1e-6)
    corner = (slice(0, 2), slice(0, 2))  # the blue wall, seen directly
    assert np.allclose(albedo[corner], [0.1, 0.1, 0.8], atol=1e-6)
    assert np.allclose(guide[corner], albedo[corner])


# ------------------------------------------------------------------ command line
def test_render_writes_aov_layers(tmp_path, cornell):
    import OpenEXR

    from drpt.cli import main

    out = tmp_path / "x.exr"
    assert main(["render", str(cornell), "--size", "8", "8", "--spp", "2", "-q",
                 "--aovs", "depth,nn:normal", "-o", str(out)]) == 0
    with OpenEXR.File(str(out)) as f:
        names = set(f.channels())
    assert {"depth.T", "nn.X", "nn.Y", "nn.Z"} <= names


@pytest.mark.parametrize("flags,message", [
    (["--aovs", "depth", "-o", "x.png"], "holds no extra layers: write an .exr"),
    (["--aovs", "depth,dp_du", "-o", "x.exr"], "'dp_du' is not supported"),
    (["--aovs", "shape_index", "-o", "x.exr"], "need a Mitsuba XML scene")])
def test_aov_flag_errors_are_one_line(tmp_path, capsys, flags, message, cornell):
    from drpt.cli import main

    flags = [str(tmp_path / f) if f.startswith("x.") else f for f in flags]
    assert main(["render", str(cornell), "--size", "8", "8", "--spp", "1", "-q", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
