"""Mitsuba's ``projector`` and textured ``spot`` emitters (drpt.render.lights.delta): the light a
shading point receives equals Mitsuba's ``sample_direction`` weight on a grid of points (constant
and textured projectors of another aspect, rotated, every fov_axis; a textured spot), with negative
controls (the texture read upside down); a white diffuse surface lit by a constant projector shows
the analytic radiance ``value / z^2``; a scene with both renders like Mitsuba on the same file
(block z-test); bad input is a located error."""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f

from drpt.scene import load_scene
from drpt.testing import mitsuba

LOOKAT = '<lookat origin="0.3, -0.2, 2" target="0, 0.1, 0" up="0.2, 1, 0"/>'


@pytest.fixture
def png(tmp_path):
    from PIL import Image

    u8 = np.random.default_rng(2).integers(0, 256, size=(4, 6, 3), dtype=np.uint8)  # 6 wide, 4 high
    p = tmp_path / "tex.png"
    Image.fromarray(u8, "RGB").save(p)
    return p


def _xml(path: Path, emitter: str) -> Path:
    path.write_text(f'<scene version="3.0.0"><sensor type="perspective"/>{emitter}'
                    '<shape type="rectangle"><transform name="to_world"><scale value="5"/></transform>'
                    '</shape></scene>')
    return path


def _compare(path: Path, flip: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """drpt's irradiance and Mitsuba's sample_direction weight at points of the z = 0 plane."""
    from drpt.render.lights.delta import DeltaLights

    mi = mitsuba()
    s = load_scene(path)
    if flip:  # negative control: the image upside down
        light = s.lights[0]
        tex = light.texture if hasattr(light, "texture") else light.irradiance
        from dataclasses import replace

        flipped = replace(tex, to_uv=(1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 1.0))
        s.lights[0] = replace(light, **({"texture": flipped} if hasattr(light, "texture")
                                        else {"irradiance": flipped}))
    xs, ys = np.meshgrid(np.linspace(-3, 3, 61), np.linspace(-3, 3, 61))
    P = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 0)
    ours = np.array(next(iter(DeltaLights(s).samples(Array3f(*P)))).irradiance)
    scene = mi.load_file(str(path))
    it = dr.zeros(mi.Interaction3f)
    it.p = mi.Point3f(*P)
    _, spec = scene.emitters()[0].sample_direction(it, mi.Point2f(0.5, 0.5))
    return ours, np.array(spec)


@pytest.mark.mitsuba
@pytest.mark.parametrize("irradiance,fov", [
    ('<rgb name="irradiance" value="0.5, 1, 2"/>', '<float name="fov" value="80"/>'),
    ("TEX", '<float name="fov" value="60"/>'),
    ("TEX", '<float name="fov" value="50"/><string name="fov_axis" value="y"/>'),
    ("TEX", '<float name="fov" value="70"/><string name="fov_axis" value="diagonal"/>'),
])
def test_projector_equals_mitsuba(tmp_path, png, irradiance, fov):
    if irradiance == "TEX":
        irradiance = (f'<texture type="bitmap" name="irradiance"><string name="filename" value="{png}"/>'
                      '</texture>')
    p = _xml(tmp_path / "p.xml", f'<emitter type="projector">{fov}<float name="scale" value="1.5"/>'
                                 f'<transform name="to_world">{LOOKAT}</transform>{irradiance}</emitter>')
    ours, theirs = _compare(p)
    assert (theirs.max(0) > 0).mean() > 0.1  # a good part of the grid is lit
    np.testing.assert_allclose(ours, theirs, rtol=2e-5, atol=2e-5)
    if "bitmap" in irradiance:
        bad, theirs = _compare(p, flip=True)
        assert np.abs(bad - theirs).max() > 0.1


@pytest.mark.mitsuba
def test_textured_spot_equals_mitsuba(tmp_path, png):
    p = _xml(tmp_path / "s.xml", f'<emitter type="spot"><rgb name="intensity" value="5"/>'
                                 '<float name="cutoff_angle" value="40"/><float name="beam_width" value="25"/>'
                                 f'<transform name="to_world">{LOOKAT}</transform>'
                                 f'<texture type="bitmap" name="texture"><string name="filename" value="{png}"/>'
                                 '</texture></emitter>')
    ours, theirs = _compare(p)
    assert (theirs.max(0) > 0).mean() > 0.1
    np.testing.assert_allclose(ours, theirs, rtol=2e-5, atol=2e-5)
    bad, theirs = _compare(p, flip=True)
    assert np.abs(bad - theirs).max() > 0.1


