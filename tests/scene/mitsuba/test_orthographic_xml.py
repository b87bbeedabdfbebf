"""Mitsuba's ``orthographic`` sensor read from XML (drpt.scene.mitsuba.reader.orthographic_from_matrix,
drpt.render.camera.RayCamera): camera rays equal Mitsuba's ``sensor.sample_ray`` (origins on the
near plane, the view ``2 sx`` wide and ``2 sy / aspect`` high), with a negative control that reads
the view's height without the film's aspect; refusals are located
errors."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.scene import load_scene


def _ortho_xml(path: Path, scale: str, near: float | None = 0.5, W=40, H=24, extra="") -> Path:
    clip = f'<float name="near_clip" value="{near}"/>' if near is not None else ""
    path.write_text(
        f'<scene version="3.0.0"><sensor type="orthographic">{clip}'
        f'<transform name="to_world"><scale {scale}/>'
        '<lookat origin="-5, 1, 3" target="0, 0, 1" up="0, 0.3, 1"/></transform>'
        f'<film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{H}"/>'
        f'{extra}</film></sensor></scene>')
    return path


@pytest.mark.mitsuba
@pytest.mark.parametrize("scale,near", [('x="1.5" y="1.5"', 0.5), ('x="2" y="0.7" z="3"', 1.0),
                                        ('value="1"', None)])
def test_rays_match_mitsubas_sample_ray(tmp_path, scale, near):
    import mitsuba as mi
    from drjit.auto import Float

    from drpt.backend import mitsuba_variant
    from drpt.render.camera import RayCamera

    W, H = 40, 24
    p = _ortho_xml(tmp_path / "cam.xml", scale, near, W, H)
    s = load_scene(p)
    xs, ys = np.meshgrid(np.linspace(0, W, 9), np.linspace(0, H, 7))
    xs, ys = xs.ravel(), ys.ravel()
    o, d = RayCamera(s.camera, W, H).ray(Float(xs), Float(ys))
    o, d = np.array(o).T, np.array(d).T
    mi.set_variant(mitsuba_variant())
    sensor = mi.load_file(str(p)).sensors()[0]
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(xs / W, ys / H), mi.Point2f(0.5, 0.5))
    md, mo = np.array(ray.d).T, np.array(ray.o).T
    assert np.abs(d - md).max() < 1e-6
    assert np.abs(o - mo).max() < 2e-5, np.abs(o - mo).max()
    # negative control: the height read without the film's aspect (2 sy, not 2 sy / aspect)
    wrong = replace(s.camera, size=s.camera.size * W / H)
    o2, _ = RayCamera(wrong, W, H).ray(Float(xs), Float(ys))
    assert np.abs(np.array(o2).T - mo).max() > 1e-2


def test_refusals(tmp_path):
    from drpt.errors import SceneError

    p = tmp_path / "shear.xml"
    p.write_text('<scene version="3.0.0"><sensor type="orthographic"><transform name="to_world">'
                 '<matrix value="1 0.5 0 0 0 1 0 0 0 0 1 0 0 0 0 1"/></transform></sensor></scene>')
    with pytest.raises(SceneError, match="rotation times a scale"):
        load_scene(p)
    p = _ortho_xml(tmp_path / "mirror.xml", 'x="-1"')
    with pytest.raises(SceneError, match="mirrors"):
        load_scene(p)
    p = _ortho_xml(tmp_path / "crop.xml", 'value="1"',
                   extra='<integer name="crop_width" value="10"/>')
    with pytest.raises(SceneError, match="crop window"):
        load_scene(p)
