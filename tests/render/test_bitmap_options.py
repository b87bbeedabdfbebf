"""Mitsuba ``bitmap`` options (drpt.materials.spec.Texture, drpt.render.texture.Bitmap): ``filter_type``
nearest, ``wrap_mode`` mirror and clamp, ``raw`` and ``to_uv`` look up what Mitsuba's ``bitmap``
evaluates at the same uv (and a ``rawconstant`` is its value); the negative controls (nearest read
as bilinear, mirror as repeat, raw decoded, to_uv dropped) do not. A scene with every combination
renders like Mitsuba on the same file (tests/data/xml/bitmap_options.xml, block z-test)."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Float, UInt32

from drpt.materials.spec import Texture
from drpt.render.texture import TextureSet
from drpt.testing import mitsuba
from support import DATA

TO_UV = (2.0, 0.3, -0.5, -0.2, 2.0, -0.5, 0.0, 0.0, 1.0)


@pytest.fixture
def png(tmp_path):
    from PIL import Image

    u8 = np.random.default_rng(0).integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    p = tmp_path / "tex.png"
    Image.fromarray(u8, "RGB").save(p)
    return p


def _ours(tex: Texture, uv: np.ndarray) -> np.ndarray:
    ts = TextureSet([tex])
    n = uv.shape[1]
    r = ts.lookup(UInt32(np.zeros(n, np.uint32)), Array2f(Float(uv[0]), Float(uv[1])))
    return np.broadcast_to(np.array(r), (3, n))


def _theirs(mi, tex: Texture, uv: np.ndarray) -> np.ndarray:
    d = {"type": "bitmap", "filename": str(tex.path), "filter_type": tex.filter_type,
         "wrap_mode": tex.wrap_mode, "raw": tex.raw}
    if tex.to_uv is not None:
        a = np.asarray(tex.to_uv).reshape(3, 3)
        m = np.eye(4)
        m[:2, :2], m[:2, 3] = a[:2, :2], a[:2, 2]
        d["to_uv"] = mi.ScalarTransform4f(m.tolist())
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.uv = mi.Point2f(uv[0], 1.0 - uv[1])  # drpt's OBJ uv -> Mitsuba's
    return np.array(mi.load_dict(d).eval(si))


CASES = [("nearest", "repeat", False, None), ("bilinear", "mirror", False, None),
         ("bilinear", "clamp", False, None), ("nearest", "mirror", True, TO_UV),
         ("nearest", "clamp", False, TO_UV), ("bilinear", "repeat", True, TO_UV)]


@pytest.mark.mitsuba
@pytest.mark.parametrize("filt,wrap,raw,to_uv", CASES)
def test_equals_mitsuba_bitmap(png, filt, wrap, raw, to_uv):
    mi = mitsuba()
    rng = np.random.default_rng(4)
    uv = rng.uniform(-2.0, 3.0, size=(2, 5000)).astype(np.float32)
    tex = Texture(png, 0.5, filter_type=filt, wrap_mode=wrap, raw=raw, to_uv=to_uv)
    theirs = _theirs(mi, tex, uv)
    ours = _ours(tex, uv)
    # float32 rounding of the to_uv product (Mitsuba fuses it) moves a lookup by an ulp
    np.testing.assert_allclose(ours, theirs, atol=2e-5, rtol=0)
    assert np.abs(ours - theirs).mean() < 2e-7
    # negative controls: each option changed is not Mitsuba's lookup
    for wrong in ({"filter_type": "bilinear" if filt == "nearest" else "nearest"},
                  {"wrap_mode": "repeat" if wrap != "repeat" else "mirror"}, {"raw": not raw},
                  {"to_uv": None if to_uv is not None else TO_UV}):
        other = Texture(png, 0.5, **{**dict(filter_type=filt, wrap_mode=wrap, raw=raw, to_uv=to_uv),
                                     **wrong})
        assert np.abs(_ours(other, uv) - theirs).max() > 1e-2, wrong


def test_reader_reads_the_options(tmp_path, png):
    from drpt.errors import SceneError
    from drpt.scene import load_scene

    def scene(tex: str):
        p = tmp_path / "s.xml"
        p.write_text(f'<scene version="3.0.0"><sensor type="perspective"/><shape type="rectangle">'
                     f'<bsdf type="diffuse">{tex}</bsdf></shape></scene>')
        return load_scene(p)

    s = scene(f'<texture type="bitmap" name="reflectance"><string name="filename" value="{png}"/>'
              '<string name="filter_type" value="nearest"/><string name="wrap_mode" value="mirror"/>'
              '<boolean name="raw" value="true"/><transform name="to_uv"><scale value="2"/>'
              '<translate x="-0.5" y="0.25"/></transform></texture>')
    t = s.materials[0].bsdf.params["kd"]
    assert (t.filter_type, t.wrap_mode, t.raw) == ("nearest", "mirror", True)
    assert np.allclose(t.to_uv, (2, 0, -0.5, 0, 2, 0.25, 0, 0, 1))
    s = scene('<texture type="rawconstant" name="reflectance"><vector name="value" value="0.1, 0.2, 0.3"/>'
              '</texture>')
    assert s.materials[0].bsdf.params["kd"] == (0.1, 0.2, 0.3)
    with pytest.raises(SceneError, match="wrap_mode must be one of"):
        scene(f'<texture type="bitmap" name="reflectance"><string name="filename" value="{png}"/>'
              '<string name="wrap_mode" value="wrap"/></texture>')


@pytest.mark.slow
@pytest.mark.mitsuba
def test_scene_renders_like_mitsuba():
    """Six rectangles, nearest and bilinear by repeat, mirror and clamp, under a to_uv (the
    nearest mirror one raw), drpt vs Mitsuba on the same file: 4x4 block z-test (|z| < 4.5 over
    96 blocks x 3 channels); negative control: the nearest textures read bilinear fail it."""
    from dataclasses import replace

    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from drpt.testing import assert_agree, block_z
    from support.xml import render_xml_both

    path = DATA / "xml" / "bitmap_options.xml"
    scene = load_scene(path)
    r, ref, var = render_xml_both(scene, path, 64)
    assert r.image.shape == (32, 48, 3) and ref.mean() > 0.05
    assert_agree(r, ref, var, zmax=4.5, block=4)
    for m in scene.materials:
        kd = m.bsdf.params["kd"]
        m.bsdf.params["kd"] = replace(kd, filter_type="bilinear")
    opts = replace(with_scene_settings(RenderOptions(progress=False, seed=3), scene)[0], spp=64)
    bad = Renderer(scene, opts).render()
    assert np.abs(block_z(bad.image, bad.variance, ref, var, block=4)).max() > 6.0
