"""Mitsuba's ``checkerboard`` texture (drpt.materials.spec.Checkerboard, drpt.render.texture): its value at
random uvs equals Mitsuba's ``eval`` (RGB parameters) and ``eval_1`` (float parameters, which swap
the two colors and read an rgb value's channel mean), with a rotating, scaling, translating
``to_uv``; a corpus scene with checkerboards on a diffuse reflectance and on a roughconductor's
alpha renders like Mitsuba on the same file (block z-test), and fails it with the colors swapped
(negative control)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.materials.spec import Checkerboard
from drpt.scene import load_scene

pytestmark = pytest.mark.mitsuba
XML = Path(__file__).resolve().parents[1] / "data" / "xml"  # tests/data/xml
TO_UV = '<transform name="to_uv"><scale x="4" y="3"/><rotate z="1" angle="20"/><translate x="0.3"/></transform>'


def _drpt_values(spec: Checkerboard, uv_mitsuba: np.ndarray, scalar: bool) -> np.ndarray:
    from drjit.auto import Array2f, UInt32

    from drpt.render.texture import TextureSet

    ts = TextureSet([spec])
    uv = Array2f(uv_mitsuba[:, 0], 1.0 - uv_mitsuba[:, 1])  # drpt keeps OBJ uvs: v = 1 - Mitsuba's
    return np.array(ts.lookup(UInt32(np.zeros(len(uv_mitsuba), np.uint32)), uv, True, scalar=scalar)).T


@pytest.mark.parametrize("to_uv", ["", TO_UV])
def test_values_equal_mitsubas_eval_and_eval_1(tmp_path, to_uv):
    import mitsuba as mi
    from drjit.auto import Array3f

    from drpt.backend import mitsuba_variant
    from drpt.render.material import _luminance

    texture = ('<texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.8, 0.2, 0.1"/>'
               f'<rgb name="color1" value="0.1, 0.3, 0.5"/>{to_uv}</texture>')
    p = tmp_path / "t.xml"
    p.write_text(f'<scene version="3.0.0"><include filename="{XML / "common_sensor.xml"}"/><shape type="rectangle">'
                 f'<bsdf type="diffuse">{texture}</bsdf></shape></scene>')
    spec = load_scene(p).materials[0].bsdf.params["kd"]
    assert isinstance(spec, Checkerboard)
    mi.set_variant(mitsuba_variant())
    tex = mi.load_string(texture.replace('<texture ', '<texture version="3.0.0" '))
    uv = np.random.default_rng(4).uniform(-2, 3, (4000, 2))
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(uv[:, 0], uv[:, 1])
    ref, ref1 = np.array(tex.eval(si)).T, np.array(tex.eval_1(si))
    got = _drpt_values(spec, uv, scalar=False)
    assert np.abs(got - ref).max() < 1e-6
    got1 = np.array(_luminance(Array3f(*_drpt_values(spec, uv, scalar=True).T)))
    assert np.abs(got1 - ref1).max() < 1e-5
    # negative controls: eval_1 is not the luminance of eval; without to_uv the pattern differs
    assert np.abs(np.array(_luminance(Array3f(*got.T))) - ref1).max() > 0.04
    if to_uv:
        plain = _drpt_values(replace(spec, to_uv=(1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0)), uv, scalar=False)
        assert np.abs(plain - ref).max() > 0.1


@pytest.mark.slow
def test_checkerboard_scene_renders_like_mitsuba():
    from drpt.testing import assert_agree, block_z
    from support.xml import render_xml_both

    scene = load_scene(XML / "checker.xml")
    r, ref, var = render_xml_both(scene, XML / "checker.xml", 256)
    assert_agree(r, ref, var, zmax=4.5)
    # negative control: the floor's colors swapped
    for m in scene.materials:
        kd = m.bsdf.params.get("kd")
        if isinstance(kd, Checkerboard):
            m.bsdf.params["kd"] = replace(kd, color0=kd.color1, color1=kd.color0)
    r0, _, _ = render_xml_both(scene, XML / "checker.xml", 256)
    assert np.abs(block_z(r0.image, r0.variance, ref, var)).max() > 6.0