def test_projector_analytic_radiance(tmp_path):
    """A constant projector of value v looking down the -z axis from height h: a white diffuse
    point at local depth z reflects ``E cos / pi = v / z^2`` toward any viewer."""
    from drpt.render.lights.delta import DeltaLights

    h = 2.0
    p = _xml(tmp_path / "p.xml", '<emitter type="projector"><float name="fov" value="90"/>'
                                 '<transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" '
                                 'up="0, 1, 0"/></transform><rgb name="irradiance" value="0.7"/></emitter>')
    s = load_scene(p)
    rng = np.random.default_rng(1)
    P = np.stack([rng.uniform(-1.9, 1.9, 500), rng.uniform(-1.9, 1.9, 500), np.zeros(500)], 0)
    ds = next(iter(DeltaLights(s).samples(Array3f(*P))))
    cos = np.array(ds.wo)[2]  # the plane's normal is +z
    radiance = np.array(ds.irradiance)[0] * cos / np.pi
    np.testing.assert_allclose(radiance, 0.7 / h**2, rtol=1e-5)
    # outside the 90-degree square nothing arrives
    out = next(iter(DeltaLights(s).samples(Array3f(2.5, 0.0, 0.0)))).irradiance
    assert np.array(out).max() == 0.0


@pytest.mark.mitsuba
def test_scene_renders_like_mitsuba():
    """tests/data/xml/projector_spot.xml: a textured projector and a textured spot on a floor
    and a sphere, direct lighting, drpt vs Mitsuba on the same file (8x8 block z-test)."""
    from drpt.testing import assert_agree
    from support.xml import XML, render_xml_both

    path = XML / "projector_spot.xml"
    scene = load_scene(path)
    r, ref, var = render_xml_both(scene, path, 64)
    assert ref.mean() > 0.02
    assert_agree(r, ref, var, zmax=4.5)


def test_refusals(tmp_path, png):
    from drpt.errors import SceneError

    p = _xml(tmp_path / "a.xml", '<emitter type="projector"><transform name="to_world"><scale value="2"/>'
                                 '</transform></emitter>')
    with pytest.raises(SceneError, match="rotation and translation"):
        load_scene(p)
    p = _xml(tmp_path / "b.xml", '<emitter type="spot"><texture type="checkerboard" name="texture"/></emitter>')
    with pytest.raises(SceneError, match="drpt reads a bitmap there"):
        load_scene(p)


@pytest.mark.mitsuba
def test_export_round_trip(tmp_path):
    """The exporter writes the projector and the textured spot back: Mitsuba's emitters of the
    exported XML give the same light as the original file's."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    from drpt.export.mitsuba import write_xml
    from support.xml import XML

    s = load_scene(XML / "projector_spot.xml")
    out = tmp_path / "out.xml"
    write_xml(s, out, 32, 24, 4)
    mi.set_variant(mitsuba_variant())
    P = np.stack([np.linspace(-2, 2, 41), np.zeros(41), np.linspace(-1, 1, 41)], 0)
    it = dr.zeros(mi.Interaction3f)
    it.p = mi.Point3f(*P)

    def lights(path):
        ems = [e for e in mi.load_file(str(path)).emitters() if "Projector" in str(e) or "Spot" in str(e)]
        return [np.array(e.sample_direction(it, mi.Point2f(0.5, 0.5))[1]) for e in ems]

    a, b = lights(XML / "projector_spot.xml"), lights(out)
    assert len(a) == len(b) == 2
    for x, y in zip(a, b):
        assert x.max() > 0
        np.testing.assert_allclose(x, y, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("value, message", [("0mm", "focal_length must be positive"),
                                            ("abc", "focal_length must be like '50mm'")])
def test_projector_focal_length_errors_are_located(tmp_path, value, message):
    """A projector reads its field of view as the sensor does (drpt/scene/mitsuba/reader.py's
    field_of_view): a zero focal length was a ZeroDivisionError."""
    from drpt.errors import SceneError
    from drpt.scene import load_scene

    p = tmp_path / "p.xml"
    p.write_text('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">'
                 '<integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>\n'
                 '<shape type="rectangle"/>\n'
                 f'<emitter type="projector"><string name="focal_length" value="{value}"/></emitter></scene>')
    with pytest.raises(SceneError, match=f"p.xml:3: emitter 'projector': {message}"):
        load_scene(p)
